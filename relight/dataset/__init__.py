"""The dataset format (:mod:`relight.dataset.format`): what the stages import to read a dataset."""
from relight.dataset.format import (CARD, DATASET_FORMAT, MANIFEST, MAX_COUNT, SEED_LIMIT, SPLIT_CHOICES, SPLITS,
                                    DatasetError, check_record, check_same_settings, load_spec, read_card,
                                    read_manifest, record_for, safe_join, split_records)

__all__ = ["CARD", "DATASET_FORMAT", "MANIFEST", "MAX_COUNT", "SEED_LIMIT", "SPLITS", "SPLIT_CHOICES",
           "DatasetError", "check_record", "check_same_settings", "load_spec", "read_card", "read_manifest",
           "record_for", "safe_join", "split_records"]

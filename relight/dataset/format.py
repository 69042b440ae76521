"""The dataset format: the folder, its manifest, its card, its splits, and their readers.

Layout of a dataset folder (see ``docs/conventions.md``)::

    dataset.json      the card: format, seed, generator settings, counts
    manifest.jsonl    one JSON record per finished image
    images/ID.png     8-bit sRGB, for the network
    exr/ID.exr        linear HDR float32
    scenes/ID.json    the scene description that re-renders the image exactly

A partial *last line* of the manifest (a killed writer) is ignored by the readers.
The writer is :mod:`relight.generator.run`; the stages (net, verify, inverse) read
datasets through this module only.
"""
from __future__ import annotations

__all__ = [
    "DATASET_FORMAT", "MANIFEST", "CARD", "MAX_COUNT", "SEED_LIMIT", "SPLITS", "SPLIT_CHOICES", "record_for",
    "read_manifest", "check_record", "split_records", "read_card", "check_same_settings", "load_spec",
    "safe_join",
]

import json
import math
import os

import numpy as np

from relight import frames
from relight.fileio import write_bytes
from relight.scene.spec import SceneSpec
from relight.errors import DatasetError

DATASET_FORMAT = "relight.dataset/v1"
MANIFEST = "manifest.jsonl"
CARD = "dataset.json"
MAX_COUNT = 1_000_000      # ids are six digits
SEED_LIMIT = 2 ** 32       # dataset seeds are in [0, 2**32)
SPLITS = ("train", "val", "test")
SPLIT_CHOICES = SPLITS + ("all",)   # what a reader may ask for: one split or all of them


def record_for(spec: SceneSpec, split: str) -> dict:
    """The manifest record of one image (paths relative to the dataset folder)."""
    light, cam = spec.light, spec.camera
    y = frames.encode_y(light.pan_deg, light.tilt_deg, np.asarray(light.rgb), cam.tilt_deg, cam.pan_deg)
    return {
        "id": spec.id,
        "image": f"images/{spec.id}.png",
        "exr": f"exr/{spec.id}.exr",
        "scene": f"scenes/{spec.id}.json",
        "split": split,
        "light": {"pan_deg": light.pan_deg, "tilt_deg": light.tilt_deg, "r_m": light.r_m,
                  "rgb": list(light.rgb), "cct_k": light.cct_k, "duv": light.duv,
                  "strength": light.strength, "position_m": light.position_m.tolist()},
        "camera": {"pan_deg": cam.pan_deg, "tilt_deg": cam.tilt_deg, "r_m": cam.r_m,
                   "fov_deg": cam.fov_deg, "position_m": cam.position_m.tolist()},
        "pan_rel_deg": spec.pan_rel_deg,
        "y": [float(v) for v in y],
        "seed": spec.render.seed,
        "n_objects": len(spec.objects),
        "colour_prior": spec.colour_prior,
    }


def read_manifest(dataset_dir: str | os.PathLike, repair: bool = False) -> list[dict]:
    """Records of a dataset, in file order, each checked (:func:`check_record`).

    A partial last line (a killed writer) is ignored, and cut off when ``repair`` is
    true. Records repeated with identical content (two writers of an older relight)
    are kept once -- and removed from the file when ``repair`` is true; the same id
    with different content is an error. Raises :class:`DatasetError` naming the file
    and line.

    Args:
        dataset_dir: the dataset folder (it holds ``manifest.jsonl``).
        repair: cut a partial last line and repeated records off the file.

    Returns:
        One dict per image (``docs/conventions.md``): ``id``, relative ``image`` /
        ``exr`` / ``scene`` paths, ``split``, ``light`` (``pan_deg``, ``tilt_deg`` in
        degrees, linear unit-norm ``rgb``, ...), ``camera``, ``pan_rel_deg`` and ``y``
        (the paper's 7-vector).

    A manifest whose writer was killed in the middle of its second line:

    >>> import json, os, shutil, tempfile
    >>> folder = tempfile.mkdtemp()
    >>> rec = {"id": "000000", "image": "images/000000.png", "split": "test", "pan_rel_deg": 90.0,
    ...        "light": {"pan_deg": 90.0, "tilt_deg": 45.0, "rgb": [0.6, 0.6, 0.5]},
    ...        "camera": {"pan_deg": 0.0, "tilt_deg": 30.0}, "y": [1.0, 0.0, 0.0, 1.0, 0.6, 0.6, 0.5]}
    >>> with open(os.path.join(folder, MANIFEST), "w") as f:
    ...     _ = f.write(json.dumps(rec) + "\\n" + '{"id": "000001", "ima')
    >>> [(r["id"], r["light"]["pan_deg"]) for r in read_manifest(folder)]
    [('000000', 90.0)]
    >>> shutil.rmtree(folder)
    """
    path = os.path.join(os.fspath(dataset_dir), MANIFEST)
    if not os.path.isfile(path):
        raise DatasetError(f"{os.fspath(dataset_dir)}: no {MANIFEST} (not a relight dataset?)")
    with open(path, "rb") as f:
        data = f.read()
    records, seen, good_end, pos, line_no, duplicates = [], {}, 0, 0, 0, 0
    while pos < len(data):
        nl = data.find(b"\n", pos)
        if nl < 0:
            break  # partial last line: its writer was killed
        line_no += 1
        line = data[pos:nl]
        try:
            rec = json.loads(line)
        except (json.JSONDecodeError, UnicodeDecodeError):
            if data.find(b"\n", nl + 1) >= 0:
                raise DatasetError(f"{path}: corrupt record on line {line_no}") from None
            break
        check_record(rec, f"{path}: line {line_no}")
        first = seen.get(rec["id"])
        if first is not None:
            if first != rec:
                raise DatasetError(f"{path}: line {line_no}: id {rec['id']!r} appears twice with "
                                   "different content")
            duplicates += 1
        else:
            seen[rec["id"]] = rec
            records.append(rec)
        pos = good_end = nl + 1
    if repair and (good_end < len(data) or duplicates):
        text = b"".join((json.dumps(r) + "\n").encode() for r in records) if duplicates else data[:good_end]
        if duplicates:
            write_bytes(path, text)
        else:
            with open(path, "r+b") as f:
                f.truncate(good_end)
    return records


def _finite_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def check_record(rec, where: str) -> None:
    """Check the fields of a manifest record that readers use; raises
    :class:`DatasetError` (``where`` names file and line)."""
    if not isinstance(rec, dict):
        raise DatasetError(f"{where}: expected a JSON object, got {type(rec).__name__}")
    rid = rec.get("id")
    if not isinstance(rid, str) or not rid or "/" in rid or "\\" in rid or rid in (".", ".."):
        raise DatasetError(f"{where}: 'id' must be a plain name, got {rid!r}")
    where = f"{where} (id {rid!r})"
    for key in ("image", "exr", "scene", "mask"):   # all but image may be absent (hand-made datasets; masks)
        if (key in rec or key == "image") and not isinstance(rec.get(key), str):
            raise DatasetError(f"{where}: {key!r} must be a relative path string, got {rec.get(key)!r}")
    if rec.get("split") not in SPLITS:
        raise DatasetError(f"{where}: 'split' must be one of {', '.join(SPLITS)}, got {rec.get('split')!r}")
    for part, keys in (("light", ("pan_deg", "tilt_deg")), ("camera", ("pan_deg", "tilt_deg"))):
        obj = rec.get(part)
        if not isinstance(obj, dict):
            raise DatasetError(f"{where}: {part!r} must be an object")
        for k in keys:
            if not _finite_number(obj.get(k)):
                raise DatasetError(f"{where}: {part}.{k} must be a finite number, got {obj.get(k)!r}")
    rgb = rec["light"].get("rgb")
    if not (isinstance(rgb, list) and len(rgb) == 3 and all(_finite_number(c) and c >= 0 for c in rgb)
            and max(rgb) > 0):
        raise DatasetError(f"{where}: light.rgb must be three finite non-negative numbers, got {rgb!r}")
    if not _finite_number(rec.get("pan_rel_deg")):
        raise DatasetError(f"{where}: pan_rel_deg must be a finite number, got {rec.get('pan_rel_deg')!r}")
    y = rec.get("y")
    if not (isinstance(y, list) and len(y) == frames.Y_SIZE and all(_finite_number(v) for v in y)):
        raise DatasetError(f"{where}: 'y' must be a list of {frames.Y_SIZE} finite numbers")


def split_records(records: list[dict], split: str) -> list[dict]:
    """Records of one split (``"train"``, ``"val"``, ``"test"``) or all of them (``"all"``)."""
    if split not in SPLIT_CHOICES:
        raise DatasetError(f"unknown split {split!r}; expected one of {', '.join(SPLIT_CHOICES)}")
    return list(records) if split == "all" else [r for r in records if r.get("split") == split]


def read_card(dataset_dir: str | os.PathLike) -> dict:
    """The dataset card (settings it was made with)."""
    path = os.path.join(os.fspath(dataset_dir), CARD)
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, json.JSONDecodeError) as exc:
        raise DatasetError(f"cannot read dataset card {path}: {exc}") from None


def check_same_settings(out: str, there: dict, here: dict) -> None:
    """Refuse to add to the dataset in ``out`` (card settings ``there``) with other
    settings (``here``, the same keys, ``config`` a dict): :class:`DatasetError` naming
    the first settings that differ."""
    there, here = json.loads(json.dumps(there)), json.loads(json.dumps(here))
    if there == here:
        return
    diff = [f"{k} {there.get(k)} there, {v} here" for k, v in here.items() if k != "config" and there.get(k) != v]
    old_cfg = there.get("config") if isinstance(there.get("config"), dict) else {}
    diff += [f"{k} {old_cfg.get(k)} there, {v} here" for k, v in here["config"].items() if old_cfg.get(k) != v]
    raise DatasetError(f"{out} holds a dataset made with other settings ({'; '.join(diff[:3]) or 'config'}); "
                       "use another --out or the same settings to resume")


def load_spec(dataset_dir: str | os.PathLike, record: dict) -> SceneSpec:
    """The scene spec of a manifest record (path checked to stay inside the dataset)."""
    from relight.scene.spec import load_scene
    return load_scene(safe_join(dataset_dir, record["scene"]))


def safe_join(dataset_dir: str | os.PathLike, relative: str) -> str:
    """Join a relative path from a manifest or predictions file to a dataset folder,
    refusing anything that escapes it (absolute paths, ``..``)."""
    base = os.path.realpath(os.fspath(dataset_dir))
    if not isinstance(relative, str) or os.path.isabs(relative):
        raise DatasetError(f"expected a relative path inside the dataset, got {relative!r}")
    path = os.path.realpath(os.path.join(base, relative))
    if os.path.commonpath([base, path]) != base:
        raise DatasetError(f"path {relative!r} escapes the dataset folder")
    return path

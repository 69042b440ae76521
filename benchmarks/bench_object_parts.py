"""Colour error against the number of independently coloured parts per object.

The paper gives each mesh part of its ShapeNet objects its own random colour; relight's
procedural objects had one colour each. ``relight generate --object-parts K`` cuts each
object into K coloured patches. This measures what that does to light-colour recovery,
on the ``test`` split of datasets that differ only in ``--object-parts`` (the same seed:
the same cameras, lights and rooms, so the comparison is paired):

* gray-world and shades-of-gray (no training): what averaging the surfaces gives;
* each trained model (``--model NAME=FILE``, e.g. small colour-only networks trained on
  each dataset) on every dataset's test split: the cross table says whether a model
  trained on many-part scenes still does well on one-part scenes and the reverse.

    .venv/bin/python benchmarks/bench_object_parts.py \\
        --data 1=/root/relight-data/pilot/parts1 --data 4=/root/relight-data/pilot/parts4 \\
        --model 1=/root/relight-data/pilot/runs/p1/best.safetensors ...

Prints a markdown table of mean (median) colour error in degrees per test set.
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from relight.inverse.colour_baselines import estimate_jobs  # noqa: E402
from relight.inverse.jobs import dataset_jobs  # noqa: E402
from relight.metrics import colour_error_deg  # noqa: E402
from relight.net.data import LightDataset  # noqa: E402

BASELINES = ("gray-world", "shades-of-gray")


def _named(text: str) -> tuple[str, str]:
    name, sep, path = text.partition("=")
    if not sep or not name or not path:
        raise argparse.ArgumentTypeError(f"expected NAME=PATH, got {text!r}")
    return name, path


def baseline_errors(data_dir: str, split: str) -> dict[str, np.ndarray]:
    """Colour error of each classical baseline on the split (``relight baseline``'s path)."""
    jobs = dataset_jobs(data_dir, split)
    truth = LightDataset(data_dir, split, 64, cache=False).truth()["rgb"]
    return {b: colour_error_deg(np.array([e["rgb"] for e in estimate_jobs(b, jobs, progress=False)]), truth)
            for b in BASELINES}


def model_errors(model_path: str, data_dir: str, split: str) -> np.ndarray:
    from relight.net.evaluate import decode_outputs, run_model, target_frame_of
    from relight.net.predict import load_model
    model = load_model(model_path)
    ds = LightDataset(data_dir, split, model.config.res, cache=False)
    y_pred = run_model(model, ds, 64)
    truth = ds.truth()
    _, _, rgb = decode_outputs(y_pred, truth["camera_tilt_deg"], target_frame_of(model))
    return colour_error_deg(rgb, truth["rgb"])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=_named, action="append", required=True,
                    help="NAME=DIR: a dataset (NAME: its part count), repeatable")
    ap.add_argument("--model", type=_named, action="append", default=[],
                    help="NAME=FILE: a model trained on dataset NAME, repeatable")
    ap.add_argument("--split", default="test", help="split to measure (default test)")
    args = ap.parse_args(argv)
    rows: dict[str, dict[str, np.ndarray]] = {}
    for name, path in args.data:
        for b, err in baseline_errors(path, args.split).items():
            rows.setdefault(b, {})[name] = err
    for mname, mpath in args.model:
        for name, path in args.data:
            rows.setdefault(f"model trained on {mname}", {})[name] = model_errors(mpath, path, args.split)
    names = [n for n, _ in args.data]
    n = len(next(iter(rows.values()))[names[0]])
    print(f"mean (median) colour error, degrees, on the {args.split} split ({n} images each)\n")
    print("| estimator | " + " | ".join(f"test, {k} part(s)" for k in names) + " |")
    print("|---|" + "---:|" * len(names))
    for label, errs in rows.items():
        print(f"| {label} | " + " | ".join(f"{errs[k].mean():.2f} ({np.median(errs[k]):.2f})" for k in names) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

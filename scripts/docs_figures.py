"""Redraw the README's two pictures from ``relight demo`` (the generator's defaults and the
shipped model):

    python scripts/docs_figures.py [--work demo_out]

* ``docs/dataset_examples.png``: the demo's 12 images (seed 0, 128 px, 64 spp) in two rows;
* ``docs/figure3_demo.png``: the demo's Figure 3 panel (``compare/figure3.png``).

Run it after the generator's defaults or the shipped model change. The demo resumes its
dataset, so a second run only redoes the prediction and the panel.
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

from relight import cli  # noqa: E402
from relight.dataset import read_manifest  # noqa: E402
from relight.imageio import read_srgb8, write_srgb8  # noqa: E402

DOCS = os.path.join(REPO, "docs")
ROWS, COLS = 2, 6


def montage(paths: list[str], rows: int, cols: int) -> np.ndarray:
    """The images of ``paths`` (all one size) row by row on one canvas."""
    tiles = [read_srgb8(p)[0] for p in paths]
    if len(tiles) != rows * cols:
        raise SystemExit(f"need {rows * cols} images for the montage, got {len(tiles)}")
    return np.concatenate([np.concatenate(tiles[r * cols:(r + 1) * cols], axis=1) for r in range(rows)],
                          axis=0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", default="demo_out", help="the demo's output folder (default demo_out)")
    args = ap.parse_args(argv)
    rc = cli.main(["demo", "--out", args.work, "--count", str(ROWS * COLS)])
    if rc:
        return rc
    data = os.path.join(args.work, "dataset")
    records = read_manifest(data)[:ROWS * COLS]
    canvas = montage([os.path.join(data, r["image"]) for r in records], ROWS, COLS)
    write_srgb8(os.path.join(DOCS, "dataset_examples.png"), canvas)
    shutil.copyfile(os.path.join(args.work, "compare", "figure3.png"), os.path.join(DOCS, "figure3_demo.png"))
    print(f"wrote {os.path.join(DOCS, 'dataset_examples.png')} and {os.path.join(DOCS, 'figure3_demo.png')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

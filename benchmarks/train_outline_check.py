"""Train the learned outline check (relight.probe.outline_check) and judge it alone.

Training: the Mitsuba renders of the locator's training scenes (``bash
scripts/train_locator.sh`` makes them; seeds 100000-101213, disjoint from every set it is
judged on), ``--per-scene`` candidate circles drawn around each true circle, cropped from
the 8-bit PNG as stored or (``--augment``) from the linear EXR through a camera pipeline.
Judged on the Cycles renders of the probe sets (a renderer it never saw), candidates drawn
alike with a fixed seed: how far its circle lies from the truth against how far the
candidate did (in radii), and how often it is within a tenth of the radius. How the detector
uses it is judged by ``bench_probe.py``. The shipped weights: ``bash scripts/train_outline_check.sh``.

    python benchmarks/train_outline_check.py --train ~/relight-data/issue-29/detector-train --limit 1214 \\
        --epochs 12 --save relight/models/probe_outline_check.safetensors --test ~/relight-data/issue-29/set
"""
from __future__ import annotations

import glob
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def scene_crops(json_path: str, renderer: str, per_scene: int, rng: np.random.Generator, augment: float,
                ranges=None) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """``per_scene`` candidates around the scene's chrome circle: their crops ``(n, 3, S, S)``
    as 8-bit codes (uint8), targets ``(n, 3)`` and the candidates ``(n, 3)``; None when the
    render is missing. A share ``augment`` of them is cropped from the linear EXR and drawn
    through :func:`relight.probe.locator.camera_pipeline`."""
    from relight.imageio import load_image, read_exr
    from relight.probe import locator
    from relight.probe import outline_check as oc
    png = json_path[:-5] + f".{renderer}.png"
    if not os.path.exists(png):
        return None
    with open(json_path) as f:
        truth = json.load(f)["truth"]["chrome_circle"]
    cands, targets = oc.sample_candidates(truth, per_scene, rng)
    codes = load_image(png)[0].astype(np.float32)     # sRGB codes in 0-1
    crops = np.stack([oc.crop(codes, c) for c in cands]).transpose(0, 3, 1, 2)
    pick = rng.random(per_scene) < augment
    if pick.any():
        lin = np.asarray(read_exr(json_path[:-5] + f".{renderer}.exr"), np.float32)[..., :3]
        crops[pick] = locator.camera_pipeline(np.stack([oc.crop(lin, c) for c in cands[pick]]), rng, ranges)
    return np.round(crops * 255).astype(np.uint8), targets, cands


def evaluate(path: str, folder: str, per_scene: int) -> None:
    from relight.probe import outline_check as oc
    from relight.probe.detect import read_probe_image
    from relight.imageio import to_srgb8
    rng = np.random.default_rng(12345)
    before, after = [], []
    for json_path in sorted(glob.glob(os.path.join(folder, "probe*.json"))):
        png = json_path[:-5] + ".cycles.png"
        if not os.path.exists(png):
            continue
        with open(json_path) as f:
            tx, ty, tr = json.load(f)["truth"]["chrome_circle"]
        image, clip, _ = read_probe_image(png)
        codes = to_srgb8(image / clip) / 255.0
        cands, _ = oc.sample_candidates((tx, ty, tr), per_scene, rng)
        pred = oc.predict(codes, cands, path)
        before += list(np.hypot(cands[:, 0] - tx, cands[:, 1] - ty) / tr)
        after += list(np.hypot(pred[:, 0] - tx, pred[:, 1] - ty) / tr)
        after_r = np.abs(np.log(pred[:, 2] / tr))
    b, a = np.array(before), np.array(after)
    print(f"{folder}: {len(a)} candidates; centre off (radii) before median {np.median(b):.3f} p90 "
          f"{np.percentile(b, 90):.3f}; after median {np.median(a):.3f} p90 {np.percentile(a, 90):.3f} "
          f"p99 {np.percentile(a, 99):.3f} max {a.max():.3f}; within 0.1: {100 * (a <= 0.1).mean():.1f}%, "
          f"within a third: {100 * (a <= 1 / 3).mean():.1f}%", flush=True)


def main() -> None:
    from relight.commands import argtypes as at
    ap = at.OneLineParser(description=__doc__.splitlines()[0])
    ap.add_argument("--train", help="folder of probe scenes with Mitsuba renders")
    ap.add_argument("--test", nargs="*", default=[], help="folders of probe scenes with Cycles renders")
    ap.add_argument("--epochs", type=at.int_in(1, 1000, "an epoch count"), default=12)
    ap.add_argument("--limit", type=at.int_in(1, 10 ** 6, "a scene count"), default=10 ** 6,
                    help="train on the first N scenes (by name)")
    ap.add_argument("--per-scene", type=at.int_in(1, 1000, "a candidate count"), default=24,
                    help="candidate circles drawn per scene")
    ap.add_argument("--augment", type=at.float_in(0.0, 1.0, "a probability"), default=0.5,
                    help="share of candidates cropped from the linear EXR through a camera pipeline")
    at.add_weights_options(ap)
    args = ap.parse_args()
    at.checked_weights_options(ap, args, args.train)
    import torch

    from relight.net.augment import PipelineAugment   # the photo pipeline's ranges
    from relight.probe import outline_check as oc
    torch.set_num_threads(2)
    path = args.load
    if args.train:
        from tqdm import tqdm
        rng = np.random.default_rng(0)
        paths = sorted(glob.glob(os.path.join(args.train, "probe*.json")))[:args.limit]
        items = [scene_crops(p, "mitsuba", args.per_scene, rng, args.augment, PipelineAugment())
                 for p in tqdm(paths, desc="crops", unit="scene")]
        used = [p for p, i in zip(paths, items) if i is not None]
        items = [i for i in items if i is not None]
        if not items:
            raise SystemExit(f"no Mitsuba renders of probe scenes in {args.train}")
        crops, targets = np.concatenate([i[0] for i in items]), np.concatenate([i[1] for i in items])
        print(f"training on {len(crops)} candidates of {len(items)} scenes", flush=True)
        t0 = time.time()
        net = oc.train(crops, targets, args.epochs,
                       progress=lambda m: print(f"{m} ({time.time() - t0:.0f} s)", flush=True))
        if args.save:
            from relight.probe.locator import save_weights
            save_weights(net, args.save, {"scenes": len(items), "first": os.path.basename(used[0]),
                                          "last": os.path.basename(used[-1]), "epochs": args.epochs,
                                          "per_scene": args.per_scene, "augment": args.augment})
            path = args.save
            oc.load_check.cache_clear()
    for folder in args.test:
        if path is None:
            raise SystemExit("--test needs --save or --load (the check reads its weights from a file)")
        evaluate(path, folder, 8)


if __name__ == "__main__":
    from relight.commands import argtypes
    sys.exit(argtypes.run_script(main))

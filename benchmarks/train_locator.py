"""Train the learned chrome-sphere locator (relight.probe.locator) and judge it alone.

Training: the Mitsuba renders of generated probe scenes (``bench_probe.py --make N --first
100000 --no-cycles``: seeds disjoint from every set it is judged on), their 8-bit PNGs as
stored and, on a share of them (``--augment``), a camera pipeline drawn on their linear EXR.
Judged on the Cycles renders of the tuning and held-out sets (a renderer it never saw):
miss rate (centre more than a third of the radius off, the benchmark's rule), centre and
radius errors, and with ``--probe`` the light's direction when its circle is given to
``relight probe``. How the detector uses it (a prior on its pick) is judged by
``bench_probe.py``. The shipped weights: ``bash scripts/train_locator.sh``.

    python benchmarks/train_locator.py --train ~/relight-data/issue-29/detector-train --limit 1214 \\
        --epochs 16 --augment 0.5 --save relight/models/probe_locator.safetensors \\
        --test ~/relight-data/issue-29/set ~/relight-data/issue-29/heldout ~/relight-data/issue-29/heldout2
"""
from __future__ import annotations

import glob
import json
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def load_scene(json_path: str, renderer: str, linear: bool = False
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None] | None:
    """The scene's 8-bit render as the locator sees it (:func:`relight.probe.locator.network_input`),
    its chrome circle in those pixels and (``linear``) its linear EXR resized alike
    (``(S, S, 3)``, for the camera pipeline; else None); None when the render is missing."""
    import cv2

    from relight.imageio import load_image
    from relight.probe.locator import network_input
    path = json_path[:-5] + f".{renderer}.png"
    if not os.path.exists(path):
        return None
    with open(json_path) as f:
        cx, cy, r = json.load(f)["truth"]["chrome_circle"]
    pixels, (sx, sy) = network_input(load_image(path)[0])
    circle = np.array([cx, cy, r], np.float32) / np.array([sx, sy, sx], np.float32)
    exr = None
    if linear:
        from relight.imageio import read_exr
        exr = np.asarray(read_exr(json_path[:-5] + f".{renderer}.exr"), np.float32)
        h, w = pixels.shape[1:]
        how = cv2.INTER_NEAREST if w > exr.shape[1] else cv2.INTER_AREA
        exr = cv2.resize(exr, (w, h), interpolation=how)
    return pixels, circle, exr


def evaluate(net_path: str, folder: str, probe: bool) -> None:
    from relight.errors import ProbeError
    from relight.metrics import angle_deg
    from relight.probe import locator
    from relight.probe.detect import read_probe_image
    from relight.probe.run import ProbeConfig, run_probe
    rows = []
    for json_path in sorted(glob.glob(os.path.join(folder, "probe*.json"))):
        png = json_path[:-5] + ".cycles.png"
        if not os.path.exists(png):
            continue
        with open(json_path) as f:
            truth = json.load(f)["truth"]
        image, clip, _ = read_probe_image(png)
        found = locator.locate(image, clip, net_path).circle
        tx, ty, tr = truth["chrome_circle"]
        off = math.hypot(found[0] - tx, found[1] - ty)
        err = float("nan")
        if probe:
            try:
                res = run_probe(ProbeConfig(chrome=png, chrome_circle=found, fov_deg=truth["fov_deg"],
                                            circle_tolerance_px=max(1.0, 0.1 * found[2])))
                err = float(angle_deg(res.entry["to_light_camera"], truth["to_light_camera"]))
            except ProbeError:
                err = 180.0
        rows.append((off, found[2] - tr, off > tr / 3.0, err))
    a = np.array(rows, float)
    print(f"{folder}: n {len(a)}  misses {int(a[:, 2].sum())} ({100 * a[:, 2].mean():.1f}%)  centre error median "
          f"{np.median(a[:, 0]):.2f} px  radius error median {np.median(a[:, 1]):+.2f} px", flush=True)
    if probe:
        e = a[:, 3]
        print(f"    direction, its circle given to relight probe: median {np.median(e):.2f} p90 "
              f"{np.percentile(e, 90):.2f} max {np.max(e):.2f}", flush=True)


def main() -> None:
    from relight.commands import argtypes as at
    ap = at.OneLineParser(description=__doc__.splitlines()[0])
    ap.add_argument("--train", help="folder of probe scenes with Mitsuba renders")
    ap.add_argument("--test", nargs="*", default=[], help="folders of probe scenes with Cycles renders")
    ap.add_argument("--epochs", type=at.int_in(1, 1000, "an epoch count"), default=16)
    ap.add_argument("--limit", type=at.int_in(1, 10 ** 6, "a scene count"), default=10 ** 6,
                    help="train on the first N scenes (by name)")
    ap.add_argument("--augment", type=at.float_in(0.0, 1.0, "a probability"), default=0.5,
                    help="share of training images drawn through a camera pipeline from their linear EXR")
    at.add_weights_options(ap)
    ap.add_argument("--probe", action="store_true", help="also the direction with its circle given")
    args = ap.parse_args()
    at.checked_weights_options(ap, args, args.train)
    import torch

    from relight.net.augment import PipelineAugment   # the photo pipeline's ranges
    from relight.probe import locator
    torch.set_num_threads(2)
    path = args.load
    if args.train:
        paths = sorted(glob.glob(os.path.join(args.train, "probe*.json")))[:args.limit]
        items = [(p, load_scene(p, "mitsuba", linear=args.augment > 0)) for p in paths]
        items = [(p, i) for p, i in items if i is not None]
        if not items:
            raise SystemExit(f"no Mitsuba renders of probe scenes in {args.train}")
        if len({i[0].shape for _, i in items}) > 1:
            raise SystemExit("training scenes must be square (one input size)")
        linear = np.stack([i[2] for _, i in items]) if args.augment > 0 else None
        print(f"training on {len(items)} scenes", flush=True)
        t0 = time.time()
        net = locator.train(np.stack([i[0] for _, i in items]), np.stack([i[1] for _, i in items]), args.epochs,
                            linear=linear, augment_p=args.augment, ranges=PipelineAugment(),
                            progress=lambda m: print(f"{m} ({time.time() - t0:.0f} s)", flush=True))
        if args.save:
            locator.save_weights(net, args.save, {"scenes": len(items), "first": os.path.basename(items[0][0]),
                                                  "last": os.path.basename(items[-1][0]), "epochs": args.epochs,
                                                  "augment": args.augment})
            path = args.save
    for folder in args.test:
        if path is None:
            raise SystemExit("--test needs --save or --load (the locator reads its weights from a file)")
        evaluate(path, folder, args.probe)


if __name__ == "__main__":
    from relight.commands import argtypes
    sys.exit(argtypes.run_script(main))

"""Proxy study: a learned chrome-sphere detector for ``relight probe`` (issue 29, after the
eleventh round: the hand-written detector's rules, fitted to 40 scenes, do not carry to
held-out scenes). Not part of the procedure: it answers whether a small network trained on
generated probe scenes finds the chrome sphere on scenes and a renderer it never saw.

The network sees the 8-bit image scaled to ``--size`` square and, for each cell of an
8-pixel grid, says how likely the sphere's centre lies there (a softmax over the grid:
there is one chrome sphere per scene), where in the cell, and the log of its radius.
Training: Mitsuba renders of probe scenes (``bench_probe.py --make N --first 100000
--no-cycles``); judged on the Cycles renders of the tuning and held-out sets: miss rate
(centre more than a third of the radius off, the benchmark's rule), centre and radius
errors, and the light's direction with the found circle given to ``relight probe``
(refined within a tolerance of 10% of its radius, at least 1 px).

    python benchmarks/proxy_detector.py --train ~/relight-data/issue-29/detector-train \\
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

STRIDE = 8   # output cells of 8 x 8 input pixels


def load_scene(json_path: str, renderer: str, size: int) -> tuple[np.ndarray, np.ndarray, dict] | None:
    """The scene's 8-bit render scaled to ``size`` square (float32 ``(3, size, size)`` in
    0-1, sRGB codes as stored) and its chrome circle in those pixels; None when the render
    is missing."""
    from PIL import Image
    path = json_path[:-5] + f".{renderer}.png"
    if not os.path.exists(path):
        return None
    with open(json_path) as f:
        truth = json.load(f)["truth"]
    img = Image.open(path).convert("RGB")
    scale = size / img.width
    pixels = np.asarray(img.resize((size, size), Image.BOX), np.float32).transpose(2, 0, 1) / 255.0
    cx, cy, r = truth["chrome_circle"]
    return pixels, np.array([cx * scale, cy * scale, r * scale], np.float32), truth


def build_net():
    import torch
    from torch import nn

    def block(cin, cout, stride=1, dilation=1):
        return nn.Sequential(nn.Conv2d(cin, cout, 3, stride, dilation, dilation, bias=False),
                             nn.BatchNorm2d(cout), nn.ReLU(inplace=True))
    body = nn.Sequential(block(3, 24, 2), block(24, 32), block(32, 48, 2), block(48, 48), block(48, 64, 2),
                         block(64, 64), block(64, 96, dilation=2), block(96, 96, dilation=4),
                         block(96, 96, dilation=8))
    torch.manual_seed(0)
    return nn.Sequential(body, nn.Conv2d(96, 4, 1))   # centre logit, offset x, offset y, log radius


def targets(circles: np.ndarray, cells: int):
    """Cell index, in-cell offset (0-1) and log radius (in cells) of each circle."""
    gx = np.clip((circles[:, 0] / STRIDE).astype(int), 0, cells - 1)
    gy = np.clip((circles[:, 1] / STRIDE).astype(int), 0, cells - 1)
    off = np.stack([circles[:, 0] / STRIDE - gx, circles[:, 1] / STRIDE - gy], 1)
    return gy * cells + gx, off.astype(np.float32), np.log(circles[:, 2] / STRIDE).astype(np.float32)


def decode(out) -> np.ndarray:
    """``(n, 3)`` circles (cx, cy, r) in input pixels from the network's output."""
    n, _, h, w = out.shape
    idx = out[:, 0].reshape(n, -1).argmax(1)
    gy, gx = idx // w, idx % w
    rows = np.arange(n)
    ox = out[rows, 1, gy, gx]
    oy = out[rows, 2, gy, gx]
    return np.stack([(gx + ox) * STRIDE, (gy + oy) * STRIDE, np.exp(out[rows, 3, gy, gx]) * STRIDE], 1)


def train(images: np.ndarray, circles: np.ndarray, epochs: int, seed: int = 0):
    import torch
    from torch.nn import functional as F
    net = build_net()
    opt = torch.optim.AdamW(net.parameters(), 2e-3, weight_decay=1e-4)
    steps = epochs * math.ceil(len(images) / 32)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, 2e-3, total_steps=steps)
    rng = np.random.default_rng(seed)
    size = images.shape[-1]
    cells = size // STRIDE
    for epoch in range(epochs):
        net.train()
        order = rng.permutation(len(images))
        t0, total = time.time(), 0.0
        for b in range(0, len(order), 32):
            sel = order[b:b + 32]
            x, c = images[sel].copy(), circles[sel].copy()
            flip = rng.random(len(sel)) < 0.5          # mirror left-right
            x[flip] = x[flip][..., ::-1]
            c[flip, 0] = size - c[flip, 0]
            x = np.clip(x * rng.uniform(0.6, 1.4, (len(sel), 1, 1, 1)), 0.0, 1.0).astype(np.float32)   # exposure
            idx, off, logr = targets(c, cells)
            out = net(torch.from_numpy(np.ascontiguousarray(x)))
            n = len(sel)
            rows = torch.arange(n)
            gy, gx = torch.from_numpy(idx // cells), torch.from_numpy(idx % cells)
            loss = (F.cross_entropy(out[:, 0].reshape(n, -1), torch.from_numpy(idx))
                    + F.l1_loss(out[rows, 1:3, gy, gx], torch.from_numpy(off))
                    + F.l1_loss(out[rows, 3, gy, gx], torch.from_numpy(logr)))
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach()) * n
        print(f"epoch {epoch + 1}/{epochs}: loss {total / len(images):.3f} ({time.time() - t0:.0f} s)", flush=True)
    return net


def evaluate(net, folder: str, size: int, probe: bool) -> None:
    import torch

    from relight.errors import ProbeError
    from relight.metrics import angle_deg
    from relight.probe.run import ProbeConfig, run_probe
    net.eval()
    rows = []
    for json_path in sorted(glob.glob(os.path.join(folder, "probe*.json"))):
        item = load_scene(json_path, "cycles", size)
        if item is None:
            continue
        pixels, circle, truth = item
        with torch.no_grad():
            found = decode(net(torch.from_numpy(pixels[None])).numpy())[0]
        scale = truth["chrome_circle"][2] / circle[2]
        found_px = found * scale
        tx, ty, tr = truth["chrome_circle"]
        off = math.hypot(found_px[0] - tx, found_px[1] - ty)
        err = float("nan")
        if probe:
            try:
                res = run_probe(ProbeConfig(chrome=json_path[:-5] + ".cycles.png", chrome_circle=tuple(found_px),
                                            fov_deg=truth["fov_deg"],
                                            circle_tolerance_px=max(1.0, 0.1 * float(found_px[2]))))
                err = float(angle_deg(res.entry["to_light_camera"], truth["to_light_camera"]))
            except ProbeError:
                err = 180.0
        rows.append((off, found_px[2] - tr, off > tr / 3.0, err, tr))
    a = np.array(rows, float)
    print(f"{folder}: n {len(a)}  misses {int(a[:, 2].sum())} ({100 * a[:, 2].mean():.1f}%)  centre error median "
          f"{np.median(a[:, 0]):.2f} px  radius error median {np.median(a[:, 1]):+.2f} px", flush=True)
    if probe:
        e = a[:, 3]
        print(f"    direction, found circle given to relight probe: median {np.median(e):.2f} p90 "
              f"{np.percentile(e, 90):.2f} max {np.max(e):.2f}", flush=True)


def main() -> None:
    from relight.commands import argtypes as at
    ap = at.OneLineParser(description=__doc__.splitlines()[0])
    ap.add_argument("--train", required=True, help="folder of probe scenes with Mitsuba renders")
    ap.add_argument("--test", nargs="+", required=True, help="folders of probe scenes with Cycles renders")
    ap.add_argument("--size", type=at.int_in(64, 1024, "an image size"), default=256)
    ap.add_argument("--epochs", type=at.int_in(1, 1000, "an epoch count"), default=12)
    ap.add_argument("--limit", type=at.int_in(1, 10 ** 6, "a scene count"), default=10 ** 6)
    ap.add_argument("--no-probe", action="store_true", help="circles only, no direction")
    args = ap.parse_args()
    if args.size % STRIDE:
        raise SystemExit(f"--size must be a multiple of {STRIDE}")
    import torch
    torch.set_num_threads(2)
    items = [load_scene(p, "mitsuba", args.size)
             for p in sorted(glob.glob(os.path.join(args.train, "probe*.json")))[:args.limit]]
    items = [i for i in items if i is not None]
    if not items:
        raise SystemExit(f"no Mitsuba renders of probe scenes in {args.train}")
    print(f"training on {len(items)} scenes ({args.size} px)", flush=True)
    net = train(np.stack([i[0] for i in items]), np.stack([i[1] for i in items]), args.epochs)
    for folder in args.test:
        evaluate(net, folder, args.size, not args.no_probe)


if __name__ == "__main__":
    from relight.commands import argtypes
    sys.exit(argtypes.run_script(main))

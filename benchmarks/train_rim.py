"""Train the learned rim reader (relight.probe.rim) and judge it alone.

Training: the Mitsuba and Cycles PNG renders of generated probe scenes (``bench_probe.py
--make``; the shipped weights: ``bash scripts/train_rim.sh``, seeds 30000-30299 and
31000-31149, disjoint from every set they are judged on). For each render the rim fit
(:func:`relight.probe.detect.outer_rim_fit`) is started at the true outline, its circle
moved by :data:`relight.probe.rim.TRAIN_JITTER_PX` (``--copies`` draws per render), and
each radial line's profile is paired with how far out the true outline lies on it.

Judged (``--test``) on Cycles renders of other scenes, the rim fit started at the truth as
in training but not moved: the circle's error with the one shift for the whole rim
(:func:`relight.probe.detect.outline_from_rim`) and read by the network
(:func:`relight.probe.rim.read_outline`), and the error the circle alone puts into the
light's direction (the reflected view ray at the true highlight's pixel, on the fitted
sphere against the true one). How the detector does with it is judged by ``bench_probe.py``.

    python benchmarks/train_rim.py --train ~/relight-data/issue-29/train-team ~/relight-data/issue-29/train-held \\
        --save relight/models/probe_rim.safetensors --test ~/relight-data/issue-29/team21
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


def rim_start(json_path: str, renderer: str):
    """A render's smoothed edge image, camera, true sphere, truth and the rim fit started
    at the true outline (:func:`fit_from_truth`); None when the render is missing."""
    from relight.probe import detect
    from relight.probe import geometry as geom
    from relight.probe.run import ProbeConfig
    png = json_path[:-5] + f".{renderer}.png"
    if not os.path.exists(png):
        return None
    with open(json_path) as f:
        truth = json.load(f)["truth"]
    image, clip, _ = detect.read_probe_image(png)
    camera = ProbeConfig(chrome=png, fov_deg=truth["fov_deg"]).camera(image.shape[1], image.shape[0])
    true_sphere = geom.sphere_from_circle(camera, *truth["chrome_circle"])
    return (*fit_from_truth(image, clip, camera, true_sphere), camera, true_sphere, truth)


def fit_from_truth(image: np.ndarray, clip, camera, true_sphere):
    """``(smoothed edge image, rim fit, rim shift)``: the detector's rim fit
    (:func:`relight.probe.detect.outer_rim_fit`) started at the true outline."""
    from relight.probe import detect
    view, clip = detect.detection_view(image, clip)
    smoothed = detect.edge_image(image, clip)
    shift = detect.chrome_rim_shift_px(view)
    fit = detect.outer_rim_fit(smoothed, camera, detect.outline_from_rim(camera, true_sphere, -shift))
    return smoothed, fit, shift


def distant_room(seed: int):
    """A mirror sphere in a distant surrounding, drawn from ``seed``: ``(8-bit codes decoded
    to linear (H, W, 3), camera, sphere)``. Every view ray and every reflected ray sees the
    same surrounding (a horizon at a random tilt, a dim sky above, a lit, striped or
    chequered ground below, bright patches, a small light), so the image is continuous
    across the rim, as in a photograph of a ball far from what it mirrors; 4x4 samples a
    pixel, then a camera's exposure, noise, blur and tone curve
    (:func:`relight.probe.locator.camera_pipeline`). The generated renders and the
    photographed ones lack this case (their rooms are near the ball)."""
    from relight.colour import srgb_decode
    from relight.net.augment import PipelineAugment
    from relight.probe import geometry as geom
    from relight.probe.locator import camera_pipeline
    rng = np.random.default_rng(seed)
    w = int(rng.integers(128, 321))
    h = int(rng.integers(96, 241))
    camera = geom.Camera.from_fov(w, h, float(rng.uniform(20, 60)))
    r_px = float(np.exp(rng.uniform(np.log(8), np.log(40))))
    r_px = min(r_px, 0.4 * min(w, h))
    x, y = rng.uniform(r_px + 4, w - r_px - 4), rng.uniform(r_px + 4, h - r_px - 4)
    _, d = camera.rays(np.array(x), np.array(y))
    alpha = math.atan(r_px / camera.focal_px)
    sphere = geom.Sphere(tuple((d * 5.0).tolist()), 5.0 * math.sin(alpha))
    tilt = rng.uniform(-0.5, 0.5, 2)
    up = np.array([math.sin(tilt[1]), math.cos(tilt[0]) * math.cos(tilt[1]), math.sin(tilt[0])])
    soft = float(np.exp(rng.uniform(np.log(0.005), np.log(0.1))))
    sky, ground = rng.uniform(0.01, 0.3, 3), rng.uniform(0.05, 0.7, 3)
    freq, phase = rng.uniform(2, 20), rng.uniform(0, 2 * np.pi)
    stripe_dir = rng.normal(size=3)
    chequer = rng.random() < 0.5
    patches = [(v / np.linalg.norm(v), rng.uniform(0.05, 0.4), rng.uniform(0.3, 3.0, 3))
               for v in rng.normal(size=(int(rng.integers(0, 5)), 3))]
    light = rng.normal(size=3)
    light[1] = abs(light[1])
    light /= np.linalg.norm(light)
    light_cos, light_radiance = math.cos(math.radians(rng.uniform(1, 4))), rng.uniform(20, 100)

    def seen(v):
        height = v @ up
        t = v @ stripe_dir
        texture = (np.sign(np.sin(freq * v[..., 0] / (np.abs(height) + 0.2)) * np.sin(freq * v[..., 2] /
                   (np.abs(height) + 0.2))) if chequer else np.sin(freq * t + phase))
        below = 1.0 / (1.0 + np.exp(height / soft))
        out = sky * (1.0 + 0.5 * height[..., None]) + below[..., None] * (ground * (0.7 + 0.3 * texture[..., None]) - sky)
        for axis, cos_r, rad in patches:
            out = np.where((v @ axis > 1 - cos_r * 0.1)[..., None], rad, out)
        return np.where((v @ light > light_cos)[..., None], light_radiance, out)

    lin = np.zeros((h, w, 3))
    for i in range(4):
        for j in range(4):
            ys, xs = np.mgrid[0:h, 0:w] + (np.array([i, j])[:, None, None] + 0.5) / 4
            s = geom.surface(camera, sphere, xs, ys)
            _, view = camera.rays(xs, ys)
            lin += np.where(s["hit"][..., None], seen(s["reflect"]), seen(view))
    codes = camera_pipeline((lin / 16.0)[None].astype(np.float32), rng, PipelineAugment())[0].transpose(1, 2, 0)
    return srgb_decode(np.round(codes * 255) / 255), camera, sphere


def lines_from(smoothed, fit, camera, true_sphere, copies: int, rng: np.random.Generator):
    """``copies`` draws of one image's lines around its rim fit moved off by
    :data:`relight.probe.rim.TRAIN_JITTER_PX`: features ``(copies * LINES, k)`` and targets
    (px, how far out the true outline lies on each line)."""
    from relight.probe import detect
    from relight.probe import geometry as geom
    from relight.probe import rim
    xs, ys = [], []
    cx, cy, r = geom.outline_circle(camera, fit)
    for _ in range(copies):
        j = rim.TRAIN_JITTER_PX
        moved = geom.sphere_from_circle(camera, cx + rng.normal(0, j), cy + rng.normal(0, j), r + rng.normal(0, j / 2))
        samples, points, _ = rim.profiles(smoothed, camera, moved)
        xs.append(rim.features(samples))
        ys.append(-detect._outline_distance(camera, true_sphere, points[:, 0], points[:, 1]))
    return np.concatenate(xs), np.concatenate(ys).astype(np.float32)


def scene_lines(json_path: str, renderer: str, copies: int, seed: int):
    """:func:`lines_from` one render of a probe scene, or None when it is missing."""
    start = rim_start(json_path, renderer)
    if start is None:
        return None
    smoothed, fit, _, camera, true_sphere, _ = start
    return lines_from(smoothed, fit, camera, true_sphere, copies, np.random.default_rng(seed))


def room_lines(seed: int, copies: int):
    """:func:`lines_from` one :func:`distant_room`."""
    image, camera, true_sphere = distant_room(seed)
    smoothed, fit, _ = fit_from_truth(image, 1.0, camera, true_sphere)
    return lines_from(smoothed, fit, camera, true_sphere, copies, np.random.default_rng(seed))


def judge(start, path: str, light=True):
    """One image from :func:`rim_start` (or a distant room's, ``light`` False):
    ``[(dx, dy, dr, light error deg or nan) one shift, (...) read]``."""
    from relight.probe import detect
    from relight.probe import geometry as geom
    from relight.probe import rim
    smoothed, fit, shift, camera, true_sphere, truth = start
    shifted = detect.outline_from_rim(camera, fit, shift)
    read, _ = rim.read_outline(smoothed, camera, fit, shifted, path)
    true_circle = geom.outline_circle(camera, true_sphere)
    rows = []
    for sphere in (shifted, read):
        c = geom.outline_circle(camera, sphere)
        err = float("nan")
        if light:
            px, _ = geom.predict_highlight(camera, true_sphere, truth["to_light_camera"])
            want = geom.reflected_direction(camera, true_sphere, px[0], px[1])
            got = geom.reflected_direction(camera, sphere, px[0], px[1])
            err = math.degrees(math.acos(float(np.clip(got @ want, -1.0, 1.0))))
        rows.append((c[0] - true_circle[0], c[1] - true_circle[1], c[2] - true_circle[2], err))
    return rows


def report(name: str, rows: list) -> None:
    for label, k in (("one shift", 0), ("read", 1)):
        v = np.array([r[k] for r in rows])
        c = np.hypot(v[:, 0], v[:, 1])
        light = ("" if np.isnan(v[:, 3]).all() else f"; light from the circle alone median {np.median(v[:, 3]):.2f} "
                 f"p90 {np.percentile(v[:, 3], 90):.2f} max {v[:, 3].max():.2f} deg")
        print(f"{name} {label}: n {len(v)}; centre off median {np.median(c):.3f} p90 {np.percentile(c, 90):.3f} px, "
              f"dy median {np.median(v[:, 1]):+.3f}, dr median {np.median(v[:, 2]):+.3f}, |dr| median "
              f"{np.median(np.abs(v[:, 2])):.3f} px{light}", flush=True)


def main() -> None:
    from relight.commands import argtypes as at
    ap = at.OneLineParser(description=__doc__.splitlines()[0])
    ap.add_argument("--train", nargs="*", default=[], help="folders of probe scenes with Mitsuba and/or Cycles renders")
    ap.add_argument("--test", nargs="*", default=[], help="folders of probe scenes with Cycles renders")
    ap.add_argument("--epochs", type=at.int_in(1, 1000, "an epoch count"), default=8)
    ap.add_argument("--copies", type=at.int_in(1, 100, "a draw count"), default=2,
                    help="rim fits drawn off the truth per render")
    ap.add_argument("--rooms", type=at.int_in(0, 10 ** 6, "a count"), default=0,
                    help="also train on this many distant rooms (seeds 0..N-1, drawn here, nothing stored)")
    ap.add_argument("--test-rooms", type=at.int_in(0, 10 ** 6, "a count"), default=0,
                    help="judge on this many distant rooms (seeds from 1,000,000)")
    at.add_weights_options(ap)
    args = ap.parse_args()
    at.checked_weights_options(args, args.train, "FOLDER...")
    import torch
    from tqdm import tqdm

    from relight.probe import rim
    torch.set_num_threads(2)
    path = args.load
    if args.train:
        paths = sorted(p for folder in args.train for p in glob.glob(os.path.join(folder, "probe*.json")))
        items = []
        for i, p in enumerate(tqdm(paths, desc="profiles", unit="scene")):
            for k, renderer in enumerate(("mitsuba", "cycles")):
                item = scene_lines(p, renderer, args.copies, 2 * i + k)
                if item is not None:
                    items.append(item)
        for seed in tqdm(range(args.rooms), desc="rooms", unit="room"):
            items.append(room_lines(seed, args.copies))
        if not items:
            raise SystemExit(f"no renders of probe scenes in {' '.join(args.train)}")
        x, y = np.concatenate([i[0] for i in items]), np.concatenate([i[1] for i in items])
        keep = np.isfinite(y) & (np.abs(y) < 2.5)      # a line that missed the outline altogether
        print(f"training on {int(keep.sum())} lines of {len(items)} renders", flush=True)
        t0 = time.time()
        net = rim.train(x[keep], y[keep], args.epochs,
                        progress=lambda m: print(f"{m} ({time.time() - t0:.0f} s)", flush=True))
        if args.save:
            from relight.probe.locator import save_weights
            save_weights(net, args.save, {"renders": len(items), "lines": int(keep.sum()), "epochs": args.epochs,
                                          "copies": args.copies, "rooms": args.rooms,
                                          "folders": " ".join(os.path.basename(f.rstrip("/")) for f in args.train)})
            path = args.save
            rim.load_rim.cache_clear()
    if (args.test or args.test_rooms) and path is None:
        raise SystemExit("--test needs --save or --load (the reader reads its weights from a file)")
    for folder in args.test:
        starts = (rim_start(p, "cycles") for p in sorted(glob.glob(os.path.join(folder, "probe*.json"))))
        report(folder, [judge(s, path) for s in starts if s is not None])
    if args.test_rooms:
        rows = []
        for seed in range(10 ** 6, 10 ** 6 + args.test_rooms):
            image, camera, true_sphere = distant_room(seed)
            rows.append(judge((*fit_from_truth(image, 1.0, camera, true_sphere), camera, true_sphere, None), path, False))
        report("distant rooms", rows)


if __name__ == "__main__":
    from relight.commands import argtypes
    sys.exit(argtypes.run_script(main))

"""Benchmark of the sphere procedure (``relight probe``): direction error of the chrome
sphere's highlight on perspective validation renders with known light (plain and with
clutter, front and back light) and on the real photographs in shared/data/psm_spheres.

Renders are saved as 8-bit sRGB PNG (highlights clip, as in a camera) and read back
through the same path as the command line. Methods:

- circle given: the circle closest to the true outline (what a person would mark),
  refined on the image's edges, perspective camera with the true field of view;
- automatic: no circle, the spheres found by the procedure;
- orthographic + mask (the previous procedure, relight.probe.ortho): for comparison.

    .venv/bin/python benchmarks/bench_probe.py [--count 12] [--spp 64] [--keep DIR]
"""
from __future__ import annotations

import os
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from relight.commands import argtypes as at  # noqa: E402

PSM = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "shared", "data",
                   "psm_spheres")
TARGETS = {"renders, circle given": (0.5, 2.0), "renders with clutter, automatic": (1.0, None),
           "psm_spheres, mask": (2.0, None)}


def _angle_deg(a, b) -> float:
    from relight.metrics import angle_deg
    return float(angle_deg(a, b))

def _probe(path: str, **kw):
    from relight.probe.run import ProbeConfig, run_probe
    return run_probe(ProbeConfig(chrome=path, **kw))


def _renders(args, folder: str, rows: list, qa_dir: str | None) -> None:
    from tqdm import tqdm

    from relight.probe import geometry as geom
    from relight.probe import ortho as probes
    from relight.probe.geometry import ProbeError
    from relight.probe.run import write_qa
    from relight.imageio import write_png
    from relight.verify import probe_scenes

    jobs = [(seed, clutter) for clutter in (False, True) for seed in range(args.seed, args.seed + args.count)]
    for seed, clutter in tqdm(jobs, desc="validation renders", unit="scene"):
        scene = probe_scenes.sample_probe_scene(seed, clutter=clutter, front=bool(seed % 2 == 0))
        path = os.path.join(folder, f"scene{seed:03d}{'_clutter' if clutter else ''}.png")
        if not os.path.exists(path):
            write_png(path, probe_scenes.render_probe_scene(scene, spp=args.spp, seed=seed))
        truth = np.asarray(scene.to_light)
        tag = "renders with clutter" if clutter else "renders"
        light = "front" if scene.front else "back"
        res = _probe(path, chrome_circle=scene.circle("chrome"), fov_deg=scene.fov_deg)
        rows.append((f"{tag}, circle given", light, _angle_deg(res.entry["to_light_camera"], truth)))
        if qa_dir:
            write_qa(os.path.join(qa_dir, os.path.basename(path)), res, title=os.path.basename(path))
        try:
            res = _probe(path, fov_deg=scene.fov_deg)
            err = _angle_deg(res.entry["to_light_camera"], truth)
        except ProbeError:
            err = 180.0
        rows.append((f"{tag}, automatic", light, err))
        # the previous procedure: orthographic view, the true sphere's pixel mask
        from relight.probe.detect import read_probe_image
        image = read_probe_image(path)[0]
        cam = scene.camera
        ys, xs = np.mgrid[0:cam.height, 0:cam.width] + 0.5
        mask = geom.surface(cam, scene.chrome, xs, ys)["hit"]
        rows.append((f"{tag}, orthographic + mask (previous)", light,
                     _angle_deg(probes.chrome_light_direction(image, mask), truth)))


def _psm(rows: list, qa_dir: str | None) -> None:
    from relight.probe import ortho as probes
    from relight.probe.detect import load_mask, read_probe_image
    from relight.probe.geometry import ProbeError
    from relight.probe.run import write_qa

    lights = np.loadtxt(os.path.join(PSM, "lights.txt"), skiprows=1)
    mask_path = os.path.join(PSM, "chrome.mask.png")
    mask = load_mask(mask_path)
    for i, truth in enumerate(lights):
        path = os.path.join(PSM, f"chrome.{i}.png")
        res = _probe(path, chrome_mask=mask_path)
        rows.append(("psm_spheres, mask", "front", _angle_deg(res.entry["to_light_camera"], truth)))
        if qa_dir:
            write_qa(os.path.join(qa_dir, f"psm_chrome.{i}.png"), res, title=f"psm chrome.{i}")
        try:
            err = _angle_deg(_probe(path).entry["to_light_camera"], truth)
        except ProbeError:
            err = 180.0
        rows.append(("psm_spheres, automatic", "front", err))
        rows.append(("psm_spheres, orthographic + mask (previous)", "front",
                     _angle_deg(probes.chrome_light_direction(read_probe_image(path)[0], mask), truth)))


def main() -> None:
    ap = at.OneLineParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=at.int_in(1, 100_000, "a count"), default=12, help="scenes per kind (plain, clutter)")
    ap.add_argument("--spp", type=at.spp, default=64)
    ap.add_argument("--seed", type=at.seed, default=100)
    ap.add_argument("--keep", default=None, help="folder to keep the renders (reused) and QA overlays")
    args = ap.parse_args()

    from relight import backend
    backend.init()
    rows: list = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or tmp
        os.makedirs(folder, exist_ok=True)
        qa_dir = os.path.join(folder, "qa") if args.keep else None
        if qa_dir:
            os.makedirs(qa_dir, exist_ok=True)
        _renders(args, folder, rows, qa_dir)
        if os.path.isdir(PSM):
            _psm(rows, qa_dir)
        else:
            print(f"psm_spheres not found at {os.path.normpath(PSM)}; real-photo part skipped")

    print(f"\nsphere procedure benchmark: {args.count} scenes per kind, {args.spp} spp, {backend.describe()}")
    print(f"{'set, method':<52} {'light':>6} {'n':>3} {'median':>7} {'max':>7}  target (median / max)")
    names = list(dict.fromkeys(r[0] for r in rows))
    for name in names:
        for light in ("all", "front", "back"):
            errs = [e for n, lt, e in rows if n == name and (light == "all" or lt == light)]
            if not errs or (light != "all" and len(errs) == len([e for n, _, e in rows if n == name])):
                continue
            target = TARGETS.get(name) if light == "all" else None
            tgt = "" if target is None else f"  <= {target[0]}" + (f" / <= {target[1]}" if target[1] else "")
            print(f"{name:<52} {light:>6} {len(errs):>3} {np.median(errs):7.2f} {np.max(errs):7.2f}{tgt}")


if __name__ == "__main__":
    sys.exit(at.run_script(main))

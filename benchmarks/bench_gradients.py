"""Benchmark: direction-gradient estimators of inverse rendering, bias and cost.

For generated scenes in two groups, *large moving cast shadows* (low light, big
objects) and *small shadows* (light near the zenith, small objects), in one run:

* every estimator of d(loss)/d(light direction) against a fine central-difference
  reference (64 px, 512 spp, h = 0.25 deg, common random numbers), at a point 5 deg
  off the true light: angle to the reference (deg), magnitude ratio |g| / |g_ref|,
  seconds per gradient (median: the first use of a scene structure compiles kernels);
* ``relight invert`` end to end with each Jacobian (``fd``, ``ad``, ``ad-shading``):
  direction and colour errors (deg) and seconds per image.

Estimators: the optimiser's finite differences at both levels; Mitsuba's own AD through
``light.position`` (``path`` integrator, shading term only); ours
(:mod:`relight.inverse.ad`) without and with the shadow-edge (visibility) term.

The scenes are made in memory from the generator's sampler (no dataset needed)::

    python benchmarks/bench_gradients.py            # 6 + 6 scenes at 128 px
    python benchmarks/bench_gradients.py --n 2 --no-invert   # quick look
"""
from __future__ import annotations

import dataclasses
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from relight.commands import argtypes as at  # noqa: E402

REF_RES, REF_SPP, REF_STEP_DEG, REF_SEED = 64, 512, 0.25, 11
OFFSET_DEG = 5.0
GROUPS = {
    # name: generator overrides
    "large shadows": {"light_tilt_deg": (30.0, 45.0), "object_size_m": (1.4, 2.0), "n_objects": (2, 3)},
    "small shadows": {"light_tilt_deg": (80.0, 90.0), "object_size_m": (0.8, 1.0), "n_objects": (1, 1)},
}
TARGETS = "AD+visibility: angle <= 3 deg, ratio 0.9-1.1 (median, large shadows), cost <= 3x FD L1"


def make_scenes(n_per_group: int, res: int, spp: int, seed: int):
    """``[(group, spec, linear image)]``: generated scenes rendered at ``res`` px."""
    from relight.scene.build import SceneBuilder
    from relight.generator.sampling import GeneratorConfig, sample_scene
    out = []
    for g, (name, overrides) in enumerate(GROUPS.items()):
        cfg = GeneratorConfig(res=res, spp=spp, **overrides)
        for i in range(n_per_group):
            spec = sample_scene(cfg, seed + 1000 * g, i)
            spec = dataclasses.replace(spec, id=f"{'LS'[g]}{i:02d}")
            out.append((name, spec, SceneBuilder(max_templates=1).render(spec).astype(np.float64)))
    return out


def estimators():
    """name -> function(renderer, target_at, pan, tilt, r) -> (loss, grad (2,))."""
    from relight.inverse import ad
    from relight.inverse.objective import loss_gradient
    from relight.inverse.optimize import DEFAULT_LEVELS, shading_ad_loss_gradient
    l0, l1 = DEFAULT_LEVELS
    shading = ad.ADSettings(visibility=False)
    return {
        "FD L0 (32px, 8spp, h=2)":
            lambda rd, t, p, q, r: loss_gradient(rd, t(32), p, q, r, l0.spp, 1, l0.fd_step_deg),
        "FD L1 (64px, 32spp, h=0.5)":
            lambda rd, t, p, q, r: loss_gradient(rd, t(64), p, q, r, l1.spp, 2, l1.fd_step_deg),
        "AD Mitsuba path, shading only (64px, 32spp)":
            lambda rd, t, p, q, r: shading_ad_loss_gradient(rd, t(64), p, q, r, 32, 2),
        "AD ours, shading only (64px, 32spp)":
            lambda rd, t, p, q, r: ad.ad_loss_gradient(rd, t(64), p, q, r, 32, 2, settings=shading),
        "AD ours + shadow edges (32px, 8spp)":
            lambda rd, t, p, q, r: ad.ad_loss_gradient(rd, t(32), p, q, r, 8, 1),
        "AD ours + shadow edges (64px, 32spp)":
            lambda rd, t, p, q, r: ad.ad_loss_gradient(rd, t(64), p, q, r, 32, 2),
    }


def gradient_study(scenes, rng):
    from tqdm import tqdm

    from relight.frames import tangent_move
    from relight.inverse.objective import LightRenderer, downsample, loss_gradient
    from relight.scene.build import SceneBuilder
    fns = estimators()
    rows = []   # (group, id, estimator, angle, ratio, seconds)
    ref_cost = []
    for group, spec, image in tqdm(scenes, desc="gradients", unit="scene"):
        renderer = LightRenderer(spec, SceneBuilder(max_templates=2))
        a = rng.uniform(0, 2 * math.pi)
        pan, tilt = tangent_move(spec.pan_rel_deg, spec.light.tilt_deg,
                                 OFFSET_DEG * math.cos(a), OFFSET_DEG * math.sin(a))
        tilt = min(tilt, 90.0)
        r = spec.light.r_m
        targets = {}

        def target_at(res):
            if res not in targets:
                targets[res] = downsample(image, res)
            return targets[res]

        t0 = time.perf_counter()
        _, g_ref = loss_gradient(renderer, target_at(REF_RES), pan, tilt, r, REF_SPP, REF_SEED, REF_STEP_DEG)
        ref_cost.append(time.perf_counter() - t0)
        for name, fn in fns.items():
            t0 = time.perf_counter()
            _, g = fn(renderer, target_at, pan, tilt, r)
            sec = time.perf_counter() - t0
            cos = float(g @ g_ref / (np.linalg.norm(g) * np.linalg.norm(g_ref)))
            rows.append((group, spec.id, name, math.degrees(math.acos(np.clip(cos, -1, 1))),
                         float(np.linalg.norm(g) / np.linalg.norm(g_ref)), sec))
    return rows, fns, ref_cost


def print_gradient_table(rows, names, ref_cost):
    print(f"\n### Direction-gradient estimators vs FD reference ({REF_RES}px, {REF_SPP}spp, "
          f"h={REF_STEP_DEG} deg), {OFFSET_DEG:g} deg off the true light\n")
    print("| estimator | group | scenes | angle (deg) median / max | |g|/|g_ref| median [min, max] "
          "| s per gradient (median) | cost / FD L1 |")
    print("|---|---|---|---|---|---|---|")
    fd1 = np.median([x[5] for x in rows if x[2].startswith("FD L1")])
    for group in GROUPS:
        for name in names:
            sel = [x for x in rows if x[0] == group and x[2] == name]
            if not sel:
                continue
            ang = np.array([x[3] for x in sel])
            rat = np.array([x[4] for x in sel])
            sec = np.median([x[5] for x in rows if x[2] == name])
            print(f"| {name} | {group} | {len(sel)} | {np.median(ang):.2f} / {ang.max():.2f} | "
                  f"{np.median(rat):.3f} [{rat.min():.2f}, {rat.max():.2f}] | {sec:.3f} | {sec / fd1:.2f} |")
    print(f"| FD reference | both | {len(ref_cost)} | 0 | 1 | {np.median(ref_cost):.3f} | "
          f"{np.median(ref_cost) / fd1:.2f} |")
    best = "AD ours + shadow edges (64px, 32spp)"
    sel = [x for x in rows if x[0] == "large shadows" and x[2] == best]
    if sel:
        ang, rat = np.median([x[3] for x in sel]), np.median([x[4] for x in sel])
        cost = np.median([x[5] for x in rows if x[2] == best]) / fd1
        ok = ang <= 3.0 and 0.9 <= rat <= 1.1 and cost <= 3.0
        print(f"\ntarget ({TARGETS}): angle {ang:.2f}, ratio {rat:.3f}, cost {cost:.2f}x -> "
              f"{'met' if ok else 'NOT met'}")


def invert_study(scenes, gradients):
    from tqdm import tqdm

    from relight.inverse.optimize import InvertConfig, invert
    from relight.metrics import light_errors
    from relight.scene.build import SceneBuilder
    out = {g: [] for g in gradients}   # gradient -> [(group, direction, colour, seconds, iterations)]
    for group, spec, image in tqdm(scenes, desc="invert", unit="scene"):
        for g in gradients:
            res = invert(spec, image, "grid", InvertConfig(gradient=g), SceneBuilder(max_templates=2))
            e = light_errors(res.pan_rel_deg, res.tilt_deg, res.rgb, spec.pan_rel_deg,
                             spec.light.tilt_deg, spec.light.rgb)
            out[g].append((group, float(e["direction"]), float(e["colour"]), res.seconds, res.iterations))
    res_px = scenes[0][2].shape[0]
    print(f"\n### relight invert end to end ({len(scenes)} scenes, {res_px} px, grid start)\n")
    print("| gradient | direction (deg) mean / median / max | colour (deg) mean / median | "
          "s / image mean / median | LM iterations |")
    print("|---|---|---|---|---|")
    for g, vals in out.items():
        a = np.array([v[1:] for v in vals])
        print(f"| {g} | {a[:, 0].mean():.3f} / {np.median(a[:, 0]):.3f} / {a[:, 0].max():.3f} | "
              f"{a[:, 1].mean():.3f} / {np.median(a[:, 1]):.3f} | {a[:, 2].mean():.2f} / "
              f"{np.median(a[:, 2]):.2f} | {a[:, 3].mean():.1f} |")
    if "fd" in out and "ad" in out:
        ratio = np.median([v[3] for v in out["ad"]]) / np.median([v[3] for v in out["fd"]])
        d = np.median([v[1] for v in out["ad"]])
        c = np.median([v[2] for v in out["ad"]])
        print(f"\n- seconds per image, ad : fd (same run, medians) = {ratio:.2f} : 1")
        print(f"- target for --gradient ad: median direction <= 0.5 deg (got {d:.3f}), colour <= 0.1 deg "
              f"(got {c:.3f}), <= 3 s per {res_px} px image (got {np.median([v[3] for v in out['ad']]):.2f} s)")
    return out


def main(argv=None) -> int:
    ap = at.OneLineParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=at.int_in(1, 100_000, "a count"), default=6, help="scenes per group (two groups)")
    ap.add_argument("--res", type=at.resolution, default=128, help="target image size (px)")
    ap.add_argument("--spp", type=at.spp, default=64, help="samples per pixel of the targets")
    ap.add_argument("--seed", type=at.seed, default=41)
    ap.add_argument("--no-invert", action="store_true", help="skip the end-to-end study")
    ap.add_argument("--gradients", default="fd,ad,ad-shading", help="Jacobians of the invert study")
    ap.add_argument("--threads", type=at.threads, default=None)
    args = ap.parse_args(argv)
    if args.n < 1 or args.res % 64:
        ap.error("--n >= 1 and --res a multiple of 64 expected")

    from relight import backend
    backend.init(args.threads)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"# bench_gradients: {args.n} + {args.n} scenes, {args.res} px, {backend.describe()}, "
          f"load average {load:.1f}")
    scenes = make_scenes(args.n, args.res, args.spp, args.seed)
    rows, fns, ref_cost = gradient_study(scenes, np.random.default_rng(args.seed))
    print_gradient_table(rows, list(fns), ref_cost)
    if not args.no_invert:
        invert_study(scenes, [g.strip() for g in args.gradients.split(",") if g.strip()])
    return 0


if __name__ == "__main__":
    sys.exit(at.run_script(main))

"""Does a denoiser pay? Intel Open Image Denoise (CPU) on low-spp renders, against
4096-spp references: relative RMSE over the image and in the band of the shading's
edges (shadow boundaries, creases), and the time each way takes.

    .venv/bin/python benchmarks/bench_denoise.py                    # 8 scenes, 128 px (docs/denoise.md)
    .venv/bin/python benchmarks/bench_denoise.py --scenes 2 --res 32 --ref-spp 256   # quick

The scenes are the noise calibration's (``bench_generate.py --calibrate``: generator
defaults, seed 777, multijitter, path depth 4) and so are the references (``independent``
at 4096 spp, another seed). Each low-spp render is scored three ways: as rendered; denoised
from its colour alone; denoised with albedo and normal images (Mitsuba's ``aov``
integrator at ``--aov-spp``, whose time is counted). The denoiser needs the
``pyoidn`` package (``pip install pyoidn``, not a dependency); without it the script
says so in one line and exits 0 (skipped).

Shading-edge band: the shading is the reference over its albedo (the clean albedo of
the same scene at 64 spp), so texture edges are divided out and what is left are the
light's edges: cast and attached shadow boundaries and creases. The band is the 5% of
lit pixels where the gradient of its log luminance is largest; the band error is the
RMSE there over the reference's mean there. A denoiser that blurs or moves a shadow edge
shows it in this figure first, and shadow edges are what the network reads the light's
direction from.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from relight import backend  # noqa: E402
from relight.commands import argtypes as at  # noqa: E402
from relight.generator.sampling import GeneratorConfig, sample_scene  # noqa: E402
from relight.render import render_scene  # noqa: E402
from relight.scene import noise  # noqa: E402
from relight.scene.build import SceneBuilder  # noqa: E402

CALIBRATION_SEED = 777      # the noise calibration's scenes (bench_generate.py)
EDGE_SHARE = 0.05           # the band: this share of lit pixels with the steepest shading
ALBEDO_FLOOR = 0.02         # pixels darker in albedo than this are left out of the band


def luminance(rgb: np.ndarray) -> np.ndarray:
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


def edge_band(reference: np.ndarray, albedo: np.ndarray, share: float = EDGE_SHARE) -> np.ndarray:
    """Boolean mask of the shading-edge band of a reference image (module docstring)."""
    from scipy import ndimage
    a = luminance(np.asarray(albedo, np.float64))
    lit = a > ALBEDO_FLOOR
    shading = luminance(np.asarray(reference, np.float64)) / np.maximum(a, ALBEDO_FLOOR)
    log_s = np.log(np.maximum(shading, 1e-4 * max(float(shading.max()), 1e-12)))
    grad = np.hypot(ndimage.sobel(log_s, axis=0), ndimage.sobel(log_s, axis=1))
    grad[~lit] = -np.inf
    n = max(1, int(round(share * lit.sum())))
    band = np.zeros(grad.shape, bool)
    band.flat[np.argsort(grad, axis=None)[-n:]] = True
    return band & lit


def band_rmse(image: np.ndarray, reference: np.ndarray, band: np.ndarray) -> float:
    """RMSE of ``image`` in ``band`` over the reference's mean there."""
    d = (np.asarray(image, np.float64) - reference)[band]
    return float(np.sqrt(np.mean(d ** 2)) / np.mean(reference[band]))


def spp_list(text: str) -> list[int]:
    """Comma-separated sample counts, each a valid ``--spp``."""
    try:
        return [at.spp(t) for t in text.split(",")]
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"expected sample counts per pixel A,B,... (1-{at.MAX_SPP}), "
                                         f"got {text!r}") from None


def timed(fn, repeats: int):
    """(result of the last call, median seconds over ``repeats`` calls)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, float(np.median(times))


def main() -> int:
    ap = at.OneLineParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", type=at.int_in(1, 1000, "a scene count"), default=8,
                    help="fixed default scenes (default 8)")
    ap.add_argument("--res", type=at.int_in(8, at.MAX_RES, "an image size in pixels"), default=128,
                    help="image size in pixels (default 128)")
    ap.add_argument("--ref-spp", type=at.spp, default=4096, help="reference samples per pixel (default 4096)")
    ap.add_argument("--spp", type=spp_list, default=[1, 2, 4, 8, 16],
                    help="low sample counts to test (default 1,2,4,8,16)")
    ap.add_argument("--aov-spp", type=at.spp, default=4, help="samples of the albedo/normal images (default 4)")
    ap.add_argument("--quality", default="high", choices=("high", "balanced", "fast"),
                    help="denoiser quality (default high)")
    ap.add_argument("--repeats", type=at.int_in(1, 100, "a repeat count"), default=3,
                    help="timing repeats, median (default 3)")
    args = ap.parse_args()
    counts = args.spp
    try:
        import pyoidn as oidn
    except ImportError:
        print("bench_denoise: skipped (needs the pyoidn package: .venv/bin/python -m pip install pyoidn)")
        return 0
    mi = backend.mitsuba()
    aov = mi.load_dict({"type": "aov", "aovs": "al:albedo,nn:sh_normal"})
    builder = SceneBuilder()
    cfg = GeneratorConfig(res=args.res)
    rows: dict[tuple[int, str], list[tuple[float, float, float]]] = {}
    aov_times, ref_means = [], []
    for i in range(args.scenes):
        spec = sample_scene(cfg, CALIBRATION_SEED, i)
        ref_spec = dataclasses.replace(spec, render=dataclasses.replace(
            spec.render, sampler="independent", spp=args.ref_spp, seed=spec.render.seed + 99))
        reference = builder.render(ref_spec).astype(np.float64)
        template = builder.template_for(spec)
        clean = render_scene(template.scene, 64, spec.render.seed + 7, integrator=aov)
        band = edge_band(reference, clean[..., :3])
        ref_means.append(float(reference.mean()))
        render_scene(template.scene, args.aov_spp, 1, integrator=aov)     # warm
        feats, t_aov = timed(lambda: render_scene(template.scene, args.aov_spp, spec.render.seed + 3,
                                                  integrator=aov), args.repeats)
        aov_times.append(t_aov)
        albedo = np.ascontiguousarray(np.clip(feats[..., :3], 0.0, 1.0), np.float32)
        normal = np.ascontiguousarray(np.clip(feats[..., 3:6], -1.0, 1.0), np.float32)
        for spp in counts:
            template.render(spp, 1)                                     # warm: kernel compiled
            image, t_render = timed(lambda: template.render(spp, spec.render.seed), args.repeats)
            colour = np.ascontiguousarray(image, np.float32)
            ways = {
                "plain": (image, 0.0),
                "denoised": timed(lambda: oidn.denoise(colour, hdr=True, quality=args.quality), args.repeats),
                "denoised + aux": timed(lambda: oidn.denoise(colour, albedo, normal, hdr=True,
                                                             quality=args.quality), args.repeats),
            }
            for way, (out, t_extra) in ways.items():
                t = t_render + t_extra + (t_aov if way == "denoised + aux" else 0.0)
                rows.setdefault((spp, way), []).append(
                    (noise.relative_rmse(out, reference), band_rmse(out, reference, band), t))
        print(f"scene {i + 1}/{args.scenes} done", file=sys.stderr, flush=True)

    print(f"# {args.scenes} default scenes (seed {CALIBRATION_SEED}), {args.res}x{args.res}, multijitter; "
          f"reference independent {args.ref_spp} spp; denoiser quality {args.quality}, HDR; "
          f"albedo/normal at {args.aov_spp} spp ({1000 * np.median(aov_times):.1f} ms, counted in + aux)")
    print("| spp | way | relative RMSE (mean) | shading-edge band RMSE (mean) | time per image, ms (median) |")
    print("|---|---|---|---|---|")
    summary = {}
    for (spp, way), vals in sorted(rows.items()):
        v = np.array(vals)
        summary[spp, way] = (float(v[:, 0].mean()), float(v[:, 1].mean()), float(np.median(v[:, 2])))
        e, b, t = summary[spp, way]
        print(f"| {spp} | {way} | {e:.4f} | {b:.4f} | {1000 * t:.1f} |")
    target = noise.DEFAULT_TARGET_RMSE
    base_spp = noise.spp_for_target(target)
    if (base_spp, "plain") in summary:
        e0, b0, t0 = summary[base_spp, "plain"]
        print(f"\n# the generator's default: multijitter {base_spp} spp, relative RMSE {e0:.4f}, "
              f"band {b0:.4f}, {1000 * t0:.1f} ms")
        print("| way | cheapest spp reaching both (RMSE <= default's and band <= default's) | time ratio default / it |")
        print("|---|---|---|")
        for way in ("plain", "denoised", "denoised + aux"):
            hits = [(summary[s, way][2], s) for s in counts if summary[s, way][0] <= e0 and summary[s, way][1] <= b0]
            if hits:
                t, s = min(hits)
                print(f"| {way} | {s} | {t0 / t:.2f} |")
            else:
                print(f"| {way} | none of {counts} | - |")
    return 0


if __name__ == "__main__":
    sys.exit(at.run_script(main))

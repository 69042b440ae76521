"""Generation benchmark: equal-error sampler table, images/s, overhead over the render call.

Equal error (``--calibrate``, also run by default): 8 fixed default scenes (128 px,
path depth 4) rendered with each Mitsuba sampler at the sample counts it takes
exactly; relative RMSE against a 4096-spp ``independent`` reference of each scene
(``relight.scene.noise.relative_rmse``) and render seconds per image, all in one
run. It prints the table, the spp each sampler needs for the target, and the
``CALIBRATION`` literal of :mod:`relight.scene.noise` (paste it there to recalibrate).

Speed, measured in one run on the same scenes (after a warm-up that loads every room
structure once, so both ways run with compiled kernels), at the default noise target:

* template way: ``relight.generator.run.generate`` (one loaded scene per structure, updated
  through ``mi.traverse``), images/s and total time / time inside ``mi.render``;
* naive way: ``mi.load_dict`` a new scene for every image (``build_naive``), same
  rendering and file writing;
* optionally the template way with 2 worker processes.

Where the Blender environment exists (``scripts/setup_blender.sh``), the Cycles
comparison of ``benchmarks/bench_cycles.py`` follows (``--no-cycles`` skips it).

Usage: python benchmarks/bench_generate.py [--n 48] [--res 128] [--spp N | --target-rmse E]
                                           [--workers 2] [--calibrate | --no-calibrate]
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from relight.commands import argtypes as at  # noqa: E402

import dataclasses  # noqa: E402

import numpy as np  # noqa: E402

from relight import backend  # noqa: E402
from relight.generator.run import _write_card, generate  # noqa: E402
from relight.imageio import write_exr, write_png  # noqa: E402
from relight.scene import noise  # noqa: E402
from relight.scene.build import SceneBuilder, build_naive  # noqa: E402
from relight.generator.sampling import GeneratorConfig, sample_scene  # noqa: E402

# Sample counts each Mitsuba sampler takes without rounding them.
EXACT_SPP = {
    "independent": (4, 8, 16, 32, 64, 128, 256),
    "stratified": (4, 16, 64, 256),
    "multijitter": (4, 8, 12, 16, 25, 36, 64, 100, 144, 256),
    "orthogonal": (4, 9, 25, 49, 121),
    "ldsampler": (4, 16, 64, 256),
}
CALIBRATION_SEED, CALIBRATION_SCENES, REFERENCE_SPP = 777, 8, 4096


def equal_error_table(res: int, target: float) -> None:
    """Relative RMSE and render time per sampler and spp on fixed scenes (one run)."""
    builder = SceneBuilder()
    cfg = GeneratorConfig(res=res)
    specs = [sample_scene(cfg, CALIBRATION_SEED, i) for i in range(CALIBRATION_SCENES)]
    refs = []
    for spec in specs:
        ref_spec = dataclasses.replace(spec, render=dataclasses.replace(
            spec.render, sampler="independent", spp=REFERENCE_SPP, seed=spec.render.seed + 99))
        refs.append(builder.render(ref_spec))
    rows = {}
    for sampler, counts in EXACT_SPP.items():
        for spp in counts:
            errs, times = [], []
            for spec, ref in zip(specs, refs):
                s = dataclasses.replace(spec, render=dataclasses.replace(spec.render, sampler=sampler, spp=spp))
                template = builder.template_for(s)
                template.render(spp, 1)  # warm: kernels compiled, caches hot
                t0 = time.perf_counter()
                image = template.render(spp, s.render.seed)
                times.append(time.perf_counter() - t0)
                errs.append(noise.relative_rmse(image, ref))
            rows[sampler, spp] = (float(np.mean(errs)), float(np.median(times)))
    print(f"# equal error: {CALIBRATION_SCENES} default scenes, {res}x{res}, depth {cfg.max_depth}, "
          f"reference {REFERENCE_SPP} spp independent; relative RMSE (mean), render s/image (median)")
    print("| sampler | " + " | ".join(f"{n} spp" for n in EXACT_SPP["independent"]) + " |")
    print("|---|" + "---|" * len(EXACT_SPP["independent"]))
    for sampler, counts in EXACT_SPP.items():
        cells = [f"{spp}: {rows[sampler, spp][0]:.4f}, {rows[sampler, spp][1]:.3f} s" for spp in counts]
        print(f"| {sampler} | " + " | ".join(cells) + " |")
    print(f"\n# to reach relative RMSE <= {target}:")
    print("| sampler | spp | relative RMSE | render s/image |")
    print("|---|---|---|---|")
    for sampler, counts in EXACT_SPP.items():
        hit = next((spp for spp in counts if rows[sampler, spp][0] <= target), None)
        if hit is None:
            print(f"| {sampler} | > {counts[-1]} | - | - |")
        else:
            print(f"| {sampler} | {hit} | {rows[sampler, hit][0]:.4f} | {rows[sampler, hit][1]:.3f} |")
    print("\n# relight.scene.noise.CALIBRATION (measured above)")
    for sampler in noise.CALIBRATION:
        pairs = ", ".join(f"({spp}, {rows[sampler, spp][0]:.4f})" for spp in EXACT_SPP[sampler])
        print(f'    "{sampler}": ({pairs}),')


def main() -> int:
    ap = at.OneLineParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=at.int_in(1, 100_000, "a count"), default=48, help="images per measurement")
    ap.add_argument("--res", type=at.resolution, default=128)
    ap.add_argument("--spp", type=at.spp, default=None, help="samples per pixel (default: from the target)")
    ap.add_argument("--target-rmse", type=at.relative_rmse, default=noise.DEFAULT_TARGET_RMSE)
    ap.add_argument("--workers", type=at.workers, default=2, help="also measure this many worker processes (1: skip)")
    ap.add_argument("--calibrate", action=argparse.BooleanOptionalAction, default=True,
                    help="print the equal-error sampler table first (default on)")
    ap.add_argument("--cycles", action=argparse.BooleanOptionalAction, default=True,
                    help="then run bench_cycles.py with its defaults where Blender is set up (default on)")
    args = ap.parse_args()
    backend.init()
    if args.calibrate:
        equal_error_table(args.res, args.target_rmse)
        print()
    cfg = GeneratorConfig(res=args.res, spp=args.spp, target_rmse=args.target_rmse)
    seed = 12345
    with tempfile.TemporaryDirectory() as tmp:
        # warm-up: every room structure (n_walls 4..8) once, other images than the measured ones
        generate(os.path.join(tmp, "warm"), 12, seed=seed + 1, cfg=cfg, progress=False)

        stats = generate(os.path.join(tmp, "fast"), args.n, seed=seed, cfg=cfg, progress=False)

        naive_dir = os.path.join(tmp, "naive")
        for sub in ("images", "exr", "scenes"):
            os.makedirs(os.path.join(naive_dir, sub))
        _write_card(naive_dir, seed, cfg, args.n, 0)
        t0 = time.perf_counter()
        naive_render_s = 0.0
        for i in range(args.n):
            spec = sample_scene(cfg, seed, i)
            template = build_naive(spec)
            t1 = time.perf_counter()
            image = template.render(spec.render.spp, spec.render.seed)
            naive_render_s += time.perf_counter() - t1
            spec.save(os.path.join(naive_dir, "scenes", f"{spec.id}.json"))
            write_exr(os.path.join(naive_dir, "exr", f"{spec.id}.exr"), image)
            write_png(os.path.join(naive_dir, "images", f"{spec.id}.png"), image)
        naive_s = time.perf_counter() - t0

        par = None
        if args.workers > 1:
            par = generate(os.path.join(tmp, "par"), args.n, seed=seed, cfg=cfg, progress=False,
                           workers=args.workers)

    print(f"# generation benchmark: {args.n} images, {args.res}x{args.res}, {cfg.sampler} "
          f"{cfg.render_spp} spp, path depth {cfg.max_depth}; {backend.describe()}")
    print("| way | images/s | s/image | render s/image | total / render |")
    print("|---|---|---|---|---|")
    print(f"| template (1 process) | {stats.images_per_s:.2f} | {stats.total_s / args.n:.3f} | "
          f"{stats.render_s / args.n:.3f} | {stats.overhead_ratio:.3f} |")
    print(f"| naive load_dict per image | {args.n / naive_s:.2f} | {naive_s / args.n:.3f} | "
          f"{naive_render_s / args.n:.3f} | {naive_s / naive_render_s:.3f} |")
    if par is not None:
        print(f"| template ({args.workers} processes) | {par.images_per_s:.2f} | {par.total_s / args.n:.3f} | "
              f"- | - |")
    print(f"\nnaive / template time ratio: {naive_s / stats.total_s:.2f}")
    print(f"targets: >= 12 images/s at the default noise target; total/render <= 1.10")
    try:
        import bench_cycles  # noqa: PLC0415 - optional: needs the Blender environment
    except ImportError:
        bench_cycles = None
    if not args.cycles:
        bench_cycles = None
    if bench_cycles is not None and hasattr(bench_cycles, "main"):
        print()
        bench_cycles.main([])
    return 0


if __name__ == "__main__":
    sys.exit(at.run_script(main))

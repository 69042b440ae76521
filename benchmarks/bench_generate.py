"""Generation benchmark: images/s, overhead over the render call, and the naive way.

Measured in one run on the same scenes (after a warm-up that loads every room
structure once, so both ways run with compiled kernels):

* template way: ``relight.dataset.generate`` (one loaded scene per structure, updated
  through ``mi.traverse``), images/s and total time / time inside ``mi.render``;
* naive way: ``mi.load_dict`` a new scene for every image (``build_naive``), same
  rendering and file writing;
* optionally the template way with 2 worker processes.

Usage: python benchmarks/bench_generate.py [--n 24] [--res 128] [--spp 64] [--workers 2]
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from relight import backend  # noqa: E402
from relight.dataset import _write_card, generate  # noqa: E402
from relight.render import write_exr, write_png  # noqa: E402
from relight.scene.build import build_naive  # noqa: E402
from relight.scene.sampling import GeneratorConfig, sample_scene  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=24, help="images per measurement")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--workers", type=int, default=2, help="also measure this many worker processes (1: skip)")
    args = ap.parse_args()
    backend.init()
    cfg = GeneratorConfig(res=args.res, spp=args.spp)
    seed = 12345
    with tempfile.TemporaryDirectory() as tmp:
        # warm-up: every room structure (n_walls 4..8) once, other images than the measured ones
        generate(os.path.join(tmp, "warm"), 12, seed=seed + 1, cfg=cfg, progress=False)

        stats = generate(os.path.join(tmp, "fast"), args.n, seed=seed, cfg=cfg, progress=False)

        naive_dir = os.path.join(tmp, "naive")
        for sub in ("images", "exr", "scenes"):
            os.makedirs(os.path.join(naive_dir, sub))
        _write_card(naive_dir, seed, cfg, args.n)
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

    print(f"# generation benchmark: {args.n} images, {args.res}x{args.res}, {args.spp} spp, "
          f"path depth {cfg.max_depth}; {backend.describe()}")
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
    print(f"targets: >= 3.5 images/s at 128x128/64 spp; total/render <= 1.15")
    return 0


if __name__ == "__main__":
    sys.exit(main())

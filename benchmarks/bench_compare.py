"""Benchmark of ``relight compare``: seconds per compared image at 128 px / 64 spp, and
the ratio to the generator's seconds per image, both measured in this run.

A compare does two renders per image (the re-render under the prediction and the
noise-floor render of the true light), so a ratio near 2 means little overhead.

    .venv/bin/python benchmarks/bench_compare.py [--count 6] [--res 128] [--spp 64]
"""
from __future__ import annotations

import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from relight.commands import argtypes as at  # noqa: E402


def main() -> None:
    ap = at.OneLineParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=at.int_in(1, 100_000, "a count"), default=6)
    ap.add_argument("--res", type=at.resolution, default=128)
    ap.add_argument("--spp", type=at.spp, default=64)
    ap.add_argument("--seed", type=at.seed, default=5)
    args = ap.parse_args()

    from relight import backend
    from relight.dataset import read_manifest
    from relight.generator.run import generate
    from relight.predictions import write_predictions
    from relight.scene.build import SceneBuilder
    from relight.generator.sampling import GeneratorConfig
    from relight.verify.compare import compare_predictions, moved_light_predictions
    from relight.verify.report import write_report

    backend.init()
    with tempfile.TemporaryDirectory() as tmp:
        ds = os.path.join(tmp, "ds")
        cfg = GeneratorConfig(res=args.res, spp=args.spp)
        generate(os.path.join(tmp, "warm"), count=1, seed=args.seed + 1, cfg=cfg, progress=False)  # kernels
        stats = generate(ds, count=args.count, seed=args.seed, cfg=cfg, progress=False)
        gen_s = stats.total_s / args.count
        pred = os.path.join(tmp, "p.json")
        write_predictions(pred, moved_light_predictions(ds, 20.0, 0.1, seed=0), dataset=ds)
        builder = SceneBuilder()
        compare_predictions(pred, limit=1, progress=False, builder=builder)   # warm the builder
        t0 = time.perf_counter()
        comparison = compare_predictions(pred, progress=False, builder=builder)
        cmp_s = (time.perf_counter() - t0) / args.count
        render_s = comparison.render_seconds / args.count
        t0 = time.perf_counter()
        write_report(comparison, os.path.join(tmp, "report"), {"command": "bench"})
        rep_s = (time.perf_counter() - t0) / args.count
        assert len(read_manifest(ds)) == args.count

    print(f"compare benchmark: {args.count} images, {args.res} px, {args.spp} spp, "
          f"{os.cpu_count()} cores, {backend.describe()}")
    rows = [("generate (per image)", gen_s, 1.0),
            ("compare: re-render + noise floor + metrics", cmp_s, cmp_s / gen_s),
            ("  of which the two Mitsuba renders", render_s, render_s / gen_s),
            ("report: panels, figure3, files", rep_s, rep_s / gen_s),
            ("compare + report", cmp_s + rep_s, (cmp_s + rep_s) / gen_s)]
    print(f"{'stage':44s} {'s/image':>9s} {'x generate':>11s}")
    for name, s, ratio in rows:
        print(f"{name:44s} {s:9.3f} {ratio:11.2f}")


if __name__ == "__main__":
    sys.exit(at.run_script(main))

"""Engine benchmark: one process versus Dask ``local:1`` and ``local:2``, in one run.

Generates the same images (default 128 px, default noise target) into fresh folders:

* ``single tN``: today's path (``relight generate``), one process, N Dr.Jit threads
  (1 and all cores);
* ``local:1``: one Dask worker process with all cores; ``local:2``: two worker
  processes, one thread each.

Images/s counts everything a user waits for (a Dask run includes starting the
cluster and each worker's Mitsuba set-up); it is also given without the cluster
start-up, and for workers that have already rendered other images of these
settings (``warm``: Mitsuba started, scene templates loaded, kernels compiled),
which is what a long run sees after its first minute; the targets are checked on
the warm rows.
The outputs are compared byte for byte.

Engine overhead per task (scheduling, serialisation, result transfer) is measured on
one worker (``local:1``, warm): tasks run back to back, so the time between two task
completions seen by the client minus the task's own wall time (render + write, timed
in the worker) is what the engine adds. It is printed in ms and as a share of the
task's render time.

Usage: python benchmarks/bench_engine.py [--n 32] [--res 128] [--spp N]
"""
from __future__ import annotations

import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from relight.commands import argtypes as at  # noqa: E402

from relight.generator.run import generate  # noqa: E402
from relight.generator.sampling import GeneratorConfig  # noqa: E402

SEED = 3


def same_outputs(a: str, b: str) -> bool:
    """Images, EXRs and scene files byte-identical, manifests equal up to record order."""
    for sub in ("images", "exr", "scenes"):
        names = sorted(os.listdir(os.path.join(a, sub)))
        if names != sorted(os.listdir(os.path.join(b, sub))):
            return False
        for name in names:
            with open(os.path.join(a, sub, name), "rb") as fa, open(os.path.join(b, sub, name), "rb") as fb:
                if fa.read() != fb.read():
                    return False
    with open(os.path.join(a, "manifest.jsonl")) as fa, open(os.path.join(b, "manifest.jsonl")) as fb:
        return sorted(fa) == sorted(fb)


def overhead_ms(cfg: GeneratorConfig, out: str, n_tasks: int) -> tuple[float, float]:
    """(engine ms per task, mean render ms per task) on a warm local:1, one image a task."""
    from relight import engine
    from relight.generator.run import _render_shard
    context = (out, cfg, SEED)
    with engine.client(engine.Scheduler(local=1)) as (c, threads):
        engine.run_shards(c, _render_shard, context, [[0]], lambda part, r: None, threads)   # warm-up
        stamps, task_s, render_s = [], [], []

        def on_result(part, r):
            stamps.append(time.perf_counter())
            task_s.append(r.task_s)
            render_s.append(sum(seconds for _, seconds in r.value))
        engine.run_shards(c, _render_shard, context, [[i] for i in range(1, n_tasks + 1)], on_result,
                          threads)   # one image a task
    gaps = [stamps[k] - stamps[k - 1] - task_s[k] for k in range(1, len(stamps))]
    return 1e3 * sum(gaps) / len(gaps), 1e3 * sum(render_s[1:]) / len(gaps)


def warm_run(cfg: GeneratorConfig, tmp: str, n: int, n_proc: int, threads: int, k: int):
    """A table row for ``n`` images on a LocalCluster of ``n_proc`` workers that have
    already rendered (other) images of these settings: the steady state of a long run."""
    import logging

    import distributed
    with distributed.LocalCluster(n_workers=n_proc, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=logging.CRITICAL) as cluster:
        generate(os.path.join(tmp, f"warm{k}"), 8 * n_proc, seed=SEED + 1, cfg=cfg, progress=False,
                 threads=threads, scheduler=cluster.scheduler_address)
        out = os.path.join(tmp, f"warmrun{k}")
        stats = generate(out, n, seed=SEED, cfg=cfg, progress=False, threads=threads,
                         scheduler=cluster.scheduler_address)
    ips = stats.written / (stats.total_s - stats.startup_s)
    return (f"local:{n_proc} warm ({threads} thr each)", ips, out, ips, stats.startup_s)


def main() -> int:
    p = at.OneLineParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=at.int_in(1, 100_000, "a count"), default=32, help="images per run (default 32)")
    p.add_argument("--res", type=at.resolution, default=128, help="image size (default 128)")
    p.add_argument("--spp", type=at.spp, default=None, help="samples per pixel (default: noise target)")
    p.add_argument("--tasks", type=at.int_in(1, 100_000, "a count"), default=12, help="tasks for the overhead figure (default 12)")
    args = p.parse_args()
    cfg = GeneratorConfig(res=args.res, **({"spp": args.spp} if args.spp else {}))
    cores = os.cpu_count() or 1
    rows = []
    with tempfile.TemporaryDirectory(prefix="relight-bench-engine-") as tmp:
        generate(os.path.join(tmp, "warm"), 8, seed=SEED + 1, cfg=cfg, progress=False)   # kernel cache
        runs = [(f"single t1", dict(threads=1)), (f"single t{cores}", dict(threads=cores)),
                ("local:1", dict(scheduler="local:1", threads=cores)),
                ("local:2 (1 thread each)", dict(scheduler="local:2", threads=1))]
        for name, kw in runs:
            out = os.path.join(tmp, name.split()[0].replace(":", "") + str(len(rows)))
            stats = generate(out, args.n, seed=SEED, cfg=cfg, progress=False, **kw)
            rows.append((name, stats.images_per_s, out,
                         stats.written / (stats.total_s - stats.startup_s), stats.startup_s))
        for n_proc, threads in ((1, cores), (2, 1)):   # warm workers: what a long run sees
            rows.append(warm_run(cfg, tmp, args.n, n_proc, threads, len(rows)))
        over, render = overhead_ms(cfg, os.path.join(tmp, "overhead"), args.tasks)
        best_single = max(r[1] for r in rows[:2])
        ref = rows[1][2]
        print(f"\n{args.n} images at {args.res} px, spp {cfg.render_spp}, {cores} cores (one run)\n")
        best_run = max(r[3] for r in rows[:2])
        print(f"{'run':26s} {'images/s':>9s} {'vs best single':>15s} {'start-up s':>11s} "
              f"{'img/s w/o start':>16s} {'vs best':>8s} {'identical':>10s}")
        for name, ips, out, run_ips, startup in rows:
            ident = "ref" if out == ref else ("yes" if same_outputs(ref, out) else "NO")
            print(f"{name:26s} {ips:9.3f} {ips / best_single:15.3f} {startup:11.2f} "
                  f"{run_ips:16.3f} {run_ips / best_run:8.3f} {ident:>10s}")
        print(f"\nengine overhead per task (local:1, warm, 1 image a task): {over:.1f} ms "
              f"= {100 * over / render:.2f}% of the render time ({render:.0f} ms)")
        ok1 = rows[4][3] >= 0.9 * rows[1][3]
        ok2 = rows[5][3] >= best_run
        print(f"targets (warm workers): local:1 within 10% of single t{cores}: {'met' if ok1 else 'NOT met'}; "
              f"local:2 >= best single: {'met' if ok2 else 'NOT met'}; "
              f"overhead < 5%: {'met' if over < 0.05 * render else 'NOT met'}")
    return 0


if __name__ == "__main__":
    sys.exit(at.run_script(main))

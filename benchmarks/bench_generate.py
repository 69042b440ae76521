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

Stage profile (``--profile``, instead of the above): where an image's time goes, from
:class:`relight.timing.StageTimer` and Dr.Jit's kernel history, in one run:

* one after the other (``generate(..., overlap=False)``): every stage of every image in
  one thread (scene sampling, meshes, textures, template parameters, template update
  with the acceleration structure, tracing + launch, the kernel's run, readback, the
  scene JSON, EXR, PNG and manifest writes); the stages add up to the wall time, the
  residual is printed;
* the default pipeline (prepare and write threads around the render): what the render
  thread waits for, beside the helper threads' busy time;
* the same two runs without a timer (the timer's cost, the pipeline's gain);
* the start-up of ``relight generate`` in a fresh process, split the same way
  (interpreter, imports, Mitsuba/Dr.Jit set-up, first template and first kernels,
  the steady images, exit), with the kernel cache warm and with an empty one.

Usage: python benchmarks/bench_generate.py [--n 48] [--res 128] [--spp N | --target-rmse E]
                                           [--workers 2] [--calibrate | --no-calibrate]
                                           [--profile]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from relight.commands import argtypes as at  # noqa: E402
from relight.engine import worker_count  # noqa: E402

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


# ---- stage profile (--profile) ------------------------------------------------------------

# The start-up of `relight generate` in a fresh process, timed from inside (wall clock,
# so the parent can place the interpreter's start and exit around it). It runs what
# the command runs: the CLI's imports and parser, the backend, then generate().
STARTUP_CHILD = r"""
import json, sys, time
t0 = time.time()
import relight.cli
args = relight.cli.build_parser().parse_args(sys.argv[1:])
from relight.generator.run import generate
from relight.generator.sampling import GeneratorConfig
cfg = GeneratorConfig.from_file(args.config, preset=args.preset, res=args.res, spp=args.spp)
t1 = time.time()
from relight import backend
backend.init()
t2 = time.time()
from relight.timing import StageTimer
timer = StageTimer(drjit=backend.drjit(), kernels=True)
stats = generate(args.out, args.count, seed=args.seed, cfg=cfg, progress=False, timer=timer)
timer.close()
t3 = time.time()
first = min(timer.images())
print(json.dumps({"t0": t0, "imports": t1 - t0, "backend": t2 - t1, "generate": t3 - t2, "end": time.time(),
                  "first": first, "seconds": [[*k, v] for k, v in timer.seconds.items()],
                  "first_kernels": [vars(k) for (i, n), k in timer.kernel.items() if i == first]}))
"""

# The first image's stages that load the template and trace, compile (or load) and run
# its kernels for the first time in a process.
FIRST_COMPILE = ("template: load (new structure)", "render: tracing + launch", "render: kernel")


# Table order of the stages (the order an image goes through them); others follow.
STAGE_ORDER = ("hand-off to helper threads", "scene sampling", "meshes", "textures", "wait: prepare",
               "template: load (new structure)", "template: parameters",
               "template: update + acceleration structure", "render: tracing + launch", "render: kernel",
               "render: readback", "write: scene JSON", "write: EXR", "write: PNG", "write: manifest append",
               "wait: writes", "profiler: kernel history")


def _ordered(stages: list[str]) -> list[str]:
    return sorted(stages, key=lambda s: STAGE_ORDER.index(s) if s in STAGE_ORDER else len(STAGE_ORDER))


def _uptime() -> str:
    try:
        return open("/proc/loadavg").read().split()[:3].__str__()
    except OSError:
        return "n/a"


def _stage_table(timer, wall_s: float, n: int, threads: list[str], title: str) -> float:
    """Print the mean per image of every stage of ``threads`` (others: in brackets, as
    overlapped time) and return the residual wall - sum (seconds, whole run)."""
    ms = 1000.0 / n
    print(f"\n## {title}")
    print("| stage | ms/image | share of wall | min-max over images (ms) | Dr.Jit kernels: exec / IR codegen / compile ms per image |")
    print("|---|---|---|---|---|")
    counted = 0.0
    images = timer.images()
    for stage in _ordered(timer.stages()):
        own = timer.total(stage, image=...) if threads is None else sum(timer.total(stage, t) for t in threads)
        other = timer.total(stage) - own
        per = [sum(timer.total(stage, t, image=i) for t in (threads or timer.threads())) for i in images]
        k = timer.kernels_total(stage)
        kern = (f"{k.jit_exec_ms / n:.2f} / {k.codegen_ms / n:.2f} / {k.compile_ms / n:.2f}"
                if k.jit_kernels else "")
        cell = f"{own * ms:.2f}" + (f" (+{other * ms:.2f} on helper threads)" if other > 0 else "")
        print(f"| {stage} | {cell} | {own / wall_s:.1%} | {min(per) * 1000:.2f}-{max(per) * 1000:.2f} | {kern} |")
        counted += own
    residual = wall_s - counted
    print(f"| **sum of stages** | {counted * ms:.2f} | {counted / wall_s:.1%} | | |")
    print(f"| **wall (generate)** | {wall_s * ms:.2f} | 100% | | |")
    print(f"| residual (wall - sum) | {residual * ms:.2f} | {residual / wall_s:+.2%} | | |")
    return residual


def profile(args, cfg: GeneratorConfig) -> int:
    """``--profile``: the stage tables and the start-up split (see the module docstring)."""
    from relight.timing import StageTimer
    dr = backend.drjit()
    n, seed = args.n, 12345
    print(f"# stage profile: {n} images, {args.res}x{args.res}, {cfg.sampler} {cfg.render_spp} spp, "
          f"path depth {cfg.max_depth}; load average at start {_uptime()}; {backend.describe()}")
    with tempfile.TemporaryDirectory(dir=args.tmp) as tmp:
        generate(os.path.join(tmp, "warm"), 4, seed=seed + 1, cfg=cfg, progress=False)   # kernels in memory
        runs, walls = {}, {}
        for rep in range(args.repeats):   # alternate the ways, so a load change hits them all
            for name, overlap, timed in (("serial", False, True), ("pipeline", True, True),
                                         ("serial_untimed", False, False), ("pipeline_untimed", True, False)):
                timer = StageTimer(drjit=dr, kernels=True) if timed else None
                stats = generate(os.path.join(tmp, f"{name}{rep}"), n, seed=seed, cfg=cfg, progress=False,
                                 timer=timer, overlap=overlap)
                if timer is not None:
                    timer.close()
                walls.setdefault(name, []).append(stats.total_s)
                if name not in runs or stats.total_s < runs[name][0].total_s:
                    runs[name] = (stats, timer)   # the fastest repeat: the least disturbed by the load
    stats, timer = runs["serial"]
    residual = _stage_table(timer, stats.total_s, n, None,
                            "one after the other (overlap off): every stage, in one thread")
    print(f"\nresidual {residual / stats.total_s:+.2%} of the wall time (target: within 5%)")
    kernel_ms = timer.kernels_total("render: kernel").largest_ms
    render_kernel_s = sum(timer.kernel[(i, "render: kernel")].jit_exec_ms for i in timer.images()) / 1000.0
    render_call_s = sum(timer.total(s) for s in ("render: tracing + launch", "render: kernel", "render: readback"))
    print(f"total / render call (tracing + kernel + readback): {stats.total_s / render_call_s:.3f}; "
          f"total / kernel execution (Dr.Jit history): {stats.total_s / render_kernel_s:.3f} "
          f"(longest kernel {kernel_ms:.1f} ms; target total / kernel <= 1.15)")
    stats_p, timer_p = runs["pipeline"]
    residual_p = _stage_table(timer_p, stats_p.total_s, n, ["MainThread"],
                              "pipeline (the default): the render thread; helper threads' busy time in brackets")
    print(f"\nresidual {residual_p / stats_p.total_s:+.2%} of the wall time; "
          f"total / kernel execution: {stats_p.total_s / (timer_p.kernels_total('render: kernel').jit_exec_ms / 1000):.3f}")
    su, pu = runs["serial_untimed"][0].total_s, runs["pipeline_untimed"][0].total_s
    print(f"\n{args.repeats} repeats of each way, alternated; the tables show the fastest repeat; walls (s): "
          + "; ".join(f"{k} " + ", ".join(f"{w:.2f}" for w in v) for k, v in walls.items()))
    print("\n| same run, ratios (fastest repeats) | value |\n|---|---|")
    print(f"| timer cost: timed / untimed wall, one after the other | {stats.total_s / su:.3f} |")
    print(f"| timer cost: timed / untimed wall, pipeline | {stats_p.total_s / pu:.3f} |")
    print(f"| pipeline gain: serial / pipeline wall (untimed) | {su / pu:.3f} |")
    print(f"| untimed pipeline: images/s | {n / pu:.2f} |")
    _startup_table(args, n)
    return 0


def _startup(args, n: int, cache_dir: str | None) -> dict:
    """Run ``relight generate`` (as STARTUP_CHILD) in a fresh process; its timings."""
    env = dict(os.environ)
    if cache_dir is not None:
        env["DRJIT_CACHE_DIR"] = cache_dir
    with tempfile.TemporaryDirectory(dir=args.tmp) as tmp:
        cmd = [sys.executable, "-c", STARTUP_CHILD, "generate", "--out", os.path.join(tmp, "d"),
               "--count", str(n), "--res", str(args.res), "--seed", "4242"]
        if args.spp:
            cmd += ["--spp", str(args.spp)]
        t_before = time.time()
        r = subprocess.run(cmd, capture_output=True, text=True, env=env)
        t_after = time.time()
    if r.returncode != 0:
        raise RuntimeError(f"start-up run failed: {r.stderr.strip().splitlines()[-1:]}")
    out = json.loads(r.stdout.strip().splitlines()[-1])
    out["interpreter"] = out["t0"] - t_before
    out["exit"] = t_after - out["end"]
    out["wall"] = t_after - t_before
    return out


def _startup_table(args, n: int) -> None:
    runs = {"warm kernel cache": _startup(args, n, None)}
    with tempfile.TemporaryDirectory(dir=args.tmp) as cold:
        runs["empty kernel cache"] = _startup(args, n, cold)
    rows, notes = {}, {}
    for name, r in runs.items():
        main_stage = {}   # (image is first, stage) -> seconds on the render (main) thread
        helper_first = {}
        for image, stage, thread, sec in r["seconds"]:
            if thread == "MainThread":
                key = ("first" if image == r["first"] else "outside" if image is None else "rest", stage)
                main_stage[key] = main_stage.get(key, 0.0) + sec
            elif image == r["first"]:
                helper_first[stage] = helper_first.get(stage, 0.0) + sec
        first = {st: v for (w, st), v in main_stage.items() if w == "first"}
        rest = sum(v for (w, _), v in main_stage.items() if w == "rest")
        compile_s = sum(first.get(st, 0.0) for st in FIRST_COMPILE)
        wait_prep = first.get("wait: prepare", 0.0)
        rows[name] = {
            "interpreter start": r["interpreter"],
            "imports (CLI, command modules, generator)": r["imports"],
            "Mitsuba/Dr.Jit set-up (backend.init)": r["backend"],
            "first image: its scene (sampling, meshes, textures; nothing to overlap yet)": wait_prep,
            "first image: template load, first tracing and kernel (compile or cache load)": compile_s,
            "first image: its other stages": sum(first.values()) - compile_s - wait_prep,
            f"the other {n - 1} images (render thread)": rest,
            "generate: folder, lock, card, mesh check, last writes, residual": r["generate"] - sum(first.values())
            - rest,
            "exit (interpreter and Dr.Jit shut-down)": r["exit"],
        }
        rest_per = rest / max(n - 1, 1)
        ks = r["first_kernels"]
        fixed = r["wall"] - n * rest_per
        notes[name] = (f"{name}: wall {r['wall']:.3f} s; first scene on the helper thread: "
                       + ", ".join(f"{st} {v * 1000:.0f} ms" for st, v in helper_first.items()
                                   if st in ("scene sampling", "meshes", "textures"))
                       + f"; first image's kernels: {sum(k['cache_misses'] for k in ks)} compiled, compile "
                       f"{sum(k['compile_ms'] for k in ks):.0f} ms, IR codegen {sum(k['codegen_ms'] for k in ks):.0f} ms; "
                       f"fixed cost (wall - {n} x {rest_per * 1000:.1f} ms a later image) {fixed:.2f} s "
                       f"= {fixed / rest_per:.1f} later images" if rest_per > 0 else "")
    names = list(runs)
    print(f"\n## start-up: `relight generate --count {n} --res {args.res}` in a fresh process (seconds)")
    print("| part | " + " | ".join(names) + " |")
    print("|---|" + "---|" * len(names))
    for part in rows[names[0]]:
        print(f"| {part} | " + " | ".join(f"{rows[k][part]:.3f}" for k in names) + " |")
    print("| **sum** | " + " | ".join(f"{sum(rows[k].values()):.3f}" for k in names) + " |")
    print("| **wall (measured by the parent)** | " + " | ".join(f"{runs[k]['wall']:.3f}" for k in names) + " |")
    for k in names:
        print(f"\n{notes[k]}")


def main() -> int:
    ap = at.OneLineParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=at.int_in(1, 100_000, "a count"), default=48, help="images per measurement")
    ap.add_argument("--res", type=at.resolution, default=128)
    ap.add_argument("--spp", type=at.spp, default=None, help="samples per pixel (default: from the target)")
    ap.add_argument("--target-rmse", type=at.relative_rmse, default=noise.DEFAULT_TARGET_RMSE)
    ap.add_argument("--workers", type=worker_count, default=2, help="also measure this many worker processes (1: skip)")
    ap.add_argument("--calibrate", action=argparse.BooleanOptionalAction, default=True,
                    help="print the equal-error sampler table first (default on)")
    ap.add_argument("--cycles", action=argparse.BooleanOptionalAction, default=True,
                    help="then run bench_cycles.py with its defaults where Blender is set up (default on)")
    ap.add_argument("--profile", action="store_true",
                    help="instead: the stage profile of --n images (every stage from timers and Dr.Jit's "
                         "kernel history, summing to the wall time) and the CLI start-up split the same way")
    ap.add_argument("--repeats", type=at.int_in(1, 100, "a repeat count"), default=2,
                    help="with --profile: runs of each way, alternated (the fastest is shown)")
    ap.add_argument("--tmp", default=None, help="folder for the temporary datasets (default: the system's)")
    args = ap.parse_args()
    backend.init()
    if args.profile:
        return profile(args, GeneratorConfig(res=args.res, spp=args.spp, target_rmse=args.target_rmse))
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

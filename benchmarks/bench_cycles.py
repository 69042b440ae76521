"""relight (Mitsuba) and Blender Cycles, the paper's renderer, on the same scene files.

One run on fixed default scenes (``sample_scene(GeneratorConfig(res), 4242, i)``):

(a) physics cross-check: converged Mitsuba against converged Cycles (``--ref-spp``
    each): mean brightness ratio and relative RMSE per scene, three ways:
    * as the scene files say;
    * every object's roughness set to 0, so all surfaces are Lambert in both renderers:
      what remains tests light units, geometry, textures, camera and path depth;
    * Mitsuba's Oren-Nayar given the multiple-scattering term Cycles >= 4.3 adds
      (transcribed from Cycles' ``bsdf_oren_nayar.h``; :func:`register_cycles_oren_nayar`):
      what remains with the one known model difference removed.
    The noise floor is what the two references' own noise alone gives.
(b) equal error: relative RMSE of each renderer against its own converged reference at
    each sample count (other seeds), render seconds per image, the sample count each
    needs for a target error (log-log interpolation) and the time ratio there. Mitsuba
    time is ``mi.render`` on a loaded template (as in generation); Cycles time is its
    render call (scene sync, BVH build, sampling, EXR write; the Python scene build
    is not counted). Both use all cores.
(c) ``--end-to-end``: the user's whole pipeline per scene file at equal error (the first
    target's sample counts from (b), rounded up), each a fresh process, start-up included:
    ``relight render SCENE --spp S --out x.exr --out x.png`` against ``relight
    export-blender SCENE --spp S --out x.blend --render x.exr`` (Cycles writes no PNG
    there: counted in its favour). The two commands alternate scene by scene so both see
    the same machine load; wall seconds per scene file and their ratio.
(d) ``--end-to-end --batch N``: the same at every target, but N default scene files per
    process on both sides, so start-up is paid once: one process of relight's environment
    renders all N with the library (``load_scene``, ``render_spec``, ``write_exr``,
    ``write_png``: what ``relight render`` does per file) and one process of the Blender
    environment renders the same N files with Cycles (``load_scene``,
    :func:`relight.scene.blender.render_cycles` writing the EXR: ``relight export-blender
    --render`` without the .blend; no PNG, counted in its favour). Per side: the process's
    wall (parent's clock), the wall per image after the first (the child's clock at each
    image written: (last - first) / (N - 1)) and start-up = wall - N x per image (imports,
    set-up, the first image's extra, exit). The two processes alternate over ``--repeats``
    (2) and each side's fastest repeat is shown (all walls are printed).

Relative RMSE is the generator's: ``sqrt(mean((x - ref)^2)) / mean(ref)``. References
are cached under ``--cache`` keyed by scene, renderer, code and spp. Skips (one line,
exit 0) when the Blender environment (``scripts/setup_blender.sh``) is absent.

Usage: python benchmarks/bench_cycles.py [--n 4] [--res 128] [--ref-spp 2048]
                                         [--targets 0.03,0.015,0.0075] [--cache DIR]
                                         [--end-to-end [--batch N] [--repeats 2]]
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import subprocess
import sys
import tempfile
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

from relight.commands import argtypes as at  # noqa: E402

import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

from relight.scene import blender  # noqa: E402

SCENE_SEED = 4242
LADDER_SPP = (4, 16, 64, 256)   # exact for every Mitsuba sampler but "orthogonal"
NOISY_SEED_OFFSET = 1000              # noisy renders use other seeds than the references
DEFAULT_CACHE = os.path.join("~", "relight-data", "bench-cycles")
EON_PLUGIN = "roughdiffuse_cycles"
PROFILE_TOTAL_OVER_KERNEL = 1.74   # relight's wall / kernel per image (docs/generation-profile.md)


# --------------------------------------------------------------------------- Cycles' Oren-Nayar in Mitsuba
def register_cycles_oren_nayar(mi, dr) -> None:
    """Register :data:`EON_PLUGIN`: relight's ``roughdiffuse`` plus the energy-compensating
    multiple-scattering term of Cycles >= 4.3 (``bsdf_oren_nayar.h``), as Cycles applies it::

        f cos_o = rho [A + B s/t + E_ms (1 - E(cos_i)) (1 - E(cos_o))] cos_o,
        E(mu) = pi A + B G(mu),  E_avg = pi A + (2 pi - 5.6) / 3 B,
        E_ms = rho^2 E_avg / (pi (1 - E_avg) (1 - rho (1 - E_avg))),
        G(mu) = sin(th) (th - 2/3 - sin(th) mu) + 2/3 tan(th) (1 - sin(th)^3),  mu = cos(th);

    Cycles multiplies the whole bracket by the colour (closure weight), and uses plain
    Lambert below roughness 1e-5. Only for this benchmark's cross-check.
    """
    if EON_PLUGIN in getattr(register_cycles_oren_nayar, "_done", ()):
        return

    def g_term(mu):
        sin_t = dr.safe_sqrt(1.0 - mu * mu)
        theta = dr.safe_acos(mu)
        g = sin_t * (theta - 2.0 / 3.0 - sin_t * mu) + 2.0 / 3.0 * (sin_t / dr.maximum(mu, 1e-6)) * (1.0 - sin_t ** 3)
        return dr.select(mu < 1e-6, (0.5 * math.pi - 2.0 / 3.0) - mu, g)

    from relight.scene import bsdf as rough_bsdf
    rough_bsdf.register()

    class CyclesOrenNayar(rough_bsdf.RoughDiffuse):
        """relight's ``roughdiffuse`` (sampling, pdf, parameters) with Cycles' BRDF."""

        def _f(self, si, wo, active):
            wi = si.wi
            cos_i, cos_o = mi.Frame3f.cos_theta(wi), mi.Frame3f.cos_theta(wo)
            sigma = dr.clip(self.roughness, 0.0, 1.0)
            a = 1.0 / (math.pi + (0.5 * math.pi - 2.0 / 3.0) * sigma)
            b = sigma * a
            s = dr.dot(wi, wo) - cos_i * cos_o
            t = dr.select(s > 0.0, dr.maximum(cos_i, cos_o), 1.0)
            rho = dr.clip(self.reflectance.eval(si, active), 0.0, 1.0)
            e_avg = a * math.pi + ((2.0 * math.pi - 5.6) / 3.0) * b
            e_ms = rho * rho * (e_avg / dr.maximum(1.0 - e_avg, 1e-12)) / (math.pi * (1.0 - rho * (1.0 - e_avg)))
            multi = e_ms * (1.0 - (a * math.pi + b * g_term(cos_i))) * (1.0 - (a * math.pi + b * g_term(cos_o)))
            multi = dr.select(sigma < 1e-5, 0.0, multi)
            return rho * (a + b * s / t + multi) * cos_o

    mi.register_bsdf(EON_PLUGIN, lambda props: CyclesOrenNayar(props))
    register_cycles_oren_nayar._done = (EON_PLUGIN,)


# --------------------------------------------------------------------------- helpers
def _with_render(spec, **changes):
    return dataclasses.replace(spec, render=dataclasses.replace(spec.render, **changes))


def _lambert(spec):
    return dataclasses.replace(spec, objects=tuple(dataclasses.replace(o, roughness=0.0) for o in spec.objects))


def _code_hash(*modules) -> str:
    h = hashlib.sha1()
    for m in modules:
        with open(m.__file__, "rb") as f:
            h.update(f.read())
    return h.hexdigest()[:10]


class MitsubaSide:
    """Renders specs with relight's templates; ``eon=True`` uses Cycles' Oren-Nayar."""

    def __init__(self, eon: bool = False):
        from relight import backend
        from relight.scene import bsdf, build
        self.mi = backend.init()
        self.bsdf, self.eon = bsdf, eon
        if eon:
            register_cycles_oren_nayar(self.mi, backend.drjit())
        self.builder = build.SceneBuilder()
        self.tag = f"mitsuba{self.mi.__version__}-{'eon' if eon else 'std'}-{_code_hash(bsdf, build)}"

    def template(self, spec):
        saved = self.bsdf.PLUGIN
        if self.eon:
            self.bsdf.register()               # the standard plugin, then point the builder at ours
            self.bsdf.PLUGIN = EON_PLUGIN
        try:
            return self.builder.template_for(spec)
        finally:
            self.bsdf.PLUGIN = saved

    def render(self, spec, spp: int, seed: int) -> tuple[np.ndarray, float]:
        import time
        template = self.template(_with_render(spec, spp=spp, seed=seed))
        t0 = time.perf_counter()
        image = template.render(spp, seed)
        return image, time.perf_counter() - t0


class CyclesSide:
    def __init__(self):
        self.worker = blender.CyclesWorker()
        self.tag = f"cycles-{blender.SAMPLING_PATTERN}-{_code_hash(blender)}"

    def render(self, spec, spp: int, seed: int) -> tuple[np.ndarray, float]:
        return self.worker.render(spec, spp, seed)


def reference(side, spec, spp: int, cache: str) -> np.ndarray:
    """Converged render of ``spec`` (its own seed), cached by content."""
    key = hashlib.sha1(f"{side.tag}|{spp}|{spec.to_json()}".encode()).hexdigest()[:16]
    path = os.path.join(cache, f"{side.tag.split('-')[0]}-{key}.npy")
    if os.path.isfile(path):
        return np.load(path)
    image, _ = side.render(spec, spp, spec.render.seed)
    tmp = f"{path}.tmp{os.getpid()}.npy"
    np.save(tmp, image)
    os.replace(tmp, path)
    return image


def spp_for(errors: dict[int, float], target: float) -> float | None:
    """Sample count where the mean error crosses ``target`` (log-log between ladder
    points; None above the ladder; below the first point extrapolated with slope -1/2)."""
    spps = sorted(errors)
    if errors[spps[0]] <= target:
        return spps[0] * (errors[spps[0]] / target) ** 2
    for lo, hi in zip(spps, spps[1:]):
        if errors[hi] <= target:
            slope = math.log(errors[hi] / errors[lo]) / math.log(hi / lo)
            return lo * (target / errors[lo]) ** (1.0 / slope)
    return None


def time_at(times: dict[int, float], spp: float) -> float:
    """Seconds per image at ``spp``: least-squares line t = t0 + k spp over the ladder."""
    x = np.array(sorted(times), float)
    y = np.array([times[int(s)] for s in x])
    k, t0 = np.polyfit(x, y, 1)
    return float(t0 + k * spp)


def end_to_end(specs, errors: dict, target: float) -> None:
    """(c): the user's command per scene file, both renderers at ``target`` (module docstring)."""
    counts = equal_error_spp(specs, errors, target)
    print(f"\n## (c) end to end at relative RMSE {target}: one fresh process per scene file, "
          "start-up, scene file in, images out")
    if counts is None:
        print("a renderer does not reach the target on the ladder: no end-to-end figure")
        return
    sm, sc = counts
    walls = {"m": [], "c": []}
    with tempfile.TemporaryDirectory(prefix="relight-e2e-") as tmp:
        for i, spec in enumerate(specs):
            scene = os.path.join(tmp, f"{i}.json")
            spec.save(scene)
            commands = {
                "m": ["render", scene, "--spp", str(sm), "--out", os.path.join(tmp, f"{i}.exr"),
                      "--out", os.path.join(tmp, f"{i}.png")],
                "c": ["export-blender", scene, "--spp", str(sc), "--out", os.path.join(tmp, f"{i}.blend"),
                      "--render", os.path.join(tmp, f"{i}-cycles.exr")]}
            for key, argv in commands.items():
                t0 = time.perf_counter()
                done = subprocess.run([sys.executable, "-m", "relight", *argv], capture_output=True, text=True)
                walls[key].append(time.perf_counter() - t0)
                if done.returncode != 0:
                    raise RuntimeError(f"relight {argv[0]} failed: {(done.stderr or '').strip()[-300:]}")
    m, c = float(np.median(walls["m"])), float(np.median(walls["c"]))
    print(f"| renderer | command | spp | wall s per scene file (median of {len(specs)}; all) |")
    print("|---|---|---|---|")
    print(f"| Mitsuba | relight render (EXR + PNG) | {sm} | {m:.2f} ({', '.join(f'{w:.2f}' for w in walls['m'])}) |")
    print(f"| Cycles | relight export-blender --render (.blend + EXR) | {sc} | {c:.2f} "
          f"({', '.join(f'{w:.2f}' for w in walls['c'])}) |")
    print(f"Cycles / relight, end to end: {c / m:.2f}")


# A batch of scene files in one process, either renderer: run as ``PYTHON SCRIPT JOB.json``
# with this checkout on PYTHONPATH (relight's environment for "mitsuba", the Blender one
# for "cycles"); writes the child's clock after its imports and after each image to
# job["marks"] (not stdout: Blender writes its log there).
BATCH_SCRIPT = """
import json, sys, time
t0 = time.perf_counter()
job = json.load(open(sys.argv[1]))
import dataclasses
from relight.scene.spec import load_scene
if job["renderer"] == "mitsuba":
    from relight.imageio import write_exr, write_png
    from relight.scene.build import render_spec

    def render(spec, item):
        image = render_spec(spec)
        write_exr(item["exr"], image)
        write_png(item["png"], image)
else:
    from relight.scene.blender import render_cycles

    def render(spec, item):
        render_cycles(spec, exr_path=item["exr"])
marks = [time.perf_counter() - t0]
for item in job["scenes"]:
    spec = load_scene(item["scene"])
    spec = dataclasses.replace(spec, render=dataclasses.replace(spec.render, spp=job["spp"]))
    render(spec, item)
    marks.append(time.perf_counter() - t0)
with open(job["marks"], "w") as f:
    json.dump(marks, f)
"""


@dataclasses.dataclass
class BatchRun:
    """One batch process: wall seconds (parent's clock) and the child's marks (after
    imports, then after each image)."""
    wall: float
    marks: list[float]

    @property
    def n(self) -> int:
        return len(self.marks) - 1

    @property
    def per_image(self) -> float:
        """Wall per image after the first: (last image - first image) / (N - 1)."""
        return (self.marks[-1] - self.marks[1]) / (self.n - 1)

    @property
    def startup(self) -> float:
        """Everything but N steady images: wall - N x per image."""
        return self.wall - self.n * self.per_image

    @property
    def imports(self) -> float:
        return self.marks[0]


def run_batch(renderer: str, scenes: list[str], spp: int, folder: str) -> BatchRun:
    """Render the scene files ``scenes`` at ``spp`` in one fresh process of ``renderer``
    ("mitsuba": relight's environment, "cycles": the Blender one), outputs in ``folder``."""
    python = sys.executable if renderer == "mitsuba" else blender.blender_python()
    if python is None:
        from relight.errors import BlenderError
        raise BlenderError(blender.INSTALL_HINT)
    os.makedirs(folder, exist_ok=True)
    script = os.path.join(folder, "batch.py")
    with open(script, "w") as f:
        f.write(BATCH_SCRIPT)
    items = [{"scene": s, "exr": os.path.join(folder, f"{i}.exr"), "png": os.path.join(folder, f"{i}.png")}
             for i, s in enumerate(scenes)]
    job = {"renderer": renderer, "spp": int(spp), "scenes": items, "marks": os.path.join(folder, "marks.json")}
    job_path = os.path.join(folder, "job.json")
    with open(job_path, "w") as f:
        json.dump(job, f)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (REPO, env.get("PYTHONPATH")) if p)
    t0 = time.perf_counter()
    done = subprocess.run([python, script, job_path], capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise RuntimeError(f"{renderer} batch failed: {(done.stderr or '').strip()[-300:]}")
    missing = [it["exr"] for it in items if not os.path.isfile(it["exr"])]
    if missing:
        raise RuntimeError(f"{renderer} batch wrote no {missing[0]}")
    with open(job["marks"]) as f:
        return BatchRun(wall, json.load(f))


def equal_error_spp(specs, errors: dict, target: float) -> tuple[int, int] | None:
    """Mitsuba's and Cycles' sample counts at ``target`` (from the ladder, rounded up;
    Mitsuba's to one its sampler takes exactly), or None when one is above the ladder."""
    from relight.render import exact_spp
    sm, sc = spp_for(errors["m"], target), spp_for(errors["c"], target)
    if sm is None or sc is None:
        return None
    sampler = getattr(specs[0].render, "sampler", "independent")
    return exact_spp(sampler, math.ceil(sm)), math.ceil(sc)


def end_to_end_batch(n: int, res: int, errors: dict, times: dict, targets: list[float],
                     repeats: int) -> None:
    """(d): ``n`` default scene files in one process per renderer (module docstring)."""
    from relight.generator.sampling import GeneratorConfig, sample_scene
    specs = [sample_scene(GeneratorConfig(res=res), SCENE_SEED, i) for i in range(n)]
    print(f"\n## (d) end to end, batch form: {n} default scene files ({res} px) in one process per "
          f"renderer; fastest of {repeats} alternated repeats")
    with tempfile.TemporaryDirectory(prefix="relight-e2e-batch-") as tmp:
        scenes = []
        for i, spec in enumerate(specs):
            scenes.append(os.path.join(tmp, f"scene{i}.json"))
            spec.save(scenes[-1])
        for target in targets:
            counts = equal_error_spp(specs, errors, target)
            print(f"\n### relative RMSE {target}")
            if counts is None:
                print("a renderer does not reach the target on the ladder: no batch figure")
                continue
            spp = dict(zip(("m", "c"), counts))
            runs = {"m": [], "c": []}
            for r in range(repeats):   # alternate which side goes first
                for key in (("m", "c") if r % 2 == 0 else ("c", "m")):
                    folder = os.path.join(tmp, f"{target}-{key}-{r}")
                    runs[key].append(run_batch("mitsuba" if key == "m" else "cycles", scenes, spp[key], folder))
            best = {k: min(v, key=lambda run: run.wall) for k, v in runs.items()}
            print("| renderer | spp | process wall s (all repeats) | per image after the first s "
                  "| start-up s (wall - N x per image) | of which imports before the first scene s |")
            print("|---|---|---|---|---|---|")
            for key, name in (("m", "Mitsuba (relight: EXR + PNG)"), ("c", "Cycles (EXR)")):
                b = best[key]
                print(f"| {name} | {spp[key]} | {b.wall:.2f} ({', '.join(f'{x.wall:.2f}' for x in runs[key])}) "
                      f"| {b.per_image:.3f} | {b.startup:.2f} | {b.imports:.2f} |")
            m, c = best["m"], best["c"]
            call = time_at(times["c"], spp_for(errors["c"], target)) / time_at(times["m"], spp_for(errors["m"], target))
            print(f"Cycles / relight: process {c.wall / m.wall:.2f}, per image {c.per_image / m.per_image:.2f} "
                  f"(render call on a loaded scene, (b): {call:.2f}); relight's per image at its kernel "
                  f"alone (per image / {PROFILE_TOTAL_OVER_KERNEL}) would give "
                  f"{c.per_image / (m.per_image / PROFILE_TOTAL_OVER_KERNEL):.2f}")


# --------------------------------------------------------------------------- main
def relative_rmse_list(text: str) -> list[float]:
    """``--targets``: comma-separated relative RMSEs, each in (0, 1]."""
    return [at.relative_rmse(t.strip()) for t in text.split(",")]


def main(argv: list[str] | None = None) -> int:
    ap = at.OneLineParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=at.int_in(1, 100_000, "a count"), default=4, help="scenes")
    ap.add_argument("--res", type=at.resolution, default=128)
    ap.add_argument("--ref-spp", type=at.spp, default=2048, help="samples of the converged references")
    ap.add_argument("--targets", type=relative_rmse_list, default=[0.03, 0.015, 0.0075],
                    help="relative RMSE targets, comma-separated (default 0.03,0.015,0.0075)")
    ap.add_argument("--cache", default=DEFAULT_CACHE, help="folder of cached references")
    ap.add_argument("--end-to-end", action="store_true",
                    help="also time the user's command per scene file at the first target (section c)")
    ap.add_argument("--batch", type=at.int_in(2, 10_000, "a scene-file count"), default=None, metavar="N",
                    help="with --end-to-end: also N scene files in one process per renderer at every "
                         "target (section d)")
    ap.add_argument("--repeats", type=at.int_in(1, 100, "a repeat count"), default=2,
                    help="alternated repeats of each batch process (default 2; the fastest is shown)")
    args = ap.parse_args(argv)
    if args.batch is not None and not args.end_to_end:
        ap.error("--batch needs --end-to-end")
    if blender.blender_python() is None:
        print("bench_cycles: skipped (no Blender environment; run scripts/setup_blender.sh)")
        return 0
    from relight.generator.sampling import GeneratorConfig, sample_scene
    cache = os.path.expanduser(args.cache)
    os.makedirs(cache, exist_ok=True)
    targets = args.targets
    specs = [sample_scene(GeneratorConfig(res=args.res), SCENE_SEED, i) for i in range(args.n)]

    mitsuba, mitsuba_eon, cycles = MitsubaSide(), MitsubaSide(eon=True), CyclesSide()
    try:
        bar = tqdm(total=args.n * 5 + args.n * len(LADDER_SPP), desc="bench_cycles", leave=False)
        refs = {}
        for i, spec in enumerate(specs):
            refs["m", i] = reference(mitsuba, spec, args.ref_spp, cache); bar.update()
            refs["c", i] = reference(cycles, spec, args.ref_spp, cache); bar.update()
            refs["m0", i] = reference(mitsuba, _lambert(spec), args.ref_spp, cache); bar.update()
            refs["c0", i] = reference(cycles, _lambert(spec), args.ref_spp, cache); bar.update()
            refs["me", i] = reference(mitsuba_eon, spec, args.ref_spp, cache); bar.update()

        cycles.render(specs[0], 4, 1)   # warm: Cycles' device and kernels start once per process
        errors = {"m": {}, "c": {}}
        times = {"m": {}, "c": {}}
        for spp in LADDER_SPP:   # alternate the renderers so both see the same machine load
            per = {"m": ([], []), "c": ([], [])}
            for i, spec in enumerate(specs):
                seed = spec.render.seed + NOISY_SEED_OFFSET + spp
                mitsuba.render(spec, spp, seed + 1)          # warm: kernels compiled
                for key, side in (("m", mitsuba), ("c", cycles)):
                    image, seconds = side.render(spec, spp, seed)
                    per[key][0].append(blender.relative_rmse(image, refs[key, i]))
                    per[key][1].append(seconds)
                bar.update()
            for key in per:
                errors[key][spp] = float(np.mean(per[key][0]))
                times[key][spp] = float(np.mean(per[key][1]))
        bar.close()
    finally:
        cycles.worker.close()

    # (a) cross-check
    floor = [math.hypot(errors["m"][LADDER_SPP[-1]], errors["c"][LADDER_SPP[-1]])
             * math.sqrt(LADDER_SPP[-1] / args.ref_spp)]
    print(f"# Mitsuba (relight) vs Blender {cycles.worker.version} Cycles: {args.n} default scenes, "
          f"{args.res} px, path depth {specs[0].render.max_depth}, Mitsuba sampler "
          f"{getattr(specs[0].render, 'sampler', 'independent')}, Cycles {blender.SAMPLING_PATTERN}")
    print(f"\n## (a) converged renders ({args.ref_spp} spp each): Cycles against Mitsuba")
    print("| scene | objects (roughness) | mean Cycles / Mitsuba | rel. RMSE | rel. RMSE, roughness 0 "
          "| mean ratio, roughness 0 | rel. RMSE, Mitsuba + Cycles' multiscatter term |")
    print("|---|---|---|---|---|---|---|")
    cols = {"std": [], "l": [], "e": []}
    for i, spec in enumerate(specs):
        m, c, m0, c0, me = (refs[k, i] for k in ("m", "c", "m0", "c0", "me"))
        objs = ", ".join(f"{o.family} {o.roughness:.2f}" for o in spec.objects)
        row = (c.mean() / m.mean(), blender.relative_rmse(c, m), blender.relative_rmse(c0, m0),
               c0.mean() / m0.mean(), blender.relative_rmse(c, me))
        cols["std"].append(row[1]); cols["l"].append(row[2]); cols["e"].append(row[4])
        print(f"| {spec.id} | {objs} | {row[0]:.4f} | {row[1]:.4f} | {row[2]:.4f} | {row[3]:.4f} | {row[4]:.4f} |")
    print(f"| mean | | | {np.mean(cols['std']):.4f} | {np.mean(cols['l']):.4f} | | {np.mean(cols['e']):.4f} |")
    print(f"\nnoise floor of two {args.ref_spp}-spp references (extrapolated from the ladder): "
          f"{floor[0]:.4f}")

    # (b) equal error
    print("\n## (b) relative RMSE against each renderer's own reference, seconds per image")
    print("| spp | Mitsuba rel. RMSE | Mitsuba s | Cycles rel. RMSE | Cycles s |")
    print("|---|---|---|---|---|")
    for spp in LADDER_SPP:
        print(f"| {spp} | {errors['m'][spp]:.4f} | {times['m'][spp]:.3f} | {errors['c'][spp]:.4f} | "
              f"{times['c'][spp]:.3f} |")
    for key, name in (("m", "Mitsuba"), ("c", "Cycles")):
        x = np.array(LADDER_SPP, float)
        k, t0 = np.polyfit(x, [times[key][s] for s in LADDER_SPP], 1)
        print(f"{name}: t = {t0:.3f} s + {k * 1000:.3f} ms x spp (fixed cost per image + cost per sample)")
    print("\n| target rel. RMSE | Mitsuba spp | Mitsuba s/image | Cycles spp | Cycles s/image | Cycles / Mitsuba time |")
    print("|---|---|---|---|---|---|")
    for target in targets:
        sm, sc = spp_for(errors["m"], target), spp_for(errors["c"], target)
        tm = time_at(times["m"], sm) if sm else None
        tc = time_at(times["c"], sc) if sc else None
        ratio = f"{tc / tm:.1f}" if tm and tc else "-"
        fmt = lambda s, t: ("> ladder", "-") if s is None else (f"{s:.0f}", f"{t:.3f}")  # noqa: E731
        print(f"| {target:.4f} | {' | '.join(fmt(sm, tm))} | {' | '.join(fmt(sc, tc))} | {ratio} |")
    if args.end_to_end:
        end_to_end(specs, errors, targets[0])
        if args.batch:
            end_to_end_batch(args.batch, args.res, errors, times, targets, args.repeats)
    return 0


if __name__ == "__main__":
    sys.exit(at.run_script(main))

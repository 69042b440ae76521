"""Benchmark: inverse rendering vs the network vs classical colour baselines.

On a held-out generated set (scene geometry known), in one run:

* errors (pan, tilt, direction, colour; mean and median, degrees) and seconds per
  image for: the network single shot, inverse rendering from the grid search,
  inverse rendering refined from the network, and the four colour baselines;
* the speed ratio network : inverse and the iterations/renders saved by starting
  from the network;
* the bias and cost of the direction-gradient estimator: the optimiser's
  finite differences (both levels) and Mitsuba's shading-only AD gradient, each
  against a fine finite-difference reference (512 spp, h = 0.25 deg, 64 px);
* a convergence plot (direction error vs LM iteration and vs seconds) for a few images.

The data (not in the repo) is made on first use when ``--data`` holds no dataset:
``--n`` images (at least 20) of the default generator at 32 spp, seed 3, the same as::

    relight generate --count 20 --out ~/relight-data/inv_bench --seed 3 --spp 32
    python benchmarks/bench_inverse.py --data ~/relight-data/inv_bench --n 10

If no network model can be loaded, the "network" rows use a stand-in start (the true
direction moved 8 deg in a random direction) and are labelled so.
"""
from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from relight.commands import argtypes as at  # noqa: E402

STANDIN_OFFSET_DEG = 8.0
REF_SPP, REF_STEP_DEG, REF_RES = 512, 0.25, 64
DATA_SEED, DATA_SPP, DATA_MIN_COUNT = 3, 32, 20


def ensure_data(folder: str, n: int) -> None:
    """Generate the benchmark's dataset in ``folder`` when it is missing or has fewer
    than ``n`` images (resumes an unfinished one); one line says so."""
    from relight.dataset import MANIFEST, read_manifest
    from relight.generator.run import generate
    from relight.generator.sampling import GeneratorConfig
    have = len(read_manifest(folder)) if os.path.isfile(os.path.join(folder, MANIFEST)) else 0
    if have >= n:
        return
    count = max(n, DATA_MIN_COUNT)
    print(f"# bench_inverse: making {count} images in {folder} (relight generate --count {count} "
          f"--out {folder} --seed {DATA_SEED} --spp {DATA_SPP})", file=sys.stderr)
    generate(folder, count, seed=DATA_SEED, cfg=GeneratorConfig(spp=DATA_SPP))


def _errors(preds, recs):
    """The table's errors: pan over the lights below the zenith (``pan_all`` every light's)."""
    from relight.metrics import light_errors, table_values
    pan = [p[0] for p in preds]
    tilt = [p[1] for p in preds]
    rgb = [p[2] for p in preds]
    tilt_gt = np.array([r["light"]["tilt_deg"] for r in recs])
    return table_values(light_errors(np.array(pan), np.array(tilt), np.array(rgb),
                                     np.array([r["pan_rel_deg"] for r in recs]), tilt_gt,
                                     np.array([r["light"]["rgb"] for r in recs])), tilt_gt)


def _colour_errors(rgbs, recs):
    from relight.metrics import colour_error_deg
    return {"colour": colour_error_deg(np.array(rgbs), np.array([r["light"]["rgb"] for r in recs]))}


def _row(name, errs, seconds, iters="", renders=""):
    cells = [name]
    for m in ("pan", "tilt", "direction", "colour"):
        e = errs.get(m)
        cells.append("-" if e is None or not len(e) else f"{np.mean(e):.2f} / {np.median(e):.2f}")
    cells += [f"{seconds:.3f}", str(iters), str(renders)]
    return "| " + " | ".join(cells) + " |"


def _direction_err(trace_rows, rec):
    from relight.metrics import direction_error_deg
    return np.array([float(direction_error_deg(t["pan_deg"], t["tilt_deg"], rec["pan_rel_deg"],
                                               rec["light"]["tilt_deg"])) for t in trace_rows])


def cost_to_accuracy(trace, rec, tol_deg=1.0):
    """(LM iterations, renders) after which the direction error stays <= tol_deg
    (inf if it never does): the cost of reaching a given accuracy, wasted starts included."""
    rows = [t for t in trace if t["stage"] != "grid"]
    err = _direction_err(rows, rec)
    bad = np.nonzero(err > tol_deg)[0]
    if len(bad) == 0:
        return rows[0]["iteration"], rows[0]["renders"]
    if bad[-1] == len(rows) - 1:
        return math.inf, math.inf
    return rows[bad[-1] + 1]["iteration"], rows[bad[-1] + 1]["renders"]


def gradient_study(recs, data, n):
    """Angle (deg) and magnitude ratio of each estimator against the fine reference."""
    from relight.dataset import load_spec, safe_join
    from relight.frames import tangent_move
    from relight.inverse.objective import LightRenderer, downsample, loss_gradient
    from relight.inverse.optimize import DEFAULT_LEVELS, shading_ad_loss_gradient
    from relight.imageio import read_image
    from relight.scene.build import SceneBuilder
    rows = {"FD L0 (32px, 8spp, h=2)": [], "FD L1 (64px, 32spp, h=0.5)": [],
            "AD shading-only (64px, 32spp)": []}
    cost = {k: [] for k in rows}
    cost["FD reference (64px, 512spp, h=0.25)"] = []
    for rec in recs[:n]:
        spec = load_spec(data, rec)
        image = read_image(safe_join(data, rec["exr"]))[0]
        renderer = LightRenderer(spec, SceneBuilder(max_templates=2))
        pan, tilt = tangent_move(rec["pan_rel_deg"], rec["light"]["tilt_deg"], 4.0, -3.0)
        r = spec.light.r_m
        t0 = time.perf_counter()
        _, g_ref = loss_gradient(renderer, downsample(image, REF_RES), pan, tilt, r, REF_SPP, 11, REF_STEP_DEG)
        cost["FD reference (64px, 512spp, h=0.25)"].append(time.perf_counter() - t0)
        runs = {
            "FD L0 (32px, 8spp, h=2)": lambda: loss_gradient(renderer, downsample(image, 32), pan, tilt, r,
                                                             DEFAULT_LEVELS[0].spp, 1, DEFAULT_LEVELS[0].fd_step_deg),
            "FD L1 (64px, 32spp, h=0.5)": lambda: loss_gradient(renderer, downsample(image, 64), pan, tilt, r,
                                                                DEFAULT_LEVELS[1].spp, 2, DEFAULT_LEVELS[1].fd_step_deg),
            "AD shading-only (64px, 32spp)": lambda: shading_ad_loss_gradient(renderer, downsample(image, 64), pan,
                                                                      tilt, r, 32, 2),
        }
        for name, fn in runs.items():
            t0 = time.perf_counter()
            _, g = fn()
            cost[name].append(time.perf_counter() - t0)
            cos = g @ g_ref / (np.linalg.norm(g) * np.linalg.norm(g_ref))
            rows[name].append((math.degrees(math.acos(np.clip(cos, -1, 1))),
                               np.linalg.norm(g) / np.linalg.norm(g_ref),
                               (g @ g_ref) / (g_ref @ g_ref)))
    print(f"\n### Direction-gradient estimators vs FD reference ({REF_RES}px, {REF_SPP}spp, "
          f"h={REF_STEP_DEG} deg), {min(n, len(recs))} images, 5 deg off the true light\n")
    print("| estimator | angle to ref (deg) mean / max | |g|/|g_ref| mean | projection on ref mean | s per gradient |")
    print("|---|---|---|---|---|")
    for name, vals in rows.items():
        a = np.array(vals)
        print(f"| {name} | {a[:, 0].mean():.1f} / {a[:, 0].max():.1f} | {a[:, 1].mean():.2f} | "
              f"{a[:, 2].mean():.2f} | {np.mean(cost[name]):.2f} |")
    print(f"| FD reference | 0 | 1 | 1 | {np.mean(cost['FD reference (64px, 512spp, h=0.25)']):.2f} |")


def main(argv=None) -> int:
    ap = at.OneLineParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.path.join("~", "relight-data", "inv_bench"),
                    help="dataset folder (made when missing; default ~/relight-data/inv_bench)")
    ap.add_argument("--n", type=at.int_in(1, 100_000, "a count"), default=10, help="images (first N of the manifest, all splits)")
    at.add_model_option(ap, default_text=False, default="sid2",
                        help="the network's single shot (default sid2: the set is relight's SID2-style rooms)")
    ap.add_argument("--out-dir", default="/tmp/bench_inverse", help="predictions, traces and the plot")
    ap.add_argument("--plot-n", type=at.int_in(0, 100_000, "a count"), default=3, help="images in the convergence plot")
    ap.add_argument("--grad-n", type=at.int_in(0, 100_000, "a count"), default=3, help="images in the gradient study (0: skip)")
    ap.add_argument("--threads", type=at.threads, default=None)
    args = ap.parse_args(argv)

    from relight import backend
    backend.init(args.threads)
    from relight.dataset import load_spec, read_manifest, safe_join
    from relight.inverse import colour_baselines as cb
    from relight.frames import tangent_move
    from relight.inverse.optimize import InvertConfig, invert
    from relight.predictions import write_predictions
    from relight.imageio import read_image
    from relight.scene.build import SceneBuilder

    os.makedirs(args.out_dir, exist_ok=True)
    args.data = os.path.expanduser(args.data)
    ensure_data(args.data, args.n)
    recs = read_manifest(args.data)[:args.n]
    images = [read_image(safe_join(args.data, r["exr"]))[0] for r in recs]
    specs = [load_spec(args.data, r) for r in recs]
    cfg = InvertConfig()
    print(f"# bench_inverse: {len(recs)} images of {args.data} "
          f"({images[0].shape[0]} px), {backend.describe()}")

    # --- network single shot (or labelled stand-in) -------------------------------
    net_label, net_seconds = "network single shot", float("nan")
    try:
        from relight.net.predict import load_model, predict_arrays
        model = load_model(args.model)
        predict_arrays(model, images[:1], [recs[0]["camera"]["tilt_deg"]])  # warm-up
        t0 = time.perf_counter()
        net = predict_arrays(model, images, [r["camera"]["tilt_deg"] for r in recs])
        net_seconds = (time.perf_counter() - t0) / len(recs)
        net_preds = [(p["pan_deg"], p["tilt_deg"], np.asarray(p["rgb"])) for p in net]
    except Exception as exc:  # noqa: BLE001 - any failure: say so and use the stand-in
        print(f"network unavailable ({type(exc).__name__}: {str(exc).splitlines()[0][:100]}); "
              f"using the true direction moved {STANDIN_OFFSET_DEG} deg as the start")
        net_label = f"stand-in start (truth + {STANDIN_OFFSET_DEG:g} deg)"
        rng = np.random.default_rng(0)
        net_preds = []
        for r in recs:
            a = rng.uniform(0, 2 * np.pi)
            p, t = tangent_move(r["pan_rel_deg"], r["light"]["tilt_deg"],
                                STANDIN_OFFSET_DEG * math.cos(a), STANDIN_OFFSET_DEG * math.sin(a))
            net_preds.append((p, min(t, 90.0), np.ones(3)))

    # --- inverse rendering: grid start and network start --------------------------
    results = {"grid": [], "net": []}
    for i, (rec, spec, img) in enumerate(zip(recs, specs, images)):
        builder = SceneBuilder(max_templates=2)  # live scenes slow Dr.Jit down: one per image
        results["grid"].append(invert(spec, img, "grid", cfg, builder))
        results["net"].append(invert(spec, img, net_preds[i][:2], cfg, builder))
        g, n = results["grid"][-1], results["net"][-1]
        e = _errors([(g.pan_rel_deg, g.tilt_deg, g.rgb), (n.pan_rel_deg, n.tilt_deg, n.rgb)], [rec, rec])
        print(f"  {rec['id']}: gt pan_rel {rec['pan_rel_deg']:.0f} tilt {rec['light']['tilt_deg']:.0f} | "
              f"grid dir {e['direction'][0]:.2f} col {e['colour'][0]:.2f} ({g.iterations} it, {g.renders} r, "
              f"{g.seconds:.1f} s) | from net dir {e['direction'][1]:.2f} ({n.iterations} it, "
              f"{n.renders} r, {n.seconds:.1f} s)", flush=True)
    from relight.inverse.jobs import Job, write_trace_csv
    for key, res in results.items():
        write_trace_csv(os.path.join(args.out_dir, f"inverse_{key}.trace.csv"),
                        [(Job(rec["id"], "", "", 0.0), r) for r, rec in zip(res, recs)])
        write_predictions(os.path.join(args.out_dir, f"inverse_{key}.json"),
                          [r.entry(rec["id"]) for r, rec in zip(res, recs)], dataset=args.data,
                          method="inverse", init="grid" if key == "grid" else net_label)

    # --- colour baselines ----------------------------------------------------------
    baseline_rows = {}
    for name in cb.METHODS:
        t0 = time.perf_counter()
        rgbs = [cb.estimate(name, img) for img in images]
        baseline_rows[name] = (_colour_errors(rgbs, recs), (time.perf_counter() - t0) / len(recs))
        cb.write_colour_predictions(os.path.join(args.out_dir, f"baseline_{name}.json"),
                                    [{"id": r["id"], "rgb": [float(c) for c in v]} for r, v in zip(recs, rgbs)],
                                    dataset=args.data, method=name)

    # --- table ------------------------------------------------------------------------
    def summary(res):
        return (_errors([(r.pan_rel_deg, r.tilt_deg, r.rgb) for r in res], recs),
                np.mean([r.seconds for r in res]), np.mean([r.iterations for r in res]),
                np.mean([r.renders for r in res]))

    eg, sg, ig, rg = summary(results["grid"])
    en, sn, in_, rn = summary(results["net"])
    print(f"\n### Errors in degrees (mean / median), {len(recs)} images\n")
    zenith = sum(float(r["light"]["tilt_deg"]) >= 90.0 for r in recs)
    print(f"| method | pan (tilt < 90; {zenith} zenith left out) | tilt | direction | colour | s / image | "
          "LM iterations | renders |")
    print("|---|---|---|---|---|---|---|---|")
    net_errs = _errors(net_preds, recs)
    if net_label == "network single shot":
        print(_row(net_label, net_errs, net_seconds))
    else:
        print(_row(net_label, {k: v for k, v in net_errs.items() if k != "colour"}, 0.0))
    print(_row("inverse from grid", eg, sg, f"{ig:.1f}", f"{rg:.0f}"))
    print(_row(f"inverse from {net_label}", en, sn, f"{in_:.1f}", f"{rn:.0f}"))
    for name, (errs, sec) in baseline_rows.items():
        print(_row(name + (" (p=6)" if name in ("shades-of-gray", "gray-edge") else ""), errs, sec))
    print("\n### Ratios (same run)\n")
    if math.isfinite(net_seconds):
        print(f"- speed, inverse-from-grid : network seconds per image = {sg / net_seconds:.0f} : 1")
    print(f"- LM iterations, start from {net_label} / grid start = {in_ / ig:.2f} "
          f"(renders {rn / rg:.2f}; seconds {sn / sg:.2f})")
    for tol in (1.0, 0.5):
        cg = np.array([cost_to_accuracy(r.trace, rec, tol) for r, rec in zip(results["grid"], recs)])
        cn = np.array([cost_to_accuracy(r.trace, rec, tol) for r, rec in zip(results["net"], recs)])
        print(f"- until the direction error stays <= {tol:g} deg (mean over images reaching it; "
              f"grid {int(np.isfinite(cg[:, 0]).sum())}, net {int(np.isfinite(cn[:, 0]).sum())} of {len(recs)}): "
              f"LM iterations grid {np.mean(cg[np.isfinite(cg[:, 0]), 0]):.1f} vs net "
              f"{np.mean(cn[np.isfinite(cn[:, 0]), 0]):.1f}; renders grid "
              f"{np.mean(cg[np.isfinite(cg[:, 1]), 1]):.0f} vs net {np.mean(cn[np.isfinite(cn[:, 1]), 1]):.0f}")
    print(f"- inverse from grid: median direction {np.median(eg['direction']):.2f} deg (target <= 1), "
          f"median colour {np.median(eg['colour']):.2f} deg (target <= 0.5), "
          f"{sg:.1f} s per {images[0].shape[0]} px image (target <= 20); "
          f"images over 1 deg: {int(np.sum(eg['direction'] > 1.0))}")
    worst = np.argsort(eg["direction"])[::-1][:3]
    print("- worst grid-start images: " + ", ".join(
        f"{recs[i]['id']} (pan_rel {recs[i]['pan_rel_deg']:.0f}, tilt {recs[i]['light']['tilt_deg']:.0f}, "
        f"cam tilt {recs[i]['camera']['tilt_deg']:.0f}: {eg['direction'][i]:.2f} deg)" for i in worst))

    # --- convergence plot ---------------------------------------------------------------
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    for i in range(min(args.plot_n, len(recs))):
        for key, style in (("grid", "-"), ("net", "--")):
            tr = [t for t in results[key][i].trace if t["stage"] != "grid"]
            err = np.maximum(_direction_err(tr, recs[i]), 1e-3)
            label = f"{recs[i]['id']} {'grid' if key == 'grid' else 'net'}"
            ax1.semilogy([t["iteration"] for t in tr], err, style, marker=".", label=label)
            ax2.semilogy([t["seconds"] for t in tr], err, style, marker=".", label=label)
    for ax, xl in ((ax1, "LM iteration (all starts)"), (ax2, "seconds")):
        ax.axhline(1.0, color="grey", lw=0.5)
        ax.set_xlabel(xl)
        ax.set_ylabel("direction error (deg)")
    ax1.legend(fontsize=7)
    fig.suptitle("inverse rendering convergence: grid start (solid) vs network start (dashed)")
    fig.tight_layout()
    plot = os.path.join(args.out_dir, "convergence.png")
    fig.savefig(plot, dpi=110)
    print(f"\nconvergence plot: {plot}; predictions and traces in {args.out_dir}")

    if args.grad_n > 0:
        gradient_study(recs, args.data, args.grad_n)
    return 0


if __name__ == "__main__":
    sys.exit(at.run_script(main))

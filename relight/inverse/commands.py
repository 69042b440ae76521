"""``relight invert`` (inverse rendering of the light) and ``relight baseline`` (colour
constancy baselines), plus the small library functions they call."""
from __future__ import annotations

import csv
import dataclasses
import os
import sys
from dataclasses import dataclass

from relight.commands import argtypes as at

SPLITS = ("test", "val", "train", "all")


@dataclass(frozen=True)
class Job:
    """One image to invert: its id, scene, linear image file and camera tilt (deg)."""
    id: str
    scene_path: str
    image_path: str
    camera_tilt_deg: float


def dataset_jobs(data_dir: str, split: str = "test", limit: int | None = None) -> list[Job]:
    """Jobs of a dataset split (``"all"`` for every record), in manifest order; the
    target of each is its linear EXR."""
    from relight.dataset import DatasetError, read_manifest, safe_join
    if split not in SPLITS:
        raise DatasetError(f"split must be one of {', '.join(SPLITS)}, got {split!r}")
    records = [r for r in read_manifest(data_dir) if split == "all" or r.get("split") == split]
    if limit is not None:
        records = records[:limit]
    if not records:
        raise DatasetError(f"{data_dir}: no records in split {split!r}")
    for r in records:
        if "scene" not in r or "exr" not in r:
            raise DatasetError(f"{data_dir}: record {r['id']!r} has no scene or exr file")
    return [Job(r["id"], safe_join(data_dir, r["scene"]), safe_join(data_dir, r["exr"]),
                float(r["camera"]["tilt_deg"])) for r in records]


def network_starts(jobs: list[Job], model_path: str | None = None) -> dict[str, tuple[float, float]]:
    """``{id: (pan_rel_deg, tilt_deg)}`` predicted by the trained network (the shipped
    model, or ``model_path``)."""
    from relight.inverse.optimize import InverseError
    from relight.render import read_image
    try:
        from relight.net.predict import load_model, predict_arrays
    except ImportError as exc:
        raise InverseError(f"--init network: the network predictor is unavailable ({exc})") from None
    model = load_model(model_path)
    images = [read_image(j.image_path)[0] for j in jobs]
    preds = predict_arrays(model, images, [j.camera_tilt_deg for j in jobs])
    return {j.id: (float(p["pan_deg"]), float(p["tilt_deg"])) for j, p in zip(jobs, preds)}


def file_starts(path: str, jobs: list[Job]) -> dict[str, tuple[float, float]]:
    """Starts from a predictions file; a single-entry file also serves a single job
    whose id differs."""
    from relight.inverse.optimize import InverseError
    from relight.predictions import read_predictions
    preds = {p.id: p for p in read_predictions(path).predictions}
    out = {}
    for j in jobs:
        p = preds.get(j.id)
        if p is None and len(preds) == 1 and len(jobs) == 1:
            p = next(iter(preds.values()))
        if p is None:
            raise InverseError(f"--init {path}: no prediction for image {j.id!r}")
        pan, tilt, _ = p.resolve(j.camera_tilt_deg)
        out[j.id] = (pan, tilt)
    return out


def invert_jobs(jobs: list[Job], init: str, cfg, progress: bool = True,
                model_path: str | None = None) -> list[tuple[Job, object]]:
    """Run :func:`relight.inverse.optimize.invert` on each job (one shared scene builder);
    ``init`` is ``"grid"``, ``"network"`` or a predictions file path."""
    from tqdm import tqdm

    from relight import backend
    from relight.inverse.optimize import invert
    from relight.render import read_image
    from relight.scene.build import SceneBuilder
    from relight.scene.spec import load_scene
    backend.init()
    if init == "grid":
        starts = {}
    elif init == "network":
        starts = network_starts(jobs, model_path)
    else:
        starts = file_starts(init, jobs)
    out = []
    for job in tqdm(jobs, desc="invert", unit="img", disable=not progress):
        spec = load_scene(job.scene_path)
        image, _ = read_image(job.image_path)
        # a fresh builder per image: every live Mitsuba scene enlarges Dr.Jit's virtual-call
        # tables; one shared builder measured 1.1-1.2 s per image against 0.9 s (10 images)
        out.append((job, invert(spec, image, starts.get(job.id, "grid"), cfg, SceneBuilder(max_templates=2))))
    return out


TRACE_FIELDS = ("id", "iteration", "stage", "start", "loss", "pan_deg", "tilt_deg", "r_m",
                "r", "g", "b", "renders", "seconds")


def write_trace_csv(path: str, results, transaction=None) -> None:
    """One CSV row per logged optimiser state (pan_deg = pan_rel), atomically (or staged
    in ``transaction``)."""
    from relight.fileio import atomic_write
    (transaction.stage if transaction is not None else atomic_write)(
        path, lambda tmp: _write_trace(tmp, results))


def _write_trace(tmp: str, results) -> None:
    with open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(TRACE_FIELDS)
        for job, res in results:
            for t in res.trace:
                w.writerow([job.id, t["iteration"], t["stage"], t["start"], f"{t['loss']:.6e}",
                            f"{t['pan_deg']:.4f}", f"{t['tilt_deg']:.4f}", f"{t['r_m']:.4f}",
                            *[f"{c:.6f}" for c in t["rgb"]], t["renders"], t["seconds"]])


def add_commands(sub) -> None:
    v = sub.add_parser("invert", help="recover the light by inverse rendering (scene known)",
                       description="Fit the light direction (pan/tilt on the sphere of the scene's "
                                   "light radius) and colour to an image by rendering its known scene "
                                   "(Levenberg-Marquardt on finite-difference or, with --gradient ad, "
                                   "automatic-differentiation Jacobians; closed-form colour).")
    src = v.add_mutually_exclusive_group(required=True)
    src.add_argument("--data", help="dataset folder (targets: the records' linear EXR images)")
    src.add_argument("--scene", help="scene file of a single image (with --image)")
    v.add_argument("--image", help="the image to invert (.exr linear, or .png sRGB) with --scene")
    v.add_argument("--split", choices=SPLITS, default="test", help="dataset split (default test)")
    v.add_argument("--limit", type=at.limit, default=None, help="first N images of the split")
    v.add_argument("--out", required=True, help="predictions file to write (relight.predictions/v1)")
    v.add_argument("--trace", default=None, help="per-iteration CSV (default: OUT with .trace.csv)")
    v.add_argument("--init", default="grid",
                   help="'grid' (coarse search, default), 'network', or a predictions file")
    v.add_argument("--model", default=None, help="model file for --init network (default: shipped)")
    v.add_argument("--max-iters", type=at.iterations, default=None, help="LM iterations per image (default 60)")
    v.add_argument("--time-budget", type=at.seconds, default=None,
                   help="seconds per image (default 60)")
    v.add_argument("--fit-radius", action="store_true", help="also fit the light distance")
    v.add_argument("--gradient", choices=("fd", "ad"), default="fd",
                   help="Jacobian of each LM step: 'fd' central finite differences (default) or "
                        "'ad' automatic differentiation with shadow-edge terms (relight.inverse.ad)")
    v.add_argument("--seed", type=at.seed, default=None, help="sampler seed of the fit (default 1)")
    v.add_argument("--quiet", action="store_true", help="no progress bar")
    v.set_defaults(func=cmd_invert)

    b = sub.add_parser("baseline", help="classical colour-constancy baselines (colour only)",
                       description="Estimate the light colour of each image with a classical "
                                   "method on the linear EXR; writes a colour-only predictions file.")
    from relight.inverse.colour_baselines import METHODS
    b.add_argument("name", choices=sorted(METHODS), help="method")
    b.add_argument("--data", required=True, help="dataset folder")
    b.add_argument("--split", choices=SPLITS, default="test", help="dataset split (default test)")
    b.add_argument("--limit", type=at.limit, default=None, help="first N images of the split")
    b.add_argument("--out", required=True, help="predictions file to write")
    b.set_defaults(func=cmd_baseline)


def cmd_invert(args) -> int:
    from relight.fileio import Transaction, check_file_target, check_outputs
    from relight.inverse.optimize import InverseError, InvertConfig
    from relight.predictions import write_predictions
    from relight.scene.spec import load_scene
    trace = args.trace or os.path.splitext(args.out)[0] + ".trace.csv"
    inputs = [args.data, args.scene, args.image, args.model,
              args.init if args.init not in ("grid", "network") else None]
    check_outputs([args.out, trace], inputs)
    if os.path.realpath(args.out) == os.path.realpath(trace):
        raise InverseError(f"--trace {trace} is the same file as --out")
    check_file_target(args.out)
    check_file_target(trace)
    if args.data:
        if args.image:
            raise InverseError("--image goes with --scene; with --data the targets are the dataset's EXRs")
        jobs = dataset_jobs(args.data, args.split, args.limit)
    else:
        if not args.image:
            raise InverseError("--scene needs --image (the picture to invert)")
        spec = load_scene(args.scene)
        jobs = [Job(spec.id, args.scene, args.image, spec.camera.tilt_deg)]
    overrides = {"max_iters": args.max_iters, "time_budget_s": args.time_budget, "seed": args.seed}
    cfg = InvertConfig(fit_radius=args.fit_radius, gradient=args.gradient, **{k: v for k, v in overrides.items() if v is not None})
    results = invert_jobs(jobs, args.init, cfg, progress=not args.quiet, model_path=args.model)
    settings = {"init": args.init, "max_iters": cfg.max_iters, "time_budget_s": cfg.time_budget_s,
                "fit_radius": cfg.fit_radius, "seed": cfg.seed, "gradient": cfg.gradient,
                "levels": [dataclasses.asdict(lv) for lv in cfg.levels]}
    with Transaction(inputs=inputs) as t:   # --out and --trace: both or neither
        write_predictions(args.out, [res.entry(job.id) for job, res in results],
                          dataset=os.path.abspath(args.data) if args.data else None,
                          method="inverse", settings=settings, transaction=t)
        write_trace_csv(trace, results, transaction=t)
    n = len(results)
    seconds = sum(r.seconds for _, r in results)
    print(f"{args.out}: {n} images, {sum(r.iterations for _, r in results) / n:.1f} iterations, "
          f"{sum(r.renders for _, r in results) / n:.0f} renders, {seconds / n:.1f} s per image; "
          f"trace: {trace}", file=sys.stdout)
    return 0


def cmd_baseline(args) -> int:
    from tqdm import tqdm

    from relight.inverse.colour_baselines import estimate, write_colour_predictions
    from relight.fileio import check_file_target, check_outputs
    from relight.render import read_image
    check_outputs([args.out], [args.data])
    check_file_target(args.out)
    jobs = dataset_jobs(args.data, args.split, args.limit)
    check_outputs([args.out], [j.image_path for j in jobs] + [j.scene_path for j in jobs])
    entries = []
    for job in tqdm(jobs, desc=args.name, unit="img", disable=len(jobs) < 50):
        rgb = estimate(args.name, read_image(job.image_path)[0])
        entries.append({"id": job.id, "rgb": [float(c) for c in rgb]})
    write_colour_predictions(args.out, entries, dataset=os.path.abspath(args.data), method=args.name)
    print(f"{args.out}: {len(entries)} colour estimates ({args.name}, colour only)")
    return 0

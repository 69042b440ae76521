"""``relight invert`` (inverse rendering of the light) and ``relight baseline`` (colour
constancy baselines)."""
from __future__ import annotations

__all__ = [
    "add_commands", "cmd_invert", "cmd_baseline",
]

import dataclasses
import os
import sys

from relight import engine
from relight.commands import argtypes as at
from relight.dataset import SPLIT_CHOICES as SPLITS
from relight.inverse.jobs import Job, dataset_jobs, invert_jobs, write_trace_csv


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
    at.add_model_option(v, help="the network of --init network")
    v.add_argument("--max-iters", type=at.iterations, default=None, help="LM iterations per image (default 60)")
    v.add_argument("--time-budget", type=at.seconds, default=None,
                   help="seconds per image (default 60)")
    v.add_argument("--fit-radius", action="store_true", help="also fit the light distance")
    v.add_argument("--gradient", choices=("fd", "ad"), default="fd",
                   help="Jacobian of each LM step: 'fd' central finite differences (default) or "
                        "'ad' automatic differentiation with shadow-edge terms (relight.inverse.ad)")
    v.add_argument("--seed", type=at.seed, default=None, help="sampler seed of the fit (default 1)")
    v.add_argument("--quiet", action="store_true", help="no progress bar")
    engine.add_arguments(v, "the fits")
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
    engine.add_arguments(b, "the estimates")
    b.set_defaults(func=cmd_baseline)


def cmd_invert(args) -> int:
    from relight.fileio import Transaction, check_file_target, check_outputs
    from relight.inverse.optimize import InverseError, InvertConfig
    from relight.predictions import write_predictions
    from relight.scene.spec import load_scene
    from relight.net.io import named_file
    trace = args.trace or os.path.splitext(args.out)[0] + ".trace.csv"
    model = named_file(args.model)   # a name: its file
    inputs = [args.data, args.scene, args.image, model,
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
    results = invert_jobs(jobs, args.init, cfg, progress=not args.quiet, model_path=args.model,
                          scheduler=engine.scheduler_from_args(args))
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
    import numpy as np

    from relight.inverse.colour_baselines import dataset_colour_errors, estimate_jobs, write_colour_predictions
    from relight.fileio import check_file_target, check_outputs
    check_outputs([args.out], [args.data])
    check_file_target(args.out)
    jobs = dataset_jobs(args.data, args.split, args.limit)
    check_outputs([args.out], [j.image_path for j in jobs] + [j.scene_path for j in jobs])
    entries = estimate_jobs(args.name, jobs, scheduler=engine.scheduler_from_args(args))
    write_colour_predictions(args.out, entries, dataset=os.path.abspath(args.data), method=args.name)
    err = dataset_colour_errors(entries, args.data)
    known = (f"; colour error against the lights of {len(err)}: mean {err.mean():.2f}, median "
             f"{np.median(err):.2f} degrees") if len(err) else ""
    print(f"{args.out}: {len(entries)} colour estimates ({args.name}, colour only){known}")
    return 0

"""``relight compare``, ``relight figure spheres|pole`` and ``relight envmap
from-light|to-light``: thin argument parsing over :mod:`relight.verify.compare`,
:mod:`relight.verify.report`, :mod:`relight.verify.figures` and :mod:`relight.verify.envmap`."""
from __future__ import annotations

__all__ = [
    "add_commands", "cmd_compare", "cmd_spheres", "cmd_pole",
    "envmap_width", "cmd_envmap_from_light", "cmd_envmap_to_light",
]

import os
import sys

from relight import engine
from relight.commands import argtypes as at
from relight.commands.argtypes import camera_tilt
from relight.frames import PHOTO_CAMERA_TILT_DEG as DEFAULT_PHOTO_CAMERA_TILT_DEG


def add_commands(sub) -> None:
    c = sub.add_parser("compare", help="re-render each scene under its predicted light; errors + figures",
                       description="Verify a relight.predictions/v1 or /v2 file: re-render every "
                                   "image's scene under the predicted light (a point light, or an "
                                   "HDR environment map: v2 'envmap' entries) with Mitsuba and write "
                                   "a report (panels, Figure 3, metrics.csv, summary.json, tables, "
                                   "index.html).")
    c.add_argument("predictions", help="predictions file (relight.predictions/v1 or /v2)")
    c.add_argument("--data", default=None, help="dataset folder (default: the file's 'dataset' field)")
    c.add_argument("--out", required=True, help="report folder (written atomically)")
    c.add_argument("--skip-bad", action="store_true", help="skip bad entries and list them in the report")
    c.add_argument("--limit", type=at.limit, default=None, help="compare only the first N predictions")
    c.add_argument("--max-columns", type=at.columns, default=8, help="columns of figure3 (default 8)")
    c.add_argument("--map-floor", action="store_true",
                   help="environment-map entries: also render the true light made a map (the 'map "
                        "floor': the least error any map reaches on that scene, since a map is "
                        "infinitely far and the scene's light is not); one more render per map entry")
    c.add_argument("--quiet", action="store_true", help="no progress bar")
    engine.add_arguments(c, "the re-renders")
    c.set_defaults(func=cmd_compare)

    _add_envmap_commands(sub)

    f = sub.add_parser("figure", help="figures of predictions: spheres (paper Fig. 4), pole (Fig. 5)")
    fsub = f.add_subparsers(dest="figure", metavar="FIGURE")
    fsub.required = True
    s = fsub.add_parser("spheres", help="diffuse + specular spheres under true and predicted light",
                        description="Per image, a diffuse and a specular sphere rendered under the "
                                    "ground-truth light (dataset record, or gt_pan_deg/gt_tilt_deg/"
                                    "gt_rgb fields of the entry) and under the predicted light.")
    s.add_argument("predictions", help="predictions file")
    s.add_argument("--data", default=None, help="dataset folder (default: the file's 'dataset' field, if any)")
    s.add_argument("--out", required=True, help="output folder (spheres_NNN.png/.pdf, 8 images a page)")
    s.add_argument("--camera-tilt", type=camera_tilt, default=DEFAULT_PHOTO_CAMERA_TILT_DEG,
                   help="camera tilt in degrees for entries without a dataset record (default 45)")
    s.add_argument("--res", type=at.resolution, default=96, help="sphere render size in pixels (default 96)")
    s.add_argument("--spp", type=at.spp, default=32, help="samples per pixel (default 32)")
    s.add_argument("--limit", type=at.limit, default=None, help="only the first N predictions")
    s.set_defaults(func=cmd_spheres)

    p = fsub.add_parser("pole", help="draw a rendered pole and its shadow under the predicted light",
                        description="Render a small pole and its cast shadow under the predicted "
                                    "light into IMAGE's top-left corner (paper Figure 5).")
    p.add_argument("image", help="image (PNG/JPEG taken as sRGB, EXR linear)")
    p.add_argument("predictions", help="predictions file")
    p.add_argument("--camera-tilt", type=camera_tilt, default=None,
                   help="camera tilt in degrees (default: the entry's camera_tilt_deg, e.g. the tilt the "
                        "model predicted, else 45 as in the paper)")
    p.add_argument("--id", default=None, help="entry to use (default: the only entry, or the image's file stem)")
    p.add_argument("--out", required=True, help="output PNG")
    p.set_defaults(func=cmd_pole)


def envmap_width(text: str) -> int:
    """An even map width in [8, 8192] pixels (the map is width x width/2)."""
    import argparse
    v = at.int_in(8, 8192, "a map width")(text)
    if v % 2:
        raise argparse.ArgumentTypeError(f"expected an even width (the map is width x width/2), got {v}")
    return v


def _add_envmap_commands(sub) -> None:
    e = sub.add_parser("envmap", help="environment maps <-> point-light predictions",
                       description="Convert between point-light predictions and HDR environment-map "
                                   "predictions (equirectangular linear EXR; frame in docs/conventions.md).")
    esub = e.add_subparsers(dest="envmap_command", metavar="CONVERSION")
    esub.required = True
    f = esub.add_parser("from-light", help="one map per entry: a small disc at the predicted light",
                        description="Write OUTDIR/maps/ID.exr for every point-light entry: a black map "
                                    "with a small disc (radius 1.5 pixels, at least 1 deg) toward the "
                                    "predicted light, in the camera frame of the entry's scene, whose "
                                    "irradiance at the scene centre equals the scene light's; and "
                                    "OUTDIR/predictions.json (relight.predictions/v2) whose entries "
                                    "carry only the map.")
    f.add_argument("predictions", help="point-light predictions file (relight.predictions/v1 or /v2)")
    f.add_argument("--data", default=None, help="dataset folder (default: the file's 'dataset' field)")
    f.add_argument("--out", required=True, help="output folder (written atomically)")
    f.add_argument("--width", type=envmap_width, default=256,
                   help="map width in pixels, even; the height is half (default 256)")
    f.add_argument("--frame", choices=("camera", "world"), default="camera",
                   help="frame of the maps (default camera: the centre column looks along the view)")
    f.add_argument("--quiet", action="store_true", help="no progress bar")
    f.set_defaults(func=cmd_envmap_from_light)
    t = esub.add_parser("to-light", help="the dominant point light of every map entry",
                        description="Write a relight.predictions/v1 file in which every map entry becomes "
                                    "the point light of its map's dominant light (brightest region "
                                    "after a 10 deg blur: centroid direction, mean colour); other "
                                    "entries are copied. Camera-frame maps take the camera tilt from "
                                    "the dataset record (--data or the file's 'dataset'), else from "
                                    "the entry's camera_tilt_deg.")
    t.add_argument("predictions", help="predictions file with envmap entries (relight.predictions/v2)")
    t.add_argument("--out", required=True, help="output predictions file (.json)")
    t.add_argument("--data", default=None, help="dataset folder (default: the file's 'dataset' field)")
    t.add_argument("--quiet", action="store_true", help="no progress bar")
    t.set_defaults(func=cmd_envmap_to_light)


def _is_envmap_folder(path: str) -> bool:
    import json
    try:
        with open(os.path.join(path, "predictions.json")) as f:
            return "envmap_width" in json.load(f)
    except (OSError, ValueError, TypeError):
        return False


def cmd_envmap_from_light(args) -> int:
    from relight.fileio import OutputError, check_folder_target, check_outputs
    from relight.verify.envmap import from_light
    out = os.path.abspath(args.out)
    if os.path.lexists(out) and not os.path.isdir(out):
        raise OutputError(f"--out {out} exists and is not a folder")
    check_outputs([out], [args.predictions, args.data], replaces_folder=True)
    check_folder_target(out)
    if os.path.isdir(out) and os.listdir(out) and not _is_envmap_folder(out):
        raise OutputError(f"--out {out} exists and is not an environment-map folder; choose another --out")
    n = from_light(args.predictions, args.data, out, width=args.width, frame=args.frame,
                   progress=not args.quiet)
    print(f"{out}: {n} maps of {args.width} x {args.width // 2} ({args.frame} frame), "
          f"predictions.json lists them")
    return 0


def cmd_envmap_to_light(args) -> int:
    from relight.fileio import check_file_target, check_outputs
    from relight.verify.envmap import to_light
    check_outputs([args.out], [args.predictions, args.data])
    check_file_target(args.out)
    n = to_light(args.predictions, args.out, data_dir=args.data, progress=not args.quiet)
    print(f"{args.out}: dominant light of {n} maps")
    return 0


def cmd_compare(args) -> int:
    from relight.verify.compare import compare_predictions
    from relight.fileio import check_folder_target, check_outputs
    from relight.verify.compare import CompareError
    from relight.verify.report import check_out, write_report
    out = os.path.abspath(args.out)
    check_outputs([out], [args.predictions, args.data], replaces_folder=True)
    check_folder_target(out)
    check_out(out)
    comparison = compare_predictions(args.predictions, data_dir=args.data, limit=args.limit,
                                     skip_bad=args.skip_bad, progress=not args.quiet,
                                     scheduler=engine.scheduler_from_args(args), map_floor=args.map_floor)
    check_outputs([out], [comparison.dataset_dir], replaces_folder=True)
    if not comparison.items:
        first = f" (first: {comparison.bad[0][0]}: {comparison.bad[0][1]})" if comparison.bad else ""
        raise CompareError(f"{args.predictions}: nothing could be compared: "
                           f"{len(comparison.bad)} bad entries{first}")
    settings = {"command": "compare", "predictions": os.path.abspath(args.predictions),
                "data": comparison.dataset_dir, "out": out, "skip_bad": bool(args.skip_bad),
                "limit": args.limit, "max_columns": args.max_columns,
                "map_floor": bool(args.map_floor),
                "argv": ["relight", "compare", args.predictions] + (["--data", args.data] if args.data else [])
                + ["--out", args.out] + (["--skip-bad"] if args.skip_bad else [])
                + (["--limit", str(args.limit)] if args.limit else [])
                + (["--map-floor"] if args.map_floor else [])}
    summary = write_report(comparison, out, settings, max_columns=args.max_columns,
                           progress=not args.quiet)
    d = summary["light_errors_deg"]
    line = f"{out}: {summary['n']} images compared"
    if summary["n"]:
        line += (f", direction error mean {d['direction']['mean']:.2f} deg "
                 f"(median {d['direction']['median']:.2f}), colour mean {d['colour']['mean']:.2f} deg")
    if summary["n_bad"]:
        line += f"; {summary['n_bad']} bad entries skipped (listed in the report)"
    print(line)
    print(f"open {os.path.join(out, 'index.html')}")
    return 0


def cmd_spheres(args) -> int:
    import json

    from relight import backend
    from relight.verify import figures
    backend.init()
    from relight.fileio import OutputError, atomic_folder, check_folder_target, check_outputs
    out = os.path.abspath(args.out)
    if os.path.lexists(out) and not os.path.isdir(out):
        raise OutputError(f"--out {out} exists and is not a folder")
    check_outputs([out], [args.predictions, args.data], replaces_folder=True)
    check_folder_target(out)
    if os.path.isdir(out) and os.listdir(out) and not _is_spheres_folder(out):
        raise OutputError(f"--out {out} exists and is not a spheres figure folder; choose another --out")
    from relight.verify.spheres import sphere_rows
    rows = sphere_rows(args.predictions, args.data, args.camera_tilt, args.res, args.spp, args.limit)

    def write(tmp):
        for page, start in enumerate(range(0, len(rows), figures.MAX_COLUMNS)):
            chunk = rows[start:start + figures.MAX_COLUMNS]
            for ext in ("png", "pdf"):
                figures.save_spheres_figure(chunk, os.path.join(tmp, f"spheres_{page:03d}.{ext}"))
        with open(os.path.join(tmp, "settings.json"), "w") as f:
            json.dump({"command": "figure spheres", "predictions": os.path.abspath(args.predictions),
                       "data": args.data, "camera_tilt_deg": args.camera_tilt, "res": args.res,
                       "spp": args.spp, "limit": args.limit,
                       "errors_deg": {r["id"]: r["errors"] for r in rows}}, f, indent=1)

    atomic_folder(out, write)
    print(f"{out}: spheres for {len(rows)} images")
    return 0


def _is_spheres_folder(path: str) -> bool:
    import json
    try:
        with open(os.path.join(path, "settings.json")) as f:
            return json.load(f).get("command") == "figure spheres"
    except (OSError, ValueError, AttributeError):
        return False


def cmd_pole(args) -> int:
    from relight import backend
    from relight.predictions import entry_for_image, read_predictions
    from relight.fileio import check_file_target, check_outputs
    from relight.imageio import ImageError, read_image, write_png
    from relight.verify.figures import pole_overlay
    check_outputs([args.out], [args.image, args.predictions])
    if not args.out.lower().endswith(".png"):
        raise ImageError(f"--out must end in .png, got {args.out!r}")
    check_file_target(args.out)
    image, _ = read_image(args.image)
    pred = entry_for_image(read_predictions(args.predictions).predictions, args.image, args.id)
    cam_tilt = args.camera_tilt if args.camera_tilt is not None else pred.camera_tilt(DEFAULT_PHOTO_CAMERA_TILT_DEG)
    pan, tilt, rgb = pred.resolve(cam_tilt)
    backend.init()
    write_png(args.out, pole_overlay(image, pan, tilt, rgb, cam_tilt))
    print(f"{args.out}: pole under light pan_rel {pan:.1f} tilt {tilt:.1f} deg "
          f"(camera tilt {cam_tilt:g} deg)", file=sys.stdout)
    return 0

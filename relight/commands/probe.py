"""``relight probe``: the paper's sphere procedure on a photograph of light probes."""
from __future__ import annotations

__all__ = [
    "add_commands", "circle", "cmd_probe",
    "check_circle_fits",
    "non_negative_px",
]

import os

from relight.commands.argtypes import camera_tilt, circle, field_of_view, positive_float

CIRCLE_TOLERANCE_PX = 0.5   # relight.probe.run.CIRCLE_TOLERANCE_PX (not imported: keeps --help fast)


def add_commands(sub) -> None:
    p = sub.add_parser("probe", help="light direction from a chrome sphere, colour from a diffuse sphere",
                       description="The paper's sphere procedure (Experiment 2): direction from the "
                                   "chrome sphere's highlight (each pixel's view ray reflected about "
                                   "the sphere's normal; perspective with --fov/--focal-px), colour "
                                   "(and a shading-based direction) from the diffuse sphere. Spheres "
                                   "are found automatically unless a circle or mask is given. Writes "
                                   "a relight.predictions/v1 file (and a QA overlay with --qa). "
                                   "With --folder and --circles, measures every image a CSV lists "
                                   "(one predictions entry each).")
    p.add_argument("--chrome", help="image with a chrome (mirror) sphere")
    p.add_argument("--chrome-circle", type=circle, help="CX,CY,R: the chrome sphere's outline in pixels "
                   "(x right, y down, origin top-left, pixel centres at +0.5); refined on the image's "
                   "edges only within --circle-tolerance. Give it only as exact as that: on 15-20 px "
                   "spheres a circle marked 0.5 px rms off gave 3.5 deg at the median, none (found "
                   "automatically) 1.6 (docs/probe-history.md, twenty-first round)")
    p.add_argument("--chrome-mask", help="mask image, white where the chrome sphere is")
    p.add_argument("--diffuse", help="image with a diffuse sphere (gives the colour); may be the chrome image")
    p.add_argument("--diffuse-circle", type=circle, help="CX,CY,R: the diffuse sphere's outline in pixels")
    p.add_argument("--diffuse-mask", help="mask image, white where the diffuse sphere is")
    p.add_argument("--circle-tolerance", type=non_negative_px, default=CIRCLE_TOLERANCE_PX, metavar="PX",
                   help="how far (pixels) a given circle's centre and radius may be moved to fit the "
                   "image's edges; the move is kept only if the outline then fits better "
                   f"(default {CIRCLE_TOLERANCE_PX}; 0: use the circle exactly as given)")
    p.add_argument("--no-locator", dest="locator", action="store_false",
                   help="automatic detection by the hand-written rules alone, without the learned "
                   "sphere locator (its proposed circle, and its prior on which circle is the chrome sphere)")
    p.add_argument("--folder", help="batch: a folder of photographs, measured as listed by --circles")
    p.add_argument("--circles", help="batch: CSV with a header row: image (file in --folder), optional "
                   "chrome_cx,chrome_cy,chrome_r (empty: found automatically), diffuse_cx,diffuse_cy,"
                   "diffuse_r (a diffuse sphere in the same image), id")
    p.add_argument("--fixed-probe", action="store_true",
                   help="batch: the chrome sphere stands still in every image (one camera, one probe, many "
                   "lights): it is found in every row without a chrome circle, and the circle most of those "
                   "detections agree on is given to each of them")
    proj = p.add_mutually_exclusive_group()
    proj.add_argument("--fov", type=field_of_view, help="perspective camera: horizontal field of view "
                      "(across the image width) in degrees")
    proj.add_argument("--focal-px", type=positive_float, help="perspective camera: focal length in pixels")
    proj.add_argument("--orthographic", action="store_true",
                      help="a far camera: parallel view rays (the default when no --fov/--focal-px)")
    p.add_argument("--camera-tilt", type=camera_tilt, default=None,
                   help="camera tilt in degrees used to express the direction as pan/tilt (default 0)")
    p.add_argument("--linear", action="store_true",
                   help="PNG/TIFF pixels are linear (e.g. 16-bit measurement data); default: sRGB")
    p.add_argument("--id", default=None, help="prediction id (default: the image's file name)")
    p.add_argument("--out", required=True, help="predictions file to write")
    p.add_argument("--qa", default=None, help="write a QA overlay PNG (outline, highlight, normal, direction, "
                   "error budget); with --folder, a folder of them (one per image)")
    p.set_defaults(func=cmd_probe)


def check_circle_fits(option: str, circle, image: str) -> None:
    """Refuse (one line) a circle that cannot be a sphere's outline in ``image``: a radius
    over half the image diagonal (a circle that large shows no outline), or a circle that
    misses the image; checked before the probe allocates anything of the circle's size."""
    import math

    from relight.errors import ProbeError
    from relight.imageio import load_image
    if circle is None or image is None:
        return
    height, width = load_image(image)[0].shape[:2]
    cx, cy, r = circle
    half_diagonal = math.hypot(width, height) / 2
    if r > half_diagonal:
        raise ProbeError(f"{option} {cx:g},{cy:g},{r:g}: radius larger than half the diagonal of {image} "
                         f"({width}x{height} px: at most {half_diagonal:.1f})")
    dx = max(0.0, -cx, cx - width)
    dy = max(0.0, -cy, cy - height)
    if math.hypot(dx, dy) >= r:
        raise ProbeError(f"{option} {cx:g},{cy:g},{r:g}: the circle misses {image} ({width}x{height} px)")


def non_negative_px(text: str) -> float:
    """A finite number of pixels >= 0."""
    import argparse
    import math
    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not math.isfinite(v) or v < 0:
        raise argparse.ArgumentTypeError(f"expected a number of pixels >= 0, got {text!r}")
    return v


def cmd_probe(args) -> int:
    from relight.errors import ProbeError
    from relight.fileio import check_file_target, check_outputs
    from relight.predictions import write_predictions
    from relight.probe.run import ProbeConfig, run_probe, write_qa
    if args.folder or args.circles:
        return _cmd_batch(args)
    if args.fixed_probe:
        raise ProbeError("--fixed-probe is for a batch (--folder DIR --circles CSV)")
    inputs = [args.chrome, args.chrome_mask, args.diffuse, args.diffuse_mask]
    check_file_target(args.out)   # a folder given for a file: said as such, before the input rule
    if args.qa:
        check_file_target(args.qa)
    check_outputs([args.out, args.qa], inputs)
    check_circle_fits("--chrome-circle", args.chrome_circle, args.chrome)
    check_circle_fits("--diffuse-circle", args.diffuse_circle, args.diffuse)
    cfg = ProbeConfig(chrome=args.chrome, chrome_circle=args.chrome_circle, chrome_mask=args.chrome_mask,
                      diffuse=args.diffuse, diffuse_circle=args.diffuse_circle, diffuse_mask=args.diffuse_mask,
                      fov_deg=args.fov, focal_px=args.focal_px, camera_tilt_deg=args.camera_tilt,
                      linear=args.linear, circle_tolerance_px=args.circle_tolerance, locator=args.locator)
    result = run_probe(cfg)
    ident = args.id or os.path.splitext(os.path.basename(args.chrome or args.diffuse))[0]
    entry = {"id": ident, **result.entry}
    meta = {"camera_tilt_deg": args.camera_tilt if args.camera_tilt is not None else 0.0,
            "settings": {k: v for k, v in vars(args).items() if k != "func"}}
    if args.camera_tilt is None:
        meta["camera_tilt_note"] = "no --camera-tilt given: pan_deg/tilt_deg assume a level camera (tilt 0)"
    if args.qa:
        write_qa(args.qa, result, title=ident)
    write_predictions(args.out, [entry], **meta)
    rgb, d = entry["rgb"], entry["to_light_camera"]
    quality = f", ~{entry['quality_deg']:.1f} deg" if "quality_deg" in entry else ""
    print(f"{ident}: to_light_camera ({d[0]:+.3f}, {d[1]:+.3f}, {d[2]:+.3f}), pan_rel {entry['pan_deg']:.1f} deg, "
          f"tilt {entry['tilt_deg']:.1f} deg, rgb ({rgb[0]:.3f}, {rgb[1]:.3f}, {rgb[2]:.3f}) "
          f"[{entry['method']}{quality}] -> {args.out}")
    if "diffuse_skipped" in entry:
        print(f"note: the diffuse sphere was not measured ({entry['diffuse_skipped']}): the direction is the "
              f"chrome sphere's alone and the colour white")
    if "detection" in entry:
        det = entry["detection"]
        cx, cy, r = det["alternative_circle"]
        print(f"note: another circle, ({cx:.1f}, {cy:.1f}) r {r:.1f}, looks nearly as much like the chrome sphere "
              f"(ambiguity {det['ambiguity']:.2f}; its light is {det['separation_deg']:.0f} deg away): "
              f"check the QA overlay or give --chrome-circle")
    return 0


def _cmd_batch(args) -> int:
    """``relight probe --folder DIR --circles CSV --out FILE [--qa FOLDER]``."""
    from relight.errors import ProbeError
    from relight.fileio import check_file_target, check_folder_target, check_outputs
    from relight.predictions import write_predictions
    from relight.probe.batch import read_circles, run_batch
    from relight.probe.run import ProbeConfig
    if not (args.folder and args.circles):
        raise ProbeError("batch mode needs both --folder DIR and --circles CSV")
    single = [n for n in ("chrome", "chrome_circle", "chrome_mask", "diffuse", "diffuse_circle", "diffuse_mask", "id")
              if getattr(args, n) is not None]
    if single:
        raise ProbeError(f"--{single[0].replace('_', '-')} is for one image; with --folder the CSV gives the circles")
    check_outputs([args.out], [args.circles, args.folder])
    check_file_target(args.out)
    if args.qa:     # replaced as a whole: it must hold no input (nor the predictions file)
        check_outputs([args.qa], [args.circles, args.folder, args.out], replaces_folder=True)
        check_folder_target(args.qa)
    rows = read_circles(args.circles, args.folder)
    base = ProbeConfig(chrome=rows[0].path, fov_deg=args.fov, focal_px=args.focal_px,
                       camera_tilt_deg=args.camera_tilt, linear=args.linear,
                       circle_tolerance_px=args.circle_tolerance, locator=args.locator)
    entries = run_batch(rows, base, args.qa, fixed_probe=args.fixed_probe)
    meta = {"camera_tilt_deg": args.camera_tilt if args.camera_tilt is not None else 0.0,
            "settings": {k: v for k, v in vars(args).items() if k != "func"}}
    if args.camera_tilt is None:
        meta["camera_tilt_note"] = "no --camera-tilt given: pan_deg/tilt_deg assume a level camera (tilt 0)"
    write_predictions(args.out, entries, **meta)
    for e in entries:
        d = e["to_light_camera"]
        print(f"{e['id']}: to_light_camera ({d[0]:+.3f}, {d[1]:+.3f}, {d[2]:+.3f}) "
              f"[{e['method']}, ~{e.get('quality_deg', float('nan')):.1f} deg]"
              + (f" (diffuse sphere not measured: {e['diffuse_skipped']})" if "diffuse_skipped" in e else ""))
    print(f"{len(entries)} images -> {args.out}" + (f" (QA overlays in {args.qa})" if args.qa else ""))
    return 0

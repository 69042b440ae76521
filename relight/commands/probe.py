"""``relight probe``: the paper's sphere procedure on a photograph of light probes."""
from __future__ import annotations

__all__ = [
    "add_commands", "circle", "cmd_probe",
    "check_circle_fits",
]

import os

from relight.commands.argtypes import camera_tilt, circle, field_of_view, positive_float


def add_commands(sub) -> None:
    p = sub.add_parser("probe", help="light direction from a chrome sphere, colour from a diffuse sphere",
                       description="The paper's sphere procedure (Experiment 2): direction from the "
                                   "chrome sphere's highlight (each pixel's view ray reflected about "
                                   "the sphere's normal; perspective with --fov/--focal-px), colour "
                                   "(and a shading-based direction) from the diffuse sphere. Spheres "
                                   "are found automatically unless a circle or mask is given. Writes "
                                   "a relight.predictions/v1 file (and a QA overlay with --qa).")
    p.add_argument("--chrome", help="image with a chrome (mirror) sphere")
    p.add_argument("--chrome-circle", type=circle, help="CX,CY,R: the chrome sphere's outline in pixels "
                   "(x right, y down, origin top-left, pixel centres at +0.5); refined on the image")
    p.add_argument("--chrome-mask", help="mask image, white where the chrome sphere is")
    p.add_argument("--diffuse", help="image with a diffuse sphere (gives the colour); may be the chrome image")
    p.add_argument("--diffuse-circle", type=circle, help="CX,CY,R: the diffuse sphere's outline in pixels")
    p.add_argument("--diffuse-mask", help="mask image, white where the diffuse sphere is")
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
    p.add_argument("--qa", default=None, help="write a QA overlay PNG (outline, highlight, normal, direction)")
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


def cmd_probe(args) -> int:
    from relight.fileio import check_file_target, check_outputs
    from relight.predictions import write_predictions
    from relight.probe.run import ProbeConfig, run_probe, write_qa
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
                      linear=args.linear)
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
    return 0

"""``relight probe``: the paper's sphere procedure on a photograph of light probes."""
from __future__ import annotations

import os

import numpy as np


def add_commands(sub) -> None:
    p = sub.add_parser("probe", help="light direction from a chrome sphere, colour from a diffuse sphere",
                       description="The paper's sphere procedure (Experiment 2): direction from the "
                                   "chrome sphere's highlight (mirror reflection), colour (and a "
                                   "shading-based direction) from the diffuse sphere. Writes a "
                                   "relight.predictions/v1 file.")
    p.add_argument("--chrome", help="image with a chrome (mirror) sphere")
    p.add_argument("--chrome-mask", help="mask image, white where the chrome sphere is")
    p.add_argument("--diffuse", help="image with a diffuse sphere (gives the colour)")
    p.add_argument("--diffuse-mask", help="mask image, white where the diffuse sphere is")
    p.add_argument("--camera-tilt", type=float, default=0.0,
                   help="camera tilt in degrees used to express the direction as pan/tilt (default 0)")
    p.add_argument("--id", default=None, help="prediction id (default: the image's file name)")
    p.add_argument("--out", required=True, help="predictions file to write")
    p.set_defaults(func=cmd_probe)


def _mask(path: str) -> np.ndarray:
    from relight.render import read_image
    image, _ = read_image(path)
    return image.mean(-1) > 0.5


def cmd_probe(args) -> int:
    from relight import probes
    from relight.predictions import write_predictions
    from relight.render import read_image
    if not args.chrome and not args.diffuse:
        raise probes.ProbeError("give --chrome (direction) and/or --diffuse (colour)")
    direction, rgb, method = None, np.ones(3) / np.sqrt(3), []
    if args.diffuse:
        if not args.diffuse_mask:
            raise probes.ProbeError("--diffuse needs --diffuse-mask")
        direction, rgb = probes.diffuse_light(read_image(args.diffuse)[0], _mask(args.diffuse_mask))
        method.append("diffuse")
    if args.chrome:
        if not args.chrome_mask:
            raise probes.ProbeError("--chrome needs --chrome-mask")
        direction = probes.chrome_light_direction(read_image(args.chrome)[0], _mask(args.chrome_mask))
        method.append("chrome")
    pan, tilt = probes.camera_to_pan_tilt(direction, args.camera_tilt)
    ident = args.id or os.path.splitext(os.path.basename(args.chrome or args.diffuse))[0]
    entry = {"id": ident, "pan_deg": pan, "tilt_deg": tilt, "rgb": [float(c) for c in rgb],
             "to_light_camera": [float(c) for c in direction], "method": "+".join(method)}
    write_predictions(args.out, [entry], camera_tilt_deg=args.camera_tilt)
    print(f"{ident}: pan_rel {pan:.1f} deg, tilt {tilt:.1f} deg, rgb "
          f"({rgb[0]:.3f}, {rgb[1]:.3f}, {rgb[2]:.3f}) [{'+'.join(method)}] -> {args.out}")
    return 0

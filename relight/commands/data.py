"""``relight generate`` and ``relight render``."""
from __future__ import annotations

__all__ = [
    "add_commands", "cmd_generate_mid", "cmd_generate", "cmd_render",
]

import os
import sys

from relight import engine
from relight.commands import argtypes as at
from relight.scene.albedo import PRIORS
from relight.scene.spec import SAMPLERS
from relight.scene.textures import BACKGROUNDS


def add_commands(sub) -> None:
    g = sub.add_parser("generate", help="render a SID2-style synthetic dataset (resumable)",
                       description="Render COUNT images of random scenes like the paper's SID2 "
                                   "into OUT. Re-running the same command resumes.")
    g.add_argument("--count", type=at.count, default=16, help="total number of images (default 16)")
    g.add_argument("--out", required=True, help="dataset folder")
    g.add_argument("--seed", type=at.seed, default=0, help="dataset seed (default 0)")
    g.add_argument("--res", type=at.resolution, default=None, help="image size in pixels (default 128)")
    g.add_argument("--spp", type=at.spp, default=None,
                   help="samples per pixel (default: the fewest that reach --target-rmse)")
    g.add_argument("--target-rmse", type=at.relative_rmse, default=None,
                   help="target relative RMSE of each render against a converged one "
                        "(default 0.02: 16 spp with multijitter); ignored with --spp")
    g.add_argument("--sampler", choices=SAMPLERS, default=None,
                   help="Mitsuba sampler (default multijitter)")
    g.add_argument("--colour-prior", choices=PRIORS, default=None,
                   help="surface-colour prior of textures and objects (default hsv; see README)")
    g.add_argument("--backgrounds", choices=BACKGROUNDS, default=None,
                   help="wall and floor textures: patterns (default; 2-5 colours each), mosaic "
                        "(grids of 4-16 x 4-16 independently coloured cells: many surfaces in "
                        "view), library (one of a closed set of 250 backgrounds per scene, shared by "
                        "every set; --preset sid2-paper's default) or unseen (drawn like the "
                        "library's, sharing none of its colours); see docs/table1.md")
    g.add_argument("--object-parts", type=at.object_parts, default=None, metavar="N|LO-HI",
                   help="independently coloured parts per object, N or a range drawn per object "
                        "(the paper colours each mesh part; default 1-32; see README)")
    g.add_argument("--max-depth", type=at.max_depth, default=None, help="path depth (default 4)")
    engine.add_arguments(g, "the renders", workers=True)   # --workers N, --scheduler
    g.add_argument("--config", default=None, help="JSON file of generator settings")
    g.add_argument("--mesh-dir", default=None, help="folder of your own .obj/.ply meshes (z up), or \"builtin\": the shipped scans and models (relight/assets/meshes)")
    g.add_argument("--preset", choices=["sid2", "sid2-paper", "photo", "mid"], default="sid2",
                   help="sid2 (default): the paper's SID2-style images; sid2-paper: the same rooms with "
                        "the paper group's colour protocol (light colour a temperature of 2000-9900 K in "
                        "100 K steps, Tanner-Helland RGB; one of 250 library backgrounds, or --backgrounds "
                        "unseen; pastel part colours, 1-11 parts per object; explicit options and --config "
                        "win over it; see docs/table1.md); photo: the photo-training mix (level to steep "
                        "cameras, 20-90 deg fields of view, low lights, half the scenes on a black void; "
                        "docs/photo.md); mid: a MID-like set (indoor rooms, "
                        "chrome + gray sphere, a flash above the camera turned to 25 directions; --count is "
                        "the number of rooms, 25 images each; --config takes its settings; see README)")
    g.add_argument("--quiet", action="store_true", help="no progress bar")
    g.set_defaults(func=cmd_generate)

    r = sub.add_parser("render", help="re-render one scene file, optionally under another light",
                       description="Render SCENE (a relight.scene/v1 file) to OUT (.png or .exr); "
                                   "repeat --out to write several files from one render.")
    r.add_argument("scene", help="scene file (JSON)")
    r.add_argument("--out", required=True, action="append",
                   help="output image (.png 8-bit sRGB or .exr linear); repeatable (e.g. --out a.exr --out a.png)")
    r.add_argument("--light-pan", type=at.light_pan, default=None,
                   help="light pan relative to the camera, degrees (0 front, 90 right)")
    r.add_argument("--light-tilt", type=at.light_tilt, default=None, help="light tilt (elevation), degrees")
    r.add_argument("--rgb", type=at.bounded_rgb, default=None, help="light colour R,G,B (linear; normalised)")
    r.add_argument("--spp", type=at.spp, default=None, help="override samples per pixel")
    r.set_defaults(func=cmd_render)


def cmd_generate_mid(args) -> int:
    from relight.fileio import check_outputs
    from relight.experiments.mid.dataset import generate_mid, mid_config
    cfg = mid_config(args.config, res=args.res, spp=args.spp, max_depth=args.max_depth,
                     refused={"--workers": args.workers != 1, "--scheduler": args.scheduler,
                              "--sampler": args.sampler, "--colour-prior": args.colour_prior,
                              "--object-parts": args.object_parts, "--backgrounds": args.backgrounds,
                              "--mesh-dir": args.mesh_dir, "--target-rmse": args.target_rmse})
    check_outputs([args.out], [args.config])
    stats = generate_mid(args.out, args.count, seed=args.seed, cfg=cfg, progress=not args.quiet,
                         threads=args.threads)
    print(f"{args.out}: {stats.scenes_written} rooms written ({stats.images} images, "
          f"{stats.failed_probe} without a procedure ground truth), {stats.scenes_skipped} already there")
    print(f"images: {os.path.join(args.out, 'images')}  masked: {os.path.join(args.out, 'masked')}  "
          f"manifest: {os.path.join(args.out, 'manifest.jsonl')}")
    return 0


def cmd_generate(args) -> int:
    if args.preset == "mid":
        return cmd_generate_mid(args)
    from relight.generator.run import generate
    from relight.fileio import check_outputs
    from relight.generator.sampling import BUILTIN_MESHES, GeneratorConfig
    mesh_dir = args.mesh_dir if args.mesh_dir in (None, BUILTIN_MESHES) else os.path.abspath(args.mesh_dir)
    overrides = dict(res=args.res, spp=args.spp, max_depth=args.max_depth, sampler=args.sampler,
                     target_rmse=args.target_rmse, colour_prior=args.colour_prior, backgrounds=args.backgrounds,
                     object_parts=args.object_parts, mesh_dir=mesh_dir)
    cfg = GeneratorConfig.from_file(args.config, preset=args.preset, **overrides)
    check_outputs([args.out], [args.config, args.mesh_dir])
    scheduler = engine.scheduler_from_args(args)   # --scheduler, or --workers N as local:N
    stats = generate(args.out, args.count, seed=args.seed, cfg=cfg, progress=not args.quiet,
                     threads=args.threads, scheduler=scheduler)
    msg = f"{args.out}: {stats.written} images written, {stats.skipped} already there"
    if stats.written:
        msg += f" ({stats.images_per_s:.2f} img/s, total/render time {stats.overhead_ratio:.2f})"
    print(msg)
    print(f"images: {os.path.join(args.out, 'images')}  manifest: {os.path.join(args.out, 'manifest.jsonl')}")
    return 0


def cmd_render(args) -> int:
    import dataclasses

    from relight.fileio import check_file_target, check_outputs
    from relight.imageio import ImageError, write_exr, write_png
    from relight.scene.build import render_spec
    from relight.scene.spec import load_scene
    outs = list(args.out)
    for out in outs:
        if os.path.splitext(out)[1].lower() not in (".png", ".exr"):
            raise ImageError(f"--out must end in .png or .exr, got {out!r}")
        check_file_target(out)
    if len({os.path.realpath(out) for out in outs}) < len(outs):
        raise ImageError("--out names the same file twice")
    check_outputs(outs, [args.scene])
    spec = load_scene(args.scene)
    spec = spec.with_light(args.light_pan, args.light_tilt, args.rgb)
    if args.spp:
        spec = dataclasses.replace(spec, render=dataclasses.replace(spec.render, spp=args.spp))
    image = render_spec(spec)
    for out in outs:
        (write_exr if out.lower().endswith(".exr") else write_png)(out, image, inputs=[args.scene])
    print(f"{', '.join(outs)}: {spec.render.res}x{spec.render.res}, light pan_rel {spec.pan_rel_deg:.1f} "
          f"tilt {spec.light.tilt_deg:.1f} deg", file=sys.stdout)
    return 0

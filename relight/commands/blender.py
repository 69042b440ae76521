"""``relight export-blender``: the same scene file in Blender Cycles (the paper's renderer)."""
from __future__ import annotations

__all__ = [
    "add_commands", "cmd_export_blender",
]

import importlib.util
import os

from relight.commands import argtypes as at


def add_commands(sub) -> None:
    e = sub.add_parser("export-blender", help="build a scene file in Blender Cycles (.blend), optionally render it",
                       description="Build SCENE (a relight.scene/v1 file) in Blender Cycles as Mitsuba "
                                   "renders it (geometry, textures, Oren-Nayar roughness, camera, point "
                                   "light in the same units, same path depth) and save OUT (.blend). "
                                   "Needs bpy: in this environment, or in the one scripts/setup_blender.sh "
                                   "makes (or $RELIGHT_BLENDER_PYTHON). Opening the .blend in Blender "
                                   "keeps Sobol-Burley sampling only with Developer Extras and Cycles "
                                   "debug enabled in the preferences.")
    e.add_argument("scene", help="scene file (JSON)")
    e.add_argument("--out", required=True, help="Blender file to write (.blend)")
    e.add_argument("--render", default=None, help="also render with Cycles to this linear .exr")
    e.add_argument("--spp", type=at.spp, default=None, help="samples per pixel (default: the scene's)")
    e.set_defaults(func=cmd_export_blender)


def cmd_export_blender(args) -> int:
    from relight.scene.blender import BlenderError, blender_python, run_blender_module
    from relight.errors import OutputError
    from relight.scene.spec import load_scene
    if not args.out.lower().endswith(".blend"):
        raise OutputError(f"--out must name a .blend file, got {args.out}")
    if args.render is not None and not args.render.lower().endswith(".exr"):
        raise OutputError(f"--render must name an .exr file (linear radiance), got {args.render}")
    spec = load_scene(args.scene)  # bad scene files fail here, before any Blender start
    threads = int(os.environ["RELIGHT_THREADS"]) if os.environ.get("RELIGHT_THREADS") else None
    if importlib.util.find_spec("bpy") is not None:
        from relight.scene.blender import export_and_render
        return export_and_render(spec, args.out, render_path=args.render, spp=args.spp, threads=threads)
    if blender_python() is None:
        from relight.scene.blender import INSTALL_HINT
        raise BlenderError(INSTALL_HINT)
    cmd = ["export", os.path.abspath(args.scene), "--out", os.path.abspath(args.out)]
    if args.render is not None:
        cmd += ["--render", os.path.abspath(args.render)]
    if args.spp is not None:
        cmd += ["--spp", str(args.spp)]
    if threads is not None:
        cmd += ["--threads", str(threads)]
    return run_blender_module(cmd).returncode

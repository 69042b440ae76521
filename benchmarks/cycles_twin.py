"""Render a relight dataset's scene files again with Blender Cycles: a twin dataset.

The twin has the same ids, records, scene files (and object masks) and splits as the source dataset; only
its images (``images/ID.png``, ``exr/ID.exr``) come from Cycles (``relight export-blender``'s
scene translation, :class:`relight.scene.blender.CyclesWorker`). It is the "other renderer" test
of ``benchmarks/bench_photos.py``: the same scenes seen through another renderer.

Usage (resumable: re-run the same command; ids already in the twin's manifest are kept)::

    .venv/bin/relight generate --count 320 --seed 71 --out ~/relight-data/photo/devset-mitsuba
    .venv/bin/python benchmarks/cycles_twin.py ~/relight-data/photo/devset-mitsuba \
        --out ~/relight-data/photo/devset-cycles --spp 64

``--view-transform AgX SRC_TWIN`` makes a second twin whose PNGs go through Blender's own
colour management instead (the view transform a Blender user gets by default, AgX since
Blender 4.0, sRGB display, 8-bit PNG via ``Image.save_render``); its EXRs are the source
twin's, so no scene is rendered again::

    .venv/bin/python benchmarks/cycles_twin.py ~/relight-data/photo/devset-cycles \
        --out ~/relight-data/photo/devset-cycles-agx --view-transform AgX

Needs the Blender environment (``bash scripts/setup_blender.sh``); without it, one line and
exit 2.
"""
from __future__ import annotations

import json
import os
import shutil
import sys

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

DEFAULT_SPP = 64   # Cycles at 64 spp: relative RMSE about 2% at 128 px, the dataset's noise target


def _copy_geometry(src: str, out: str, rec: dict) -> None:
    """The record's files no renderer changes: its scene file and, where it names one, its
    object mask (the objects' coverage depends on the geometry and the camera alone)."""
    for key in ("scene", "mask"):
        if isinstance(rec.get(key), str):
            os.makedirs(os.path.dirname(os.path.join(out, rec[key])), exist_ok=True)
            shutil.copyfile(os.path.join(src, rec[key]), os.path.join(out, rec[key]))


def cycles_twin(src: str, out: str, spp: int = DEFAULT_SPP, limit: int | None = None,
                progress: bool = True) -> int:
    """Render every record of dataset ``src`` (first ``limit``) with Cycles into ``out``.
    Returns the number of images rendered now."""
    from tqdm import tqdm

    from relight.scene import blender
    from relight.dataset import MANIFEST, load_spec, read_manifest
    from relight.fileio import check_outputs, write_json
    from relight.imageio import write_exr, write_png

    records = read_manifest(src)[:limit]
    check_outputs([out], [src], replaces_folder=True)
    os.makedirs(os.path.join(out, "images"), exist_ok=True)
    os.makedirs(os.path.join(out, "exr"), exist_ok=True)
    os.makedirs(os.path.join(out, "scenes"), exist_ok=True)
    done = {r["id"] for r in read_manifest(out)} if os.path.exists(os.path.join(out, MANIFEST)) else set()
    card_src = os.path.join(src, "dataset.json")
    if not os.path.exists(os.path.join(out, "dataset.json")):
        card = json.load(open(card_src)) if os.path.exists(card_src) else {}
        card["renderer"] = {"name": "cycles", "spp": spp, "twin_of": os.path.abspath(src)}
        write_json(os.path.join(out, "dataset.json"), card)
    todo = [r for r in records if r["id"] not in done]
    n = 0
    with blender.CyclesWorker(threads=None) as worker:
        for rec in tqdm(todo, desc="cycles twin", disable=not progress):
            spec = load_spec(src, rec)
            image, _seconds = worker.render(spec, spp, spec.render.seed)
            _copy_geometry(src, out, rec)
            write_exr(os.path.join(out, rec["exr"]), image)
            write_png(os.path.join(out, rec["image"]), image)
            with open(os.path.join(out, MANIFEST), "a") as f:   # after the files are complete
                f.write(json.dumps(rec) + "\n")
            n += 1
    return n


VIEW_SCRIPT = """
import bpy, json, sys
jobs = json.load(open(sys.argv[-1]))
scene = bpy.context.scene
scene.view_settings.view_transform = jobs["view"]
scene.view_settings.look = "None"
scene.display_settings.display_device = "sRGB"
scene.render.image_settings.file_format = "PNG"
scene.render.image_settings.color_depth = "8"
for src, dst in jobs["pairs"]:
    img = bpy.data.images.load(src)
    img.save_render(dst, scene=scene)
    bpy.data.images.remove(img)
"""


def view_transform_twin(src: str, out: str, view: str = "AgX", progress: bool = True) -> int:
    """A twin of dataset ``src`` whose PNGs are its EXRs through Blender's view transform
    ``view`` (sRGB display, 8-bit); records, scenes and EXRs are copied. Returns the count."""
    import subprocess
    import tempfile

    from relight.scene import blender
    from relight.dataset import MANIFEST, read_manifest
    from relight.errors import BlenderError
    from relight.fileio import check_outputs, write_json
    python = blender.blender_python()
    if python is None:
        raise BlenderError(blender.INSTALL_HINT)
    records = read_manifest(src)
    check_outputs([out], [src], replaces_folder=True)
    for sub in ("images", "exr", "scenes"):
        os.makedirs(os.path.join(out, sub), exist_ok=True)
    done = {r["id"] for r in read_manifest(out)} if os.path.exists(os.path.join(out, MANIFEST)) else set()
    todo = [r for r in records if r["id"] not in done]
    if not os.path.exists(os.path.join(out, "dataset.json")):
        card = json.load(open(os.path.join(src, "dataset.json"))) if os.path.exists(os.path.join(src, "dataset.json")) else {}
        card["view_transform"] = {"blender": view, "display": "sRGB", "twin_of": os.path.abspath(src)}
        write_json(os.path.join(out, "dataset.json"), card)
    with tempfile.TemporaryDirectory(prefix="relight-view-") as tmp:
        pairs = [(os.path.abspath(os.path.join(src, r["exr"])), os.path.join(tmp, f"{r['id']}.png")) for r in todo]
        with open(os.path.join(tmp, "jobs.json"), "w") as f:
            json.dump({"view": view, "pairs": pairs}, f)
        with open(os.path.join(tmp, "view.py"), "w") as f:
            f.write(VIEW_SCRIPT)
        run = subprocess.run([python, os.path.join(tmp, "view.py"), os.path.join(tmp, "jobs.json")],
                             capture_output=True, text=True)
        if run.returncode != 0:
            raise BlenderError(f"Blender's view transform failed: {(run.stderr or run.stdout).strip().splitlines()[-1:]}")
        for r, (_, png) in zip(todo, pairs):
            _copy_geometry(src, out, r)
            shutil.copyfile(os.path.join(src, r["exr"]), os.path.join(out, r["exr"]))
            shutil.move(png, os.path.join(out, r["image"]))
            with open(os.path.join(out, MANIFEST), "a") as f:
                f.write(json.dumps(r) + "\n")
    return len(todo)


def main(argv=None) -> int:
    from relight.commands import argtypes as at
    ap = at.OneLineParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("src", help="source dataset folder (relight generate output)")
    ap.add_argument("--out", required=True, help="twin dataset folder to write (resumable)")
    ap.add_argument("--spp", type=at.spp, default=DEFAULT_SPP, help=f"Cycles samples per pixel (default {DEFAULT_SPP})")
    ap.add_argument("--limit", type=at.int_in(1, 1_000_000, "a count"), default=None, help="only the first N records")
    ap.add_argument("--view-transform", default=None, metavar="VIEW",
                    help="instead of rendering: copy the twin SRC with its PNGs made by Blender's view "
                         "transform VIEW (e.g. AgX, Filmic, Standard) from its EXRs")
    args = ap.parse_args(argv)
    from relight.errors import RelightError
    try:
        if args.view_transform:
            n = view_transform_twin(args.src, args.out, args.view_transform)
            print(f"{args.out}: {n} images through Blender's {args.view_transform} view transform")
            return 0
        n = cycles_twin(args.src, args.out, args.spp, args.limit)
    except RelightError as exc:
        sys.stderr.write(f"cycles_twin: error: {str(exc).splitlines()[0]}\n")
        return 2
    print(f"{args.out}: {n} images rendered by Cycles")
    return 0


if __name__ == "__main__":
    from relight.commands import argtypes
    sys.exit(argtypes.run_script(main))

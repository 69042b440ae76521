"""Real photographs and another renderer: the network where it was not trained.

Scores one or more models (default: every shipped model, ``photo`` and ``sid2``, each
labelled by its name) on
* ``shared/data/psm_objects``: 60 real photographs of 5 objects under 12 known lights;
* ``shared/data/psm_spheres``: the gray (diffuse) and chrome ball photographs of the same
  12 lights (the network, beside the constant guess; the sphere procedure's own figures are
  ``benchmarks/bench_probe.py``'s);
* a Cycles dev set: default rooms rendered by Blender Cycles from relight scene files
  (``benchmarks/cycles_twin.py``), beside the same scenes rendered by Mitsuba, its PNGs made
  two ways: relight's sRGB encoding of the linear render, and Blender's default view
  transform (AgX), what a Blender user's PNG looks like;
all in the camera frame (``relight.net.photos``), with each model's own camera tilt where
it has a camera head. Also printed: the constant "light at the camera" guess, the
reference any estimator must beat on psm (its lights are all within 40 degrees of the view).

Usage::

    .venv/bin/python benchmarks/bench_photos.py [--model M ...] [--devset DIR] [--n 320]

``--devset DIR`` (default ``~/relight-data/photo``) holds ``devset-mitsuba`` and
``devset-cycles``; missing ones are made when Blender is set up (``scripts/setup_blender.sh``:
320 scenes, seed 71, 128 px; about 15 minutes on 2 cores), else skipped with one line.
Sets whose data are absent are skipped with one line.
"""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)
DEVSET_SEED = 71


def _row(label: str, s: dict, keys=("direction_deg",)) -> str:
    parts = [f"{label:<44}", f"{s['n']:>4}"]
    for k in keys:
        parts.append(f"{s.get(k + '_median', float('nan')):7.2f} {s.get(k + '_mean', float('nan')):7.2f}")
    cov = s.get("cone90_coverage", float("nan"))
    parts.append("     -" if cov != cov else f"{100 * cov:5.1f}%")
    parts.append(f"{100 * s.get('ood_share', 0.0):5.1f}%")
    if "follow_x_r" in s:
        parts.append(f"{s['follow_x_r']:5.2f} {s['follow_y_r']:5.2f}")
        parts.append(f"{s['image_angle_deg_median']:7.1f}  {s['slant_error_deg_median']:6.1f} {s['slant_bias_deg']:+6.1f}")
    if "slope_x" in s:
        parts.append(f"{s['slope_x']:5.2f} {s['slope_y']:5.2f}  {s['bias_x']:+5.2f} {s['bias_y']:+5.2f}"
                     f"  {s['bias_free_median_deg']:7.1f}")
    return "  ".join(parts)


def _label(model_path: str) -> str:
    """A model's name in the tables: its file name, or its run folder's for a run's
    best/last weights (several runs' ``best.safetensors`` side by side)."""
    path = str(model_path).rstrip(os.sep)
    base = os.path.basename(path)
    if base in ("best.safetensors", "last.safetensors"):
        return f"{os.path.basename(os.path.dirname(os.path.abspath(path)))}/{base}"
    return base


def _constant_guess(truth: np.ndarray) -> dict:
    from relight import metrics
    err = metrics.angle_deg(np.array([0.0, 0.0, 1.0]), truth)
    return {"n": len(err), "direction_deg_median": float(np.median(err)), "direction_deg_mean": float(np.mean(err)),
            "cone90_coverage": float("nan"), "ood_share": 0.0}


def _has_masks(folder: str) -> bool:
    """Whether a dataset's records name object masks (generated with ``object_masks``)."""
    from relight.dataset import read_manifest
    records = read_manifest(folder)
    return bool(records) and all(isinstance(r.get("mask"), str) for r in records)


def _count(folder: str) -> int:
    """Records in a dataset folder's manifest (0 where there is none yet)."""
    path = os.path.join(folder, "manifest.jsonl")
    if not os.path.exists(path):
        return 0
    with open(path) as f:
        return sum(1 for line in f if line.strip())


def ensure_devset(root: str, n: int) -> tuple[str | None, str | None, str | None]:
    """The Mitsuba dev set, its Cycles twin and the Cycles twin through Blender's default AgX
    view transform, under ``root`` (made when missing and possible)."""
    from relight.scene.blender import blender_python
    mitsuba, cycles = os.path.join(root, "devset-mitsuba"), os.path.join(root, "devset-cycles")
    relight_cli = [sys.executable, "-m", "relight"]
    if _count(mitsuba) < n:
        print(f"making {mitsuba}: relight generate --count {n} --seed {DEVSET_SEED} (default rooms, 128 px)")
        subprocess.run(relight_cli + ["generate", "--count", str(n), "--seed", str(DEVSET_SEED), "--out", mitsuba,
                                      "--quiet"], check=True)
    if blender_python() is None:
        print("Cycles dev set: skipped (no Blender environment; run scripts/setup_blender.sh)")
        return mitsuba, None, None
    if _count(cycles) < n:
        print(f"making {cycles}: benchmarks/cycles_twin.py {mitsuba} --limit {n} (resumable)")
        subprocess.run([sys.executable, os.path.join(REPO, "benchmarks", "cycles_twin.py"), mitsuba,
                        "--out", cycles, "--limit", str(n)], check=True)
    agx = os.path.join(root, "devset-cycles-agx")
    if _count(agx) < n:
        print(f"making {agx}: benchmarks/cycles_twin.py {cycles} --view-transform AgX")
        subprocess.run([sys.executable, os.path.join(REPO, "benchmarks", "cycles_twin.py"), cycles,
                        "--out", agx, "--view-transform", "AgX"], check=True)
    return mitsuba, cycles, agx


def _camera_response(spheres: str) -> str:
    """One line: the psm camera's response curve, read off the gray ball of known lights
    (:func:`relight.net.photos.response_gamma`)."""
    from relight.errors import RelightError
    from relight.imageio import load_image
    from relight.net import photos
    try:
        files, truth = photos.read_photo_set(spheres, ("gray",))
        mask = load_image(os.path.join(spheres, "gray.mask.png"))[0][..., 0] > 0.5
        gammas = [photos.response_gamma(load_image(f)[0][..., :3], mask, t)["gamma"] for f, t in zip(files, truth)]
    except (RelightError, OSError, ValueError) as exc:
        return f"psm camera response: not measured ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})"
    if not gammas:
        return "psm camera response: not measured (no gray ball photographs)"
    return (f"psm camera response (gray ball, {len(gammas)} lights): codes ~ (n.l)^(1/gamma), gamma median "
            f"{np.median(gammas):.2f} (range {min(gammas):.2f}-{max(gammas):.2f}; 1 = proportional to the light, "
            "sRGB about 2.2)")


def main(argv=None) -> int:
    from relight.commands import argtypes as at
    ap = at.OneLineParser(description=__doc__.split("\n\n")[0])
    at.add_model_option(ap, action="append", default_text=False,
                        help="repeatable (default: every shipped model present, each labelled by its name)")
    ap.add_argument("--devset", default=os.path.expanduser(os.path.join("~", "relight-data", "photo")),
                    help="folder of the Mitsuba / Cycles dev sets (made when missing)")
    ap.add_argument("--n", type=at.int_in(1, 100_000, "a count"), default=320, help="dev-set images (default 320)")
    ap.add_argument("--no-devset", action="store_true", help="skip the Mitsuba / Cycles dev sets")
    ap.add_argument("--camera-tilt", type=at.float_in(-89.0, 89.0, "a camera tilt in degrees"), default=None,
                    help="decode with this camera tilt instead of each model's own (or the paper's 45)")
    ap.add_argument("--backdrop-off", action="store_true",
                    help="also score psm_objects and the gray ball with everything outside the object "
                         "black (the sets' masks): how much the surroundings move each model")
    ap.add_argument("--surround", action="store_true",
                    help="also score psm_objects with the surroundings outside the masks changed one way "
                         "at a time (black, as --backdrop-off, their mean colour, upside down, each row its "
                         "mean, that profile upside down; relight.net.photos.replace_surround): what in them "
                         "moves each model")
    ap.add_argument("--linear", action="store_true",
                    help="also score psm_objects and the gray ball with their 8-bit codes read as linear values "
                         "(their camera's response, measured on the gray ball: the 'camera response' line)")
    ap.add_argument("--data", action="append", default=[], metavar="DIR",
                    help="also score this dataset folder (relight generate output; repeatable)")
    ap.add_argument("--json", default=None, help="also write every summary to this JSON file")
    ap.add_argument("--photos", default=None,
                    help="folder holding psm_objects/ and psm_spheres/ (default: $RELIGHT_SHARED_DATA, "
                         "else shared/data next to the checkout)")
    args = ap.parse_args(argv)
    from relight.errors import RelightError
    from relight.net import photos
    from relight.net.io import SHIPPED_NAMES, shipped_model_path
    from relight.net.predict import load_model, model_surround
    try:
        names = args.model or [n for n in SHIPPED_NAMES if os.path.isfile(shipped_model_path(n))] or [None]
        models = [(m or "shipped", load_model(m)) for m in names]
        sets = []
        shared = photos.shared_data_dir(args.photos)
        objects = os.path.join(shared, "psm_objects")
        spheres = os.path.join(shared, "psm_spheres")
        if os.path.isdir(objects):
            sets.append(("psm_objects (60 photos)", "photo", objects, None, None, False))
            if args.linear:
                sets.append(("psm_objects, codes read as linear", "photo", objects, None, None, True))
            if args.backdrop_off or args.surround:
                sets.append(("psm_objects, backdrop blacked out (masks)", "photo", objects, None, "black", False))
            if args.surround:
                sets += [(f"psm_objects, surroundings {how}", "photo", objects, None, how, False)
                         for how in photos.SURROUNDS if how != "black"]
        else:
            print(f"psm_objects: skipped ({objects} not present)")
        if os.path.isdir(spheres):
            sets.append(("psm_spheres gray ball", "photo", spheres, ("gray",), None, False))
            if args.linear:
                sets.append(("psm_spheres gray ball, codes read as linear", "photo", spheres, ("gray",), None, True))
            if args.backdrop_off:
                sets.append(("psm_spheres gray ball, backdrop blacked out (masks)", "photo", spheres, ("gray",),
                             "black", False))
            sets.append(("psm_spheres chrome ball", "photo", spheres, ("chrome",), None, False))
            print(_camera_response(spheres))
        else:
            print(f"psm_spheres: skipped ({spheres} not present)")
        for folder in args.data:
            if os.path.isfile(os.path.join(folder, "manifest.jsonl")):
                sets.append((f"{folder}", "data", folder, None, None, False))
            else:
                print(f"{folder}: skipped (no manifest.jsonl: not a relight dataset)")
        if not args.no_devset:
            mitsuba, cycles, agx = ensure_devset(args.devset, args.n)
            sets.append((f"dev set, Mitsuba ({args.n} default rooms)", "data", mitsuba, None, None, False))
            if cycles:
                sets.append((f"dev set, Cycles (the same {args.n} scenes)", "data", cycles, None, None, False))
                sets.append((f"dev set, Cycles + Blender's AgX view (the same {args.n})", "data", agx, None, None, False))
        results = {}
        for label, kind, folder, names, surround, linear in sets:
            print(f"\n{label}")
            if kind == "photo":
                _, truth = photos.read_photo_set(folder, names)
                print(f"  {'':<42}  {'n':>4}  direction       cone90  ood    follows x y"
                      "  in-image  slant |err| bias  slope x y    bias x y  bias-free")
                print(_row("  constant guess: light at the camera", _constant_guess(truth)))
            else:
                head_keys = ("direction_deg", "world_direction_deg", "colour_deg")
                print(f"  {'':<42}  {'n':>4}  cam-frame dir   world dir (true tilt)   colour   cone90  ood"
                      "    follows x y  in-image  slant |err| bias")
            masked = kind == "data" and any(model_surround(m) != "keep" for _, m in models) and _has_masks(folder)
            for name, model in models:
                if kind == "photo":
                    s = photos.summary(photos.score_photo_set(model, folder, names, args.camera_tilt, surround, linear))
                    print(_row(f"  {_label(name)}", s))
                elif model_surround(model) != "keep" and not masked:
                    print(f"  {_label(name):<42}  skipped: it reads the objects alone, and this set has no object masks")
                    continue
                else:
                    s = photos.summary(photos.score_dataset(model, folder, limit=args.n))
                    print(_row(f"  {_label(name)}", s, head_keys))
                results[f"{label} | {name}"] = s
        print("\ncolumns: median and mean degrees; cone90 = share of 90% cones holding the truth; "
              "ood = share flagged out-of-distribution; on photographs, follows: the correlation of "
              "predicted with true light right (x) and up (y) over the set (near 1: the answer tracks "
              "the light; near 0: a well-placed constant); in-image: median error of the light's "
              "direction in the image plane, which an object's shading determines; slant: median "
              "absolute and signed error of its angle from the view axis, which shading leaves to "
              "shadows, highlights and priors (the bas-relief ambiguity; relight.net.photos.shading_split); "
              "slope: of the predicted on the true x / y within each object (1 tracks the light, 0 stays "
              "put: shrinkage toward an average), bias: mean predicted minus true x / y, bias-free: the "
              "median error with that bias removed, a diagnostic using the truth (relight.net.photos.shrinkage)")
        if args.json:
            from relight.fileio import write_json
            write_json(args.json, results)
    except RelightError as exc:
        sys.stderr.write(f"bench_photos: error: {str(exc).splitlines()[0]}\n")
        return 2
    return 0


if __name__ == "__main__":
    from relight.commands import argtypes
    sys.exit(argtypes.run_script(main))

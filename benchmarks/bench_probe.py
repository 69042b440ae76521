"""Benchmark of the sphere procedure (``relight probe``) on spheres it has never seen:
the harder probe set (small chrome and gray spheres in cluttered rooms, rendered by
Mitsuba and by Blender Cycles; :mod:`relight.verify.probe_scenes`, "the harder set") and
the real photographs in shared/data/psm_spheres.

The set (``--set DIR``, made once with ``--make N``): ``probeNNN.json`` (a
``relight.probe-scene/v1`` file: the room as a relight scene file, the spheres, the
light, the truth), ``probeNNN.{mitsuba,cycles}.exr`` (linear) and ``.png`` (8-bit sRGB,
one exposure per scene for both renderers, chosen from the Mitsuba render so that its
brightest 2% clip: highlights and brightly lit floor or wall patches clip).
Truth: the direction from the chrome sphere's mirror point of the light's centre toward
that centre, in the camera frame (the light is 1-3.5 m away, so the direction from the
sphere's centre differs by up to a degree; both are in the file).

Methods, per renderer and file type:

- circle given: the circle closest to the true outline (what a person would mark),
  true field of view;
- circle marked: that circle moved as a careful hand would place it (centre off by
  ``MARKED_PX`` rms per axis, radius by 0.6 of that; seeded by the scene), refined within
  the default tolerance;
- circles given (+gray): the same with the gray sphere's circle as well (its shading
  helps choose among equally bright highlight candidates);
- automatic: no circle (the procedure finds the chrome sphere, the learned locator's
  prior on), true field of view; ``detector miss`` counts scenes where the chrome sphere
  found is not the true one (centre more than a third of the radius away) or none is
  found; with ``--rules-only`` also "automatic (rules only)": the hand-written detector
  alone (``relight probe --no-locator``).

Errors are in degrees; a failure counts as 180. The results found automatically over
their maximum are then listed by cause: the detection (another sphere or none), the
highlight (the same image with the true circle given is over the circle-given maximum too)
or the outline (the true circle would have given the light; the found outline's distance
from the true one through the highlight is printed).

    python benchmarks/bench_probe.py --set ~/relight-data/issue-29/set --make 40   # once (~15 min)
    python benchmarks/bench_probe.py --set ~/relight-data/issue-29/set [--qa DIR]
    python benchmarks/bench_probe.py --set ~/relight-data/issue-29/heldout --make 60 --first 1000   # never tuned on
    python benchmarks/bench_probe.py --set ~/relight-data/issue-29/team21 --make 60 --first 21000 \
        --res 256 --fov 30 --chrome-radius 15-20 --cycles-filter blackman-harris   # drawn as the team's renders
    python benchmarks/bench_probe.py --set ~/relight-data/issue-29/set --floor   # what 8-bit leaves
    python benchmarks/bench_probe.py --set ~/relight-data/issue-29/set --refilter DIR   # then --set DIR:
    #   the Cycles renders as Blender's default pixel filter (Blackman-Harris, 1.5 px) would give them
    #   (--refilter-blur 1.0: under a 1 px Gaussian blur instead, a lens's)
"""
from __future__ import annotations

import glob
import json
import math
import os
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from relight.net.photos import shared_data_dir  # noqa: E402
from relight.probe.footprint import BH_COEFFICIENTS, BH_SPAN_PX  # noqa: E402

PSM = os.path.join(shared_data_dir(), "psm_spheres")   # $RELIGHT_SHARED_DATA, else next to the checkout
TARGETS = {"cycles png, circle given": (1.0, 5.0), "cycles png, circles given (+gray)": (1.0, 5.0),
           "cycles png, automatic": (1.5, 8.0),
           "psm_spheres, mask": (2.0, None), "psm_spheres, automatic, fixed probe": (2.0, None)}
PNG_CLIP_SHARE = 0.02
MARKED_PX = 0.5        # a hand-marked circle: its centre off by this rms per axis, its radius by 0.6 of it


def _angle_deg(a, b) -> float:
    from relight.metrics import angle_deg
    return float(angle_deg(a, b))


BH_WIDTH_PX = BH_SPAN_PX / 2   # Blender's default pixel filter: Blackman-Harris of width 1.5, which
#                                Cycles spreads over twice that (film.cpp's filter table): support +-1.5 px


def blackman_harris_weights(width_px: float = BH_WIDTH_PX) -> np.ndarray:
    """1-D weights of Cycles' Blackman-Harris pixel filter over whole-pixel offsets
    ``-2..2``: the window (support ``+-width_px``) integrated in closed form over each
    offset's pixel ``[k - 0.5, k + 0.5]``, normalised to sum 1 (the filter is separable)."""
    a = BH_COEFFICIENTS
    span = 2.0 * width_px

    def antiderivative(x):   # of sum_j a_j cos(2 pi j (x / span + 1/2)) on the support
        x = np.clip(x, -width_px, width_px)
        u = x / span + 0.5
        return a[0] * x + sum(a[j] * np.sin(2 * np.pi * j * u) * span / (2 * np.pi * j) for j in (1, 2, 3))

    k = np.arange(-2, 3, dtype=float)
    w = antiderivative(k + 0.5) - antiderivative(k - 0.5)
    return w / w.sum()


def refilter_set(folder: str, out: str, blur_px: float | None = None) -> None:
    """A copy of the set's Cycles part as Blender's default pixel filter would render it:
    each linear Cycles EXR (rendered with a 1 px box, as Mitsuba's) convolved with the
    cell-integrated Blackman-Harris weights in x and y, then the 8-bit PNG re-encoded at
    the scene's exposure. An approximation (the box-filtered pixels are filtered again),
    which tells whether the light's sub-pixel position survives 8-bit clipping when a
    wider filter spreads it into unclipped neighbours. With ``blur_px``, a Gaussian blur
    of that standard deviation instead (a camera lens's, roughly)."""
    from scipy.ndimage import convolve1d, gaussian_filter

    from relight.errors import DatasetError, OutputError
    from relight.fileio import atomic_write
    from relight.imageio import read_exr, write_exr, write_png
    if os.path.abspath(out) == os.path.abspath(folder):
        raise OutputError("--refilter: the output folder must differ from --set")
    scenes = sorted(glob.glob(os.path.join(folder, "probe[0-9]*.json")))
    if not scenes:
        raise DatasetError(f"--refilter: no probe scenes (probeN.json) in {folder}")
    os.makedirs(out, exist_ok=True)
    w = blackman_harris_weights()
    for path in scenes:
        base = os.path.join(out, os.path.basename(path)[:-5])
        with open(path) as f:
            d = json.load(f)
        image = read_exr(path[:-5] + ".cycles.exr")
        if blur_px is None:
            image = convolve1d(convolve1d(image, w, axis=0, mode="nearest"), w, axis=1, mode="nearest")
        else:
            image = gaussian_filter(image, (blur_px, blur_px, 0), mode="nearest")
        write_exr(base + ".cycles.exr", image.astype(np.float32))
        write_png(base + ".cycles.png", image, exposure=d["png_exposure"])
        atomic_write(base + ".json", lambda tmp, d=d: open(tmp, "w").write(json.dumps(d, indent=1)))
    how = "Blackman-Harris" if blur_px is None else f"{blur_px:g} px Gaussian"
    print(f"wrote the {how} copy of {folder} to {out}")


SET_PROFILE = "set_profile.json"   # how a set's scenes are drawn and rendered
DEFAULT_PROFILE = {"res": None, "fov_deg": None, "chrome_radius_px": None, "cycles_filter": "box"}


def set_profile(folder: str, profile: dict) -> None:
    """Record ``profile`` (the options a set is drawn and rendered with) in ``folder``, or
    check it against the one recorded: a set is completed only with the options it was
    begun with (a set begun before profiles were recorded has the default one)."""
    from relight.errors import DatasetError
    from relight.fileio import atomic_write
    path = os.path.join(folder, SET_PROFILE)
    if os.path.exists(path):
        try:
            with open(path) as f:
                recorded = json.load(f)
        except (OSError, ValueError) as e:
            raise DatasetError(f"{path}: not a set profile ({e})") from None
    elif glob.glob(os.path.join(folder, "probe[0-9]*.json")):
        recorded = DEFAULT_PROFILE
    else:
        os.makedirs(folder, exist_ok=True)
        atomic_write(path, lambda tmp: open(tmp, "w").write(json.dumps(profile, indent=1)))
        return
    if recorded != profile:
        diff = ", ".join(f"{k} {recorded.get(k)} (asked {profile.get(k)})" for k in sorted(set(recorded) | set(profile))
                         if recorded.get(k) != profile.get(k))
        raise DatasetError(f"{folder} was made with other options: {diff}; complete it with those or use a new folder")


def make_set(folder: str, count: int, spp: int, first: int = 0, cycles: bool = True,
             pixel_filter: str = "box", res: int | None = None, fov_deg: float | None = None,
             chrome_radius_px: tuple[float, float] | None = None) -> None:
    """Write ``count`` probe scenes (seeds ``first`` on) and their Mitsuba and (unless not
    ``cycles``) Cycles renders into ``folder`` (existing files are kept: the set grows or
    resumes); Cycles with ``pixel_filter`` (``relight.verify.probe_scenes.CYCLES_PIXEL_FILTERS``:
    a box one pixel wide, Mitsuba's, or Blender's default Blackman-Harris 1.5 px). ``res``,
    ``fov_deg`` and ``chrome_radius_px`` fix what ``sample_room_scene`` otherwise draws
    (e.g. a set like the team's Cycles renders: 256 px, FOV 30, radius 15-20 px); the
    options are recorded in the set (:data:`SET_PROFILE`) and a set is only completed
    with the same ones."""
    from tqdm import tqdm

    from relight import backend
    from relight.children import child_env
    from relight.scene.blender import blender_python
    from relight.fileio import atomic_write
    from relight.imageio import write_exr, write_png
    from relight.probe.detect import camera_exposure
    from relight.verify import probe_scenes as ps
    set_profile(folder, {"res": res, "fov_deg": fov_deg,
                         "chrome_radius_px": None if chrome_radius_px is None else list(chrome_radius_px),
                         "cycles_filter": pixel_filter})
    backend.init()
    paths = []
    for i in tqdm(range(first, first + count), desc="Mitsuba renders", unit="scene"):
        path = os.path.join(folder, f"probe{i:03d}.json")
        paths.append(path)
        if os.path.exists(path) and os.path.exists(path[:-5] + ".mitsuba.png"):
            continue
        d = ps.sample_room_scene(i, res, fov_deg, chrome_radius_px)
        image = ps.render_room_mitsuba(d, spp=spp)
        # exposure as a camera's: the brightest PNG_CLIP_SHARE of the pixels clip
        d["png_exposure"] = camera_exposure(image, PNG_CLIP_SHARE)
        write_exr(path[:-5] + ".mitsuba.exr", image)
        write_png(path[:-5] + ".mitsuba.png", image, exposure=d["png_exposure"])
        atomic_write(path, lambda tmp, d=d: open(tmp, "w").write(json.dumps(d, indent=1)))
    python = blender_python() if cycles else None
    if python is None:
        print("Cycles renders skipped" + ("" if not cycles else " (no Blender environment)"))
        return
    todo = [p for p in paths if not os.path.exists(p[:-5] + ".cycles.png")]
    if not todo:
        return
    env = dict(child_env(), PYTHONPATH=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    cmd = [python, "-m", "relight.verify.probe_scenes", "cycles", *todo, "--spp", str(spp), "--pixel-filter", pixel_filter]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, text=True)
    for line in tqdm(proc.stdout, total=len(todo), desc="Cycles renders", unit="scene"):
        npy = line.strip()
        image = np.load(npy)
        base = npy[:-len(".cycles.npy")]
        with open(base + ".json") as f:
            d = json.load(f)
        write_exr(base + ".cycles.exr", image)
        write_png(base + ".cycles.png", image, exposure=d["png_exposure"])
        os.remove(npy)
    if proc.wait() != 0:
        raise SystemExit("Cycles renders failed")


def _probe(path: str, **kw):
    from relight.probe.run import ProbeConfig, run_probe
    return run_probe(ProbeConfig(chrome=path, **kw))


def rim_error_px(found, true, toward) -> float:
    """How far a found outline (circle ``(cx, cy, r)``, pixels) lies outside the true one
    along the ray from its centre through the point ``toward`` (negative: inside). Through
    the highlight, it is what the found circle puts into the light's direction: a
    highlight near the rim turns a radial error of ``d`` px into ``2 d / (r cos theta)``
    radians (``theta`` the normal's angle from the view ray)."""
    fx, fy, fr = (float(v) for v in found)
    tx, ty, tr = (float(v) for v in true)
    ux, uy = float(toward[0]) - fx, float(toward[1]) - fy
    n = math.hypot(ux, uy)
    if n == 0.0:
        return fr - tr - math.hypot(fx - tx, fy - ty)   # no direction: the worst case inside
    ux, uy = ux / n, uy / n
    b = ux * (fx - tx) + uy * (fy - ty)
    c = (fx - tx) ** 2 + (fy - ty) ** 2 - tr * tr
    return fr - (-b + math.sqrt(max(b * b - c, 0.0)))


def failure_cause(miss: bool, given_err: float, given_max: float) -> str:
    """Why a result found automatically is over its maximum: ``"detection"`` (another
    sphere or none was found), ``"highlight"`` (with the true circle given the same image is
    over the circle-given maximum too) or ``"outline"`` (the right sphere, and the true
    circle would have given the light: the found outline's error did it)."""
    return "detection" if miss else "highlight" if given_err > given_max else "outline"


def evaluate_set(folder: str, rows: list, detect: list, qa_dir: str | None, renderers, kinds,
                 automatic: bool = True, rules_only: bool = False, autos: list | None = None) -> None:
    """Every method on every image of the set: ``rows`` gets ``(method, light, error,
    file)``, ``detect`` ``(method, missed, file)`` and ``autos`` (if given), for each result
    found automatically, ``(method, file, error, circle-given error, rim error px, missed)``
    (:func:`rim_error_px` through the highlight found; ``nan`` when nothing was found)."""
    from tqdm import tqdm

    from relight.errors import ProbeError
    from relight.probe.run import write_qa
    scenes = sorted(glob.glob(os.path.join(folder, "probe*.json")))
    jobs = [(s, r, k) for s in scenes for r in renderers for k in kinds]
    for scene_path, renderer, kind in tqdm(jobs, desc="probe set", unit="image"):
        path = scene_path[:-5] + f".{renderer}.{kind}"
        if not os.path.exists(path):
            continue
        with open(scene_path) as f:
            d = json.load(f)
        t = d["truth"]
        truth = t["to_light_camera"]
        light = "front" if t["front"] else "back"
        name = f"{renderer} {kind}"
        try:
            res = _probe(path, chrome_circle=tuple(t["chrome_circle"]), fov_deg=t["fov_deg"])
            err = _angle_deg(res.entry["to_light_camera"], truth)
            if qa_dir:
                write_qa(os.path.join(qa_dir, os.path.basename(path)[:-4] + ".given.png"), res,
                         title=f"{os.path.basename(path)} circle given: error {err:.2f} deg")
        except ProbeError as exc:
            print(f"{path}: {exc}")
            err = 180.0
        rows.append((f"{name}, circle given", light, err, os.path.basename(path)))
        given_err = err
        try:    # as a person marks it: the true circle moved by MARKED_PX rms (seeded by the scene)
            rng = np.random.default_rng(int(os.path.basename(scene_path)[5:-5]))
            marked = np.asarray(t["chrome_circle"]) + rng.normal(0.0, MARKED_PX, 3) * np.array([1.0, 1.0, 0.6])
            res = _probe(path, chrome_circle=tuple(marked), fov_deg=t["fov_deg"])
            err = _angle_deg(res.entry["to_light_camera"], truth)
        except ProbeError as exc:
            print(f"{path}: {exc}")
            err = 180.0
        rows.append((f"{name}, circle marked ({MARKED_PX:g} px)", light, err, os.path.basename(path)))
        try:    # the paper's setting: the gray sphere in view too, its circle given as well
            res = _probe(path, chrome_circle=tuple(t["chrome_circle"]), fov_deg=t["fov_deg"], diffuse=path,
                         diffuse_circle=tuple(t["gray_circle"]))
            err = _angle_deg(res.entry["to_light_camera"], truth)
        except ProbeError as exc:
            print(f"{path}: {exc}")
            err = 180.0
        rows.append((f"{name}, circles given (+gray)", light, err, os.path.basename(path)))
        if not automatic:
            continue
        for locator in (True, False) if rules_only else (True,):
            suffix = "" if locator else " (rules only)"
            try:
                res = _probe(path, fov_deg=t["fov_deg"], locator=locator)
                err = _angle_deg(res.entry["to_light_camera"], truth)
                cx, cy, r = res.entry["chrome_circle"]
                tx, ty, tr = t["chrome_circle"]
                miss = math.hypot(cx - tx, cy - ty) > tr / 3.0
                rim = rim_error_px((cx, cy, r), (tx, ty, tr), res.entry["quality"]["highlight_px"])
                if qa_dir:
                    write_qa(os.path.join(qa_dir, os.path.basename(path)[:-4] + f".auto{'' if locator else '-rules'}.png"),
                             res, title=f"{os.path.basename(path)} automatic{suffix}: error {err:.2f} deg")
            except ProbeError:
                err, miss, rim = 180.0, True, math.nan
            rows.append((f"{name}, automatic{suffix}", light, err, os.path.basename(path)))
            detect.append((name + suffix, miss, os.path.basename(path)))
            if autos is not None:
                autos.append((f"{name}, automatic{suffix}", os.path.basename(path), err, given_err, rim, miss))


def evaluate_psm(rows: list, qa_dir: str | None, folder: str = PSM) -> None:
    from relight.errors import ProbeError
    from relight.probe import ortho as probes
    from relight.probe.batch import consensus_circle
    from relight.probe.detect import load_mask, read_probe_image
    from relight.probe.run import write_qa

    lights = np.loadtxt(os.path.join(folder, "lights.txt"), skiprows=1)
    mask_path = os.path.join(folder, "chrome.mask.png")
    mask = load_mask(mask_path)
    highlights, found = [], []
    for i, truth in enumerate(lights):
        path = os.path.join(folder, f"chrome.{i}.png")
        res = _probe(path, chrome_mask=mask_path)
        highlights.append(res.entry["quality"]["highlight_px"])
        rows.append(("psm_spheres, mask", "front", _angle_deg(res.entry["to_light_camera"], truth), path))
        if qa_dir:
            write_qa(os.path.join(qa_dir, f"psm_chrome.{i}.png"), res, title=f"psm chrome.{i}")
        try:
            auto = _probe(path).entry
            err = _angle_deg(auto["to_light_camera"], truth)
            found.append(auto["chrome_circle"])
        except ProbeError:
            err = 180.0
            found.append(None)
        rows.append(("psm_spheres, automatic", "front", err, path))
        rows.append(("psm_spheres, orthographic + mask (previous)", "front",
                     _angle_deg(probes.chrome_light_direction(read_probe_image(path)[0], mask), truth), path))
    # one camera, one ball, twelve lights: the batch's --fixed-probe (relight.probe.batch), the
    # circle the automatic detections agree on given to every image
    shared, agree = consensus_circle(found, len(found))
    for i, truth in enumerate(lights):
        path = os.path.join(folder, f"chrome.{i}.png")
        rows.append(("psm_spheres, automatic, fixed probe", "front",
                     _angle_deg(_probe(path, chrome_circle=shared).entry["to_light_camera"], truth), path))
    print(f"psm_spheres fixed probe: {agree} of {len(found)} automatic circles agree on "
          f"({shared[0]:.1f}, {shared[1]:.1f}, r {shared[2]:.1f})")
    circle = res.entry["chrome_circle"]
    fit, at_mask, at_fit = reference_circle(lights, np.array(highlights), circle)
    print(f"psm_spheres reference: mask circle ({circle[0]:.1f}, {circle[1]:.1f}, r {circle[2]:.1f}) median "
          f"{np.median(at_mask):.2f} deg; the circle that best explains the reference from the same highlights "
          f"({fit[0]:.1f}, {fit[1]:.1f}, r {fit[2]:.1f}) median {np.median(at_fit):.2f} max {np.max(at_fit):.2f}")


def reference_circle(lights: np.ndarray, highlights: np.ndarray, circle) -> tuple:
    """A diagnostic of a reference, not a method: the orthographic circle ``(cx, cy, r)``
    that best explains the reference directions ``lights`` (camera frame) from the
    highlight pixels found (least squares in degrees), started from ``circle`` (the
    mask's). Returns ``(fitted circle, errors at circle, errors at the fitted one)``: if
    the reference was derived with another circle, the highlights agree with it far
    better there than with the mask's."""
    from scipy import optimize

    def errors(c):
        n = np.column_stack([(highlights[:, 0] - c[0]) / c[2], -(highlights[:, 1] - c[1]) / c[2]])
        n = np.column_stack([n, np.sqrt(np.clip(1.0 - (n ** 2).sum(1), 0.0, None))])
        to_light = 2.0 * n[:, 2:3] * n - np.array([0.0, 0.0, 1.0])
        return np.degrees(np.arccos(np.clip((to_light * lights).sum(1), -1.0, 1.0)))
    fit = optimize.least_squares(errors, np.asarray(circle, float)).x
    return fit, errors(np.asarray(circle, float)), errors(fit)


RADIUS_BINS_PX = ((10.0, 15.0), (15.0, 20.0), (20.0, 45.0))   # the team's renders: radius 15-20 px


def png_floor(folder: str) -> None:
    """What an 8-bit file leaves of the light's position (Cycles, circle exact): the
    light's pixels are the connected region of the EXR, at the PNG's exposure, that the
    PNG clips and holds the brightest one; their intensity centroid (what the EXR gives),
    their plain centroid (what the clipped plateau gives: a pixel the light touches by 2%
    clips as one it fills), the footprint a light predicts from which pixels clip
    (:mod:`relight.probe.footprint`, its size unknown, as ``relight probe`` has it) and the
    same knowing the light's true angular size (the floor of what the clipped pixels
    say), each reflected on the true sphere, against the truth. (Lights within two pixels
    of the rim band keep the plain centroid in the footprint rows, as in ``relight probe``;
    scenes whose light does not clip are left out and counted.) "over 5": scenes beyond
    the circle-given target's maximum: where even the EXR's centroid is, a light's image
    within a pixel or two on a small sphere near its rim, no estimator of these pixels
    reaches it."""
    from scipy import ndimage

    from relight.probe import footprint
    from relight.probe import geometry as geom
    from relight.probe.detect import read_probe_image
    errs: dict = {"EXR intensity centroid": [], "clipped-pixel centroid (8-bit)": [],
                  "footprint, size unknown (8-bit)": [], "footprint, true size (floor)": []}
    radii, unclipped = [], 0
    for scene_path in sorted(glob.glob(os.path.join(folder, "probe*.json"))):
        with open(scene_path) as f:
            d = json.load(f)
        t = d["truth"]
        exr = read_probe_image(scene_path[:-5] + ".cycles.exr")[0]
        cam = geom.Camera.from_fov(exr.shape[1], exr.shape[0], t["fov_deg"])
        sphere = geom.sphere_from_circle(cam, *t["chrome_circle"])
        (x0, y0, x1, y1), _, s = geom.sphere_pixels(cam, sphere, rim_exclude_px=0.0)
        crop = np.where(s["hit"], exr[y0:y1, x0:x1].mean(-1) * d["png_exposure"], 0.0)
        if crop.max() < 1.0:   # the light does not clip in the PNG: no floor of clipped pixels to measure
            unclipped += 1
            continue
        radii.append(float(t["chrome_circle"][2]))
        labels, _ = ndimage.label(crop >= 1.0, np.ones((3, 3)))
        light = labels == labels[np.unravel_index(np.argmax(crop), crop.shape)]
        ys, xs = np.nonzero(light)
        centres = [(np.average(xs + 0.5, weights=w), np.average(ys + 0.5, weights=w))
                   for w in (crop[ys, xs], np.ones(len(xs)))]
        beside = ndimage.binary_dilation(light, np.ones((3, 3), bool))
        near = ndimage.binary_dilation(beside, np.ones((3, 3), bool))
        clear = not (near & ~geom.usable_pixels(cam, sphere, (x0, y0, x1, y1), s)).any()
        jac = geom.mirror_jacobian(cam, sphere, centres[1][0] + x0, centres[1][1] + y0) if clear else None
        if jac is None:   # by the rim, where relight probe does not use the footprint either
            centres += [centres[1]] * 2
        else:
            metric = jac.T @ jac
            lt, chrome = d["light"], d["chrome"]["centre_m"]
            angle = math.asin(lt["radius_m"] / float(np.linalg.norm(np.subtract(lt["position_m"], chrome))))
            observed = beside & s["hit"] & ((crop < 1.0) | light)
            for size in (None, angle / np.linalg.det(metric) ** 0.25):
                centres.append(footprint.footprint_centre(light, observed, metric, size))
        for name, (cx, cy) in zip(errs, centres):
            hit = geom.surface(cam, sphere, np.array([cx + x0]), np.array([cy + y0]))
            errs[name].append(_angle_deg(hit["reflect"][0], t["to_light_camera"]) if hit["hit"][0] else 180.0)
    radii = np.array(radii)
    if unclipped:
        print(f"8-bit floor: {unclipped} scene(s) left out, their light not clipped in the PNG")
    for name, e in errs.items():
        e = np.array(e)
        print(f"8-bit floor, {name:<32} n {len(e)} median {np.median(e):.2f} p90 {np.percentile(e, 90):.2f} "
              f"max {np.max(e):.2f} over 5 {int((e > 5.0).sum())}")
        for lo, hi in RADIUS_BINS_PX:   # the sphere's size sets what a pixel of position costs
            sel = e[(radii >= lo) & (radii < hi)]
            if len(sel):
                print(f"    chrome radius {lo:g}-{hi:g} px: n {len(sel)} median {np.median(sel):.2f} "
                      f"max {np.max(sel):.2f}")


def chrome_radii(folder: str) -> dict:
    """Each scene file's chrome sphere radius in pixels (its truth), by scene name (``probe007``)."""
    out = {}
    for scene_path in glob.glob(os.path.join(folder, "probe*.json")):
        with open(scene_path) as f:
            out[os.path.basename(scene_path)[:-5]] = float(json.load(f)["truth"]["chrome_circle"][2])
    return out


def report_by_radius(rows: list, radii: dict) -> None:
    """The set's rows again by the chrome sphere's radius (:data:`RADIUS_BINS_PX`)."""
    print("\nby chrome radius (px; the team's Cycles renders: 15-20)")
    for name in dict.fromkeys(r[0] for r in rows):
        for lo, hi in RADIUS_BINS_PX:
            errs = [e for n, _, e, f in rows if n == name and lo <= radii.get(f.split(".")[0], -1.0) < hi]
            if errs:
                print(f"{name:<44} {f'{lo:g}-{hi:g}':>6} {len(errs):>3} {np.median(errs):7.2f} "
                      f"{np.percentile(errs, 90):7.2f} {np.max(errs):7.2f}")


def median_verdict(errs, target: float, level: float = 0.95) -> tuple[float, float, str]:
    """A set's median against a target: the distribution-free confidence interval of the
    median (``scipy.stats.quantile_test``: order statistics, exact for any distribution)
    and ``"met"`` (the interval lies at or below the target), ``"not met"`` (above it) or
    ``"undecided"`` (it holds the target: the set's scenes cannot tell; a 60-scene set's
    median moves by about 0.15 deg from set to set, docs/probe-history.md)."""
    from scipy import stats
    ci = stats.quantile_test(np.asarray(errs, float), q=target, p=0.5).confidence_interval(level)
    lo, hi = float(ci.low), float(ci.high)
    return lo, hi, "met" if hi <= target else "not met" if lo > target else "undecided"


def report(rows: list, detect: list, worst: int = 0) -> None:
    """The results table; a row with a target also gives its median's 95% interval and
    verdict (:func:`median_verdict`) and how many scenes exceed the maximum."""
    print(f"{'set, method':<44} {'light':>6} {'n':>3} {'median':>7} {'p90':>7} {'max':>7}  target (median / max)")
    names = list(dict.fromkeys(r[0] for r in rows))
    for name in names:
        for light in ("all", "front", "back"):
            errs = [e for n, lt, e, _ in rows if n == name and (light == "all" or lt == light)]
            if not errs or (light != "all" and len(errs) == len([1 for n, *_ in rows if n == name])):
                continue
            target = TARGETS.get(name) if light == "all" else None
            tgt = "" if target is None else f"  <= {target[0]}" + (f" / <= {target[1]}" if target[1] else "")
            if target is not None:
                lo, hi, verdict = median_verdict(errs, target[0])
                tgt += f"; median 95% [{lo:.2f}, {hi:.2f}]: {verdict}"
                if target[1]:
                    tgt += f"; {sum(e > target[1] for e in errs)} over {target[1]:g}"
            print(f"{name:<44} {light:>6} {len(errs):>3} {np.median(errs):7.2f} {np.percentile(errs, 90):7.2f} "
                  f"{np.max(errs):7.2f}{tgt}")
    for name in dict.fromkeys(n for n, *_ in detect):
        misses = [f for n, m, f in detect if n == name and m]
        total = len([1 for n, *_ in detect if n == name])
        print(f"detector miss rate, {name:<24} {len(misses)}/{total} = {100.0 * len(misses) / total:.1f}%  "
              f"(target <= 2%){'  ' + ' '.join(misses[:6]) if misses else ''}")
    if worst:
        print("worst:")
        for n, lt, e, f in sorted(rows, key=lambda r: -r[2])[:worst]:
            print(f"  {e:7.2f}  {n:<40} {f}")


def report_causes(autos: list) -> None:
    """The results found automatically over their maximum (:data:`TARGETS`; the
    circle-given maximum of the same renderer and file type for :func:`failure_cause`), by
    cause, each with its circle-given error and, where the outline did it, how far the
    found outline lies from the true one through the highlight (:func:`rim_error_px`)."""
    for name in dict.fromkeys(a[0] for a in autos):
        top = TARGETS.get(name, (None, None))[1]
        given_top = TARGETS.get(name.split(", automatic")[0] + ", circle given", (None, None))[1]
        if top is None or given_top is None:
            continue
        over = [a for a in autos if a[0] == name and a[2] > top]
        causes = {c: [a for a in over if failure_cause(a[5], a[3], given_top) == c]
                  for c in ("outline", "highlight", "detection")}
        print(f"{name} over {top:g} deg, by cause: " + ", ".join(f"{c} {len(v)}" for c, v in causes.items())
              + f" (of {len([a for a in autos if a[0] == name])})")
        for cause, items in causes.items():
            for _, f, err, given_err, rim, _ in sorted(items, key=lambda a: -a[2]):
                where = f"; found outline {rim:+.2f} px from the true one through the highlight" if cause == "outline" else ""
                print(f"  {f:<24} {err:7.2f}  {cause:<9} circle given {given_err:.2f}{where}")


def main() -> None:
    from relight.commands import argtypes as at
    from relight.verify import probe_scenes as ps
    ap = at.OneLineParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", default=os.path.expanduser(os.path.join("~", "relight-data", "issue-29", "set")),
                    help="folder of the harder probe set")
    ap.add_argument("--make", type=at.int_in(0, 10_000, "a scene count"), default=0,
                    help="first make (or complete) a set of this many scenes")
    ap.add_argument("--first", type=at.int_in(0, 1_000_000, "a scene seed"), default=0,
                    help="with --make: the first scene's seed (a held-out set: --first 1000)")
    ap.add_argument("--no-cycles", action="store_true",
                    help="with --make: Mitsuba renders only (fast; e.g. training scenes for a learned detector)")
    ap.add_argument("--spp", type=at.spp, default=64, help="samples per pixel when making the set")
    ap.add_argument("--cycles-filter", choices=sorted(ps.CYCLES_PIXEL_FILTERS), default="box",
                    help="with --make: Cycles' pixel filter (box 1 px as Mitsuba's, the set's; blackman-harris: "
                         "Blender's default, 1.5 px)")
    ap.add_argument("--res", type=at.int_in(64, 1024, "an image size in pixels"), default=None,
                    help="with --make: every scene's image size (square; default: drawn among 128-512)")
    fov_lo, fov_hi = ps.ROOM_FOV_DEG
    ap.add_argument("--fov", type=at.float_in(fov_lo, fov_hi, "a field of view in degrees"), default=None,
                    help=f"with --make: every scene's field of view (default: drawn in {fov_lo:g}-{fov_hi:g} deg)")
    ap.add_argument("--chrome-radius", type=at.int_range_in(5, 150, "a chrome radius in pixels"), default=None,
                    metavar="LO-HI", help="with --make: the chrome sphere's radius drawn in LO-HI px (default "
                                          f"{ps.ROOM_RADIUS_PX[0]:g}-{ps.ROOM_RADIUS_PX[1]:g}, at most "
                                          f"{100 * ps.ROOM_MAX_RADIUS_SHARE:g}%% of the image side); the team's Cycles "
                                          "renders: --res 256 --fov 30 --chrome-radius 15-20 --cycles-filter blackman-harris")
    ap.add_argument("--renderers", default="cycles,mitsuba")
    ap.add_argument("--kinds", default="png,exr", help="which files of the set: png (8-bit) and/or exr")
    ap.add_argument("--no-psm", action="store_true", help="skip shared/data/psm_spheres")
    ap.add_argument("--psm", default=PSM, help="the psm_spheres folder (default: $RELIGHT_SHARED_DATA/psm_spheres, else shared/data "
                         "next to the checkout)")
    ap.add_argument("--no-auto", action="store_true", help="circles given only (automatic detection is slow)")
    ap.add_argument("--rules-only", action="store_true",
                    help="also detect without the learned locator (rows \"automatic (rules only)\")")
    ap.add_argument("--qa", default=None, help="write QA overlays to this folder")
    ap.add_argument("--floor", action="store_true",
                    help="only the 8-bit floor: the light's position from the Cycles EXR's clipped pixels")
    ap.add_argument("--worst", type=at.int_in(0, 10_000, "a count"), default=8, help="list the worst N results")
    ap.add_argument("--refilter", default=None, metavar="DIR",
                    help="only write a copy of the set's Cycles renders under Blender's default pixel filter "
                         "(Blackman-Harris 1.5 px) to DIR; then run with --set DIR --renderers cycles")
    ap.add_argument("--refilter-blur", type=at.float_in(0.0, 10.0, "a blur in pixels", open_lo=True), default=None,
                    metavar="PX", help="with --refilter: a Gaussian blur of this standard deviation (pixels) instead")
    args = ap.parse_args()
    if args.refilter_blur is not None and not args.refilter:
        ap.error("--refilter-blur needs --refilter DIR")
    for flag, value in (("--cycles-filter", args.cycles_filter != "box"), ("--res", args.res), ("--fov", args.fov),
                        ("--chrome-radius", args.chrome_radius)):
        if value and not args.make:
            ap.error(f"{flag} needs --make N (it sets how the set's scenes are made)")
    try:
        ps.check_chrome_radius(args.chrome_radius, args.res)
    except ValueError as exc:
        ap.error(f"--chrome-radius: {exc}")
    if args.refilter:
        refilter_set(args.set, args.refilter, args.refilter_blur)
        return
    if args.make:
        make_set(args.set, args.make, args.spp, args.first, cycles=not args.no_cycles, pixel_filter=args.cycles_filter,
                 res=args.res, fov_deg=args.fov, chrome_radius_px=args.chrome_radius)
    if args.floor:
        png_floor(args.set)
        return
    if args.qa:
        os.makedirs(args.qa, exist_ok=True)
    rows: list = []
    detect: list = []
    autos: list = []
    if os.path.isdir(args.set):
        evaluate_set(args.set, rows, detect, args.qa, args.renderers.split(","), args.kinds.split(","),
                     not args.no_auto, args.rules_only, autos)
    else:
        print(f"no probe set at {args.set}: make it with --make 40")
    if args.no_psm:
        pass
    elif os.path.isdir(args.psm):
        evaluate_psm(rows, args.qa, args.psm)
    else:
        print(f"psm_spheres not found at {os.path.normpath(args.psm)}; real-photo part skipped")
    print(f"\nsphere procedure benchmark: set {args.set}")
    report(rows, detect, args.worst)
    report_causes(autos)
    if os.path.isdir(args.set):
        report_by_radius(rows, chrome_radii(args.set))


if __name__ == "__main__":
    from relight.commands import argtypes
    sys.exit(argtypes.run_script(main))

"""``relight probe`` as a library call: images in, one predictions entry (and a QA
overlay) out. See :mod:`relight.probe.geometry` for the geometry and
:mod:`relight.probe.detect` for finding the spheres."""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from relight.probe import detect
from relight.probe import geometry as geom
from relight.probe.geometry import Camera, ProbeError, Sphere

__all__ = [
    "CIRCLE_TOLERANCE_PX",
    "WHITE",
    "ProbeConfig",
    "ProbeResult",
    "locate_sphere",
    "qa_caption",
    "run_probe",
    "write_qa",
]

CIRCLE_TOLERANCE_PX = 0.5     # a given circle's default uncertainty (centre and radius, pixels)
WHITE = np.full(3, 1.0 / math.sqrt(3.0))   # the colour when no diffuse sphere measures it (unit RGB)
WHITE.flags.writeable = False


@dataclass(frozen=True)
class ProbeConfig:
    """What ``relight probe`` was asked. Give ``fov_deg`` (horizontal, across the image
    width) or ``focal_px`` for a perspective camera; neither means orthographic. Circles
    are ``(cx, cy, r)`` in pixels (x right, y down, origin top-left, pixel centres at +0.5)."""
    chrome: str | None = None
    chrome_circle: tuple[float, float, float] | None = None
    chrome_mask: str | None = None
    diffuse: str | None = None
    diffuse_circle: tuple[float, float, float] | None = None
    diffuse_mask: str | None = None
    fov_deg: float | None = None
    focal_px: float | None = None
    camera_tilt_deg: float | None = None
    linear: bool = False
    refine: bool = True
    circle_tolerance_px: float = CIRCLE_TOLERANCE_PX
    locator: bool = True          # chrome detection: the learned locator's proposal and prior (relight.probe.locator)

    def __post_init__(self):
        if not self.chrome and not self.diffuse:
            raise ProbeError("give --chrome (direction) and/or --diffuse (colour)")
        if self.fov_deg is not None and self.focal_px is not None:
            raise ProbeError("give --fov or --focal-px, not both")
        for kind in ("chrome", "diffuse"):
            if getattr(self, f"{kind}_circle") is not None and getattr(self, f"{kind}_mask") is not None:
                raise ProbeError(f"give --{kind}-circle or --{kind}-mask, not both")
            if (getattr(self, f"{kind}_circle") is not None or getattr(self, f"{kind}_mask") is not None) \
                    and not getattr(self, kind):
                raise ProbeError(f"--{kind}-circle/--{kind}-mask need --{kind} IMG")

    def camera(self, width: int, height: int) -> Camera:
        if self.fov_deg is not None:
            return Camera.from_fov(width, height, self.fov_deg)
        return Camera(width, height, self.focal_px)


@dataclass
class ProbeResult:
    """One probe measurement: the predictions entry and what the QA overlay draws."""
    entry: dict
    camera: Camera
    chrome_image: np.ndarray | None = None
    chrome_sphere: Sphere | None = None
    highlight: geom.Highlight | None = None
    diffuse_image: np.ndarray | None = None
    diffuse_sphere: Sphere | None = None
    alternative_sphere: Sphere | None = None    # an ambiguous detection's rival circle


def locate_sphere(image: np.ndarray, camera: Camera, kind: str, circle=None, mask_path: str | None = None,
                  refine: bool = True, exclude=(), candidates: list | None = None,
                  tolerance_px: float = CIRCLE_TOLERANCE_PX, clip_level: float | None = None,
                  use_locator: bool = True) -> tuple[Sphere, np.ndarray | None, str, dict]:
    """The ``kind`` sphere in ``image`` from a mask, a circle, or automatic detection
    (``candidates``: those of :func:`relight.probe.detect.find_spheres`, if already found;
    the list is filled in place; ``clip_level``: the image's, for detection). Returns
    ``(sphere, mask or None, how, refinement)``.

    A given circle is the truth unless the image proves otherwise: it is refined on the
    image's edges (unless ``refine`` is off or ``tolerance_px`` is 0) only within
    ``tolerance_px`` of its centre and radius, and the refinement is kept only when the
    outline then fits the edges better than the given circle
    (:func:`relight.probe.detect.constrained_refinement`); ``refinement`` reports it.
    A chrome sphere's rim edges lie inside its outline (it mirrors what lies behind it):
    a detected chrome outline is the circle fitted to them moved out by
    :func:`relight.probe.detect.chrome_rim_shift_px`, and a given circle's refinement
    fits the outline those edges imply (``rim_shift_px`` in the report), by the fit a
    detected chrome outline ends with (:func:`relight.probe.detect.outer_rim_fit`).
    A detected chrome sphere's ``refinement`` holds the detection's ``ambiguity`` (0-1) and
    the ``rival`` sphere when another circle scores within :data:`relight.probe.detect.DETECTION_MARGIN`
    of the one chosen (:func:`relight.probe.detect.rival_sphere`), and (``use_locator``) the
    learned locator's circle and the probability it puts near the one chosen, which weighed
    in the choice (:mod:`relight.probe.locator`)."""
    if mask_path is not None:
        mask = detect.load_mask(mask_path)
        return geom.sphere_from_mask(camera, mask), mask, "mask", {}
    if circle is not None:
        guess = geom.sphere_from_circle(camera, *circle)
        geom.bounding_box(camera, guess)
        if not refine or tolerance_px <= 0:
            return guess, None, "circle", {"tolerance_px": 0.0, "accepted": False}
        rim = detect.chrome_rim_shift_px(image) if kind == "chrome" else 0.0
        sphere, report = detect.constrained_refinement(image, camera, circle, tolerance_px, rim, kind == "chrome")
        if rim:
            report["rim_shift_px"] = round(rim, 4)
        how = "circle refined on edges" if report["accepted"] else "circle (as given)"
        return sphere, None, how, report
    if candidates is None:
        candidates = []
    report: dict = {}
    centres = None
    if kind == "chrome" and use_locator:   # the learned locator: a proposal and a prior on the pick
        from relight.probe import locator
        centres = locator.locate(image, clip_level)
        report["locator_circle"] = centres.circle
    if not candidates:
        bound = None if centres is None else (
            lambda cx, cy, r: centres.radius_bound(cx, cy, r, camera.width, camera.height))
        check = None
        if centres is not None:   # the learned outline check, on the image as the locator saw it
            from relight.probe import outline_check
            check = functools.partial(outline_check.check_circles, centres.seen)
        candidates.extend(detect.find_spheres(image, camera, clip_level, extra=[centres.circle] if centres else (),
                                              radius_bound=bound, outline_check=check))
    if centres is not None:   # (circles larger than any it was trained on: what it leaves, detect.share_the_rest)
        for c in candidates:
            if locator.judges(c["circle"][2], camera.width, camera.height):
                c["locator"] = centres.mass_near(*c["circle"])
        detect.share_the_rest(candidates)
    found = detect.pick_sphere(candidates, kind, exclude)
    if "locator" in found:
        report["locator_probability"] = found["locator"]
    elif "locator_rest" in found:   # too large for it to judge: what it left over (detect.share_the_rest)
        report["locator_left_over"] = found["locator_rest"]
    if "checked_from" in found:   # the outline the learned outline check moved it from
        report["checked_from"] = found["checked_from"]
    rival, margin = detect.rival_sphere(candidates, found, kind, exclude) if kind == "chrome" else (None, 0.0)
    rim = 0.0
    sphere = found["sphere"]
    if kind == "chrome":   # the outline, from the circle fitted to the rim's edges (detect.chrome_rim_shift_px)
        view = detect.detection_view(image, clip_level)[0]
        rim = detect.chrome_rim_shift_px(view)
        report["rim_shift_px"] = round(rim, 4)
        sphere = detect.with_centre_error(view, camera, sphere)
        sphere, apart = detect.disputed_outline(sphere, found)
        if apart is not None:   # the learned outline check puts the sphere elsewhere
            report["outline_disputed_px"] = round(apart, 3)
    if rival is not None and margin < detect.DETECTION_MARGIN:
        # another circle scores nearly as well: the detection is ambiguous (see run_probe)
        report.update(ambiguity=1.0 - margin / detect.DETECTION_MARGIN,
                      rival=detect.outline_from_rim(camera, rival["sphere"], rim))
    return detect.outline_from_rim(camera, sphere, rim), None, "detected", report


def run_probe(cfg: ProbeConfig) -> ProbeResult:
    """Run the sphere procedure; returns the predictions entry (without ``id``).

    Direction: the chrome sphere's highlight (each pixel's own view ray reflected; among
    equally bright blobs the one a small light explains best, the diffuse sphere's
    shading direction helping when there is one), else the diffuse sphere's shading.
    Colour: the diffuse sphere's mean lit colour (white when there is no diffuse sphere).
    """
    entry: dict = {}
    result = ProbeResult(entry=entry, camera=None)
    direction, rgb, methods = None, WHITE, []
    chrome_circle = None
    candidates: list = []      # spheres found automatically, shared when both are in one image
    chrome_found, clip = None, None
    if cfg.chrome:
        image, clip, how = detect.read_probe_image(cfg.chrome, cfg.linear)
        if np.asarray(image).max() <= 0:
            raise ProbeError(f"{cfg.chrome} is black")
        camera = cfg.camera(image.shape[1], image.shape[0])
        chrome_found = locate_sphere(image, camera, "chrome", cfg.chrome_circle, cfg.chrome_mask, cfg.refine,
                                     candidates=candidates, tolerance_px=cfg.circle_tolerance_px, clip_level=clip,
                                     use_locator=cfg.locator)
        chrome_circle = detect.outline_circle(camera, chrome_found[0])
        result.camera, result.chrome_image = camera, image
    d_dir = None
    if cfg.diffuse:
        d_dir, rgb = _measure_diffuse(cfg, entry, result, chrome_circle, clip, candidates)
    if cfg.chrome:
        sphere, mask, found, refinement = chrome_found
        image, camera = result.chrome_image, result.camera
        circle_px = None
        if found.startswith("circle"):   # the given circle's stated uncertainty
            circle_px = refinement.get("tolerance_px", 0.0) or CIRCLE_TOLERANCE_PX
        hl = geom.locate_highlight(image, camera, sphere, mask, clip, expect_to_light=d_dir, circle_px=circle_px)
        direction = hl.to_light
        entry["chrome_circle"] = [round(v, 3) for v in chrome_circle]
        entry["chrome_found_by"] = found
        if found == "detected":
            entry["chrome_rim_shift_px"] = refinement["rim_shift_px"]
            if "locator_circle" in refinement:
                p = refinement.get("locator_probability")   # None: a circle too large for it to judge
                entry["locator"] = {"circle": [round(v, 2) for v in refinement["locator_circle"]],
                                    "probability": None if p is None else round(p, 4)}
                if "locator_left_over" in refinement:
                    entry["locator"]["left_over"] = round(refinement["locator_left_over"], 4)
                if "checked_from" in refinement:
                    entry["locator"]["outline_moved_from"] = [round(v, 2) for v in refinement["checked_from"]]
            if "outline_disputed_px" in refinement:
                entry["outline_disputed_px"] = refinement["outline_disputed_px"]
            if "rival" in refinement:
                _detection_ambiguity(entry, result, hl, refinement, image, camera, clip, d_dir)
        elif refinement:
            entry["chrome_circle_refinement"] = refinement
        entry["chrome_centre_camera"] = [round(float(v), 6) for v in sphere.c / np.linalg.norm(sphere.c)]
        entry["quality"] = {k: (round(v, 4) if isinstance(v, float) else v) for k, v in hl.quality.items()
                            if not k.startswith("alternative")}
        entry["quality"]["outline_rms_px"] = round(sphere.outline_rms_px, 4)
        if sphere.outline_sigma_px is not None and not found.startswith("circle"):
            # a found chrome outline's centre error, the budget's circle term less 0.05 px
            entry["quality"]["outline_sigma_px"] = round(sphere.outline_sigma_px, 4)
        entry["quality_deg"] = round(hl.quality["uncertainty_deg"], 3)
        if hl.quality["ambiguity"] > 0:
            q = hl.quality
            entry["ambiguity"] = {"score": round(q["ambiguity"], 3),
                                  "alternative_to_light_camera": [round(v, 6) for v in q["alternative_to_light"]],
                                  "alternative_px": [round(v, 2) for v in q["alternative_px"]],
                                  "separation_deg": round(q["alternative_separation_deg"], 2)}
        entry["image_encoding"] = how
        methods.append("chrome")
        result.chrome_sphere, result.highlight = sphere, hl
    if d_dir is not None:
        methods.append("diffuse")
        if direction is None:
            direction = d_dir
    entry["to_light_camera"] = [float(v) for v in direction]
    entry["rgb"] = [float(v) for v in rgb]
    entry["method"] = "+".join(methods)
    entry["projection"] = ("orthographic" if not result.camera.perspective
                           else f"perspective, focal {result.camera.focal_px:.2f} px")
    from relight.frames import camera_to_pan_tilt
    tilt = cfg.camera_tilt_deg if cfg.camera_tilt_deg is not None else 0.0
    entry["pan_deg"], entry["tilt_deg"] = camera_to_pan_tilt(direction, tilt)
    return result


def _measure_diffuse(cfg: ProbeConfig, entry: dict, result: "ProbeResult", chrome_circle, clip,
                     candidates: list) -> tuple[np.ndarray | None, np.ndarray]:
    """The diffuse sphere's part of :func:`run_probe`: its circle, its shading direction
    and the light's colour, written to ``entry``; returns ``(direction or None, rgb)``.
    With a chrome sphere, a diffuse sphere that cannot be measured (searched for and not
    found, or found with no lit side left: the light behind it, or its lit side hidden)
    is skipped and said so (``diffuse_skipped``): the chrome sphere still gives the
    direction, and the colour stays white. Without one, either is a one-line error."""
    same = cfg.diffuse == cfg.chrome
    image, d_clip = (result.chrome_image, clip) if same else detect.read_probe_image(cfg.diffuse, cfg.linear)[:2]
    camera = cfg.camera(image.shape[1], image.shape[0])
    result.camera = result.camera or camera
    exclude = [chrome_circle] if same and chrome_circle is not None else []
    searched = cfg.diffuse_circle is None and cfg.diffuse_mask is None
    try:
        sphere, mask, found, refinement = locate_sphere(image, camera, "diffuse", cfg.diffuse_circle,
                                                        cfg.diffuse_mask, cfg.refine, exclude,
                                                        candidates if same else None, cfg.circle_tolerance_px,
                                                        d_clip)
    except ProbeError as exc:
        if not (cfg.chrome and searched):
            raise
        entry["diffuse_skipped"] = str(exc)
        return None, WHITE
    entry["diffuse_circle"] = [round(v, 3) for v in detect.outline_circle(camera, sphere)]
    entry["diffuse_found_by"] = found
    if refinement:
        entry["diffuse_circle_refinement"] = refinement
    result.diffuse_image, result.diffuse_sphere = image, sphere
    try:
        d_dir, rgb, info = geom.diffuse_light(image, camera, sphere, mask)
    except ProbeError as exc:
        if not cfg.chrome:
            raise
        entry["diffuse_skipped"] = str(exc)
        return None, WHITE
    entry["diffuse_to_light_camera"] = [round(float(v), 6) for v in d_dir]
    entry["diffuse_fit"] = {k: round(v, 4) if isinstance(v, float) else v for k, v in info.items()}
    return d_dir, rgb


def _detection_ambiguity(entry: dict, result: "ProbeResult", hl: geom.Highlight, report: dict,
                         image: np.ndarray, camera: Camera, clip, d_dir) -> None:
    """An ambiguous detection (``report`` of :func:`locate_sphere`): the light as the rival
    circle gives it, and the error budget widened by the angle between the two times the
    ambiguity (``detection_deg``), as for two highlight candidates. Writes
    ``entry["detection"]`` and keeps the rival for the QA overlay; a rival on which no
    highlight is found widens nothing (it is not a chrome sphere with a light)."""
    rival = report["rival"]
    try:
        other = geom.locate_highlight(image, camera, rival, None, clip, expect_to_light=d_dir)
    except ProbeError:
        return
    separation = math.degrees(math.acos(float(np.clip(other.to_light @ hl.to_light, -1.0, 1.0))))
    budget = hl.quality["error_budget_deg"]
    budget["detection_deg"] = round(report["ambiguity"] * separation, 3)
    budget["total_deg"] = round(math.hypot(budget["total_deg"], budget["detection_deg"]), 3)
    hl.quality["uncertainty_deg"] = budget["total_deg"]
    entry["detection"] = {"ambiguity": round(report["ambiguity"], 3),
                          "alternative_circle": [round(v, 3) for v in detect.outline_circle(camera, rival)],
                          "alternative_to_light_camera": [round(float(v), 6) for v in other.to_light],
                          "separation_deg": round(separation, 2)}
    result.alternative_sphere = rival


def _draw(canvas, camera: Camera, sphere: Sphere | None, highlight: geom.Highlight | None, colour,
          scale: float, dx: float, dy: float, thick: int) -> None:
    """Draw a sphere's outline and (chrome) its highlight, the normal there and the
    reflected direction on ``canvas`` (BGR uint8), image point ``(x, y)`` going to
    ``((x - dx) * scale, (y - dy) * scale)`` (both in the +0.5 pixel-centre convention)."""
    import cv2
    if sphere is None:
        return

    def pt(xy):   # OpenCV draws with integer pixel centres; shift=4 gives 1/16 px
        a = np.asarray(xy, np.float64)
        return np.round(np.stack([(a[..., 0] - dx) * scale - 0.5, (a[..., 1] - dy) * scale - 0.5], -1) * 16) \
            .astype(np.int32)

    def tup(xy):
        return tuple(int(v) for v in pt(xy))

    x, y = geom.outline_polygon(camera, sphere, 180)
    cv2.polylines(canvas, [pt(np.stack([x, y], -1))], True, colour, thick, cv2.LINE_AA, shift=4)
    if highlight is None:
        return
    s = geom.surface(camera, sphere, np.array([highlight.pixel[0]]), np.array([highlight.pixel[1]]))
    if not s["hit"][0]:
        return
    p, n = s["point"][0], s["normal"][0]
    r_px = detect.outline_circle(camera, sphere)[2]
    hit_px = camera.project(p)
    cv2.line(canvas, tup(camera.project(sphere.c)), tup(camera.project(p + n * sphere.radius * 0.5)),
             (0, 160, 255), thick, cv2.LINE_AA, shift=4)
    # the reflected direction, drawn as the image of a 3-D segment from the highlight
    end = camera.project(p + highlight.to_light * sphere.radius * 1.5)
    if np.linalg.norm(end - hit_px) < 0.2 * r_px:     # toward or away from the camera: lengthen
        end = hit_px + (end - hit_px) * (0.2 * r_px / max(np.linalg.norm(end - hit_px), 1e-9))
    cv2.arrowedLine(canvas, tup(hit_px), tup(end), (0, 0, 255), thick, cv2.LINE_AA, shift=4, tipLength=0.2)
    arm = 6 * 16
    if "alternative_px" in highlight.quality:   # the other candidate of an ambiguous choice: yellow
        a = tup(np.asarray(highlight.quality["alternative_px"]))
        cv2.line(canvas, (a[0] - arm, a[1] - arm), (a[0] + arm, a[1] + arm), (0, 255, 255), thick, cv2.LINE_AA, shift=4)
        cv2.line(canvas, (a[0] - arm, a[1] + arm), (a[0] + arm, a[1] - arm), (0, 255, 255), thick, cv2.LINE_AA, shift=4)
    c = tup(np.asarray(highlight.pixel))
    cv2.line(canvas, (c[0] - arm, c[1]), (c[0] + arm, c[1]), (255, 0, 255), thick, cv2.LINE_AA, shift=4)
    cv2.line(canvas, (c[0], c[1] - arm), (c[0], c[1] + arm), (255, 0, 255), thick, cv2.LINE_AA, shift=4)


CHROME_BGR, DIFFUSE_BGR, RIVAL_BGR = (0, 255, 0), (255, 255, 0), (0, 255, 255)


def qa_caption(e: dict, title: str = "") -> list[str]:
    """The QA overlay's caption lines for entry ``e``: the direction, the quality figures and
    the error budget, with how the chrome circle was had (a batch's shared circle named as
    such, with how many of its images agreed on it)."""
    d = e["to_light_camera"]
    lines = [title, f"to_light_camera ({d[0]:+.3f}, {d[1]:+.3f}, {d[2]:+.3f})  pan {e['pan_deg']:.1f}  "
             f"tilt {e['tilt_deg']:.1f}  [{e['method']}; {e['projection']}]"]
    if "quality" in e:
        q = e["quality"]
        lines.append(f"uncertainty ~{e['quality_deg']:.2f} deg; highlight {q['highlight_pixels']} px"
                     f"{' clipped' if q['clipped'] else ''}; view angle {q['view_angle_deg']:.0f} deg; "
                     f"outline rms {q['outline_rms_px']:.2f} px; ambiguity {q['ambiguity']:.2f}")
        b = q["error_budget_deg"]
        detection = f"  detection {b['detection_deg']:.2f}" if "detection_deg" in b else ""
        lines.append(f"error budget (deg, 1 sigma): circle {b['circle_deg']:.2f}  highlight {b['highlight_deg']:.2f}"
                     f"  camera model {b['camera_deg']:.2f}{detection}  -> total {b['total_deg']:.2f}"
                     f"  [chrome {e['chrome_found_by']}"
                     + (f", locator p {e['locator']['probability']:.2f}"
                        if e.get("locator", {}).get("probability") is not None else "")
                     + (f", locator left over {e['locator']['left_over']:.2f}"
                        if "left_over" in e.get("locator", {}) else "") + "]")
    if "outline_disputed_px" in e:
        lines.append(f"chrome outline disputed: the learned outline check puts it {e['outline_disputed_px']:.2f} px away "
                     "(the circle term takes in half of that)")
    if "chrome_circle_shared" in e:
        shared = e["chrome_circle_shared"]
        c = shared["circle"]
        lines.append(f"chrome circle: the batch's fixed probe ({c[0]:.1f}, {c[1]:.1f}, r {c[2]:.1f}), "
                     f"found in {shared['found']} of {shared['images']} images, {shared['agreeing']} agreeing")
    return lines


def write_qa(path: str, result: ProbeResult, title: str = "", entry: dict | None = None) -> None:
    """QA overlay PNG: the image with the outlines (green chrome, cyan diffuse), the
    highlight (magenta cross; a rival candidate, when the choice was ambiguous, as a
    yellow x; a rival circle of an ambiguous detection in yellow), the normal there (orange, from the sphere's centre) and the reflected
    direction toward the light (red arrow); on the right, each sphere enlarged with the
    same marks; below, the numbers, with the error budget (circle, highlight, camera
    model, in degrees)."""
    import cv2
    from relight.imageio import to_srgb8
    cam = result.camera
    image = result.chrome_image if result.chrome_image is not None else result.diffuse_image
    # dark photographs are brightened for display (by up to 64x, as the caption says)
    exposure = float(np.clip(detect._exposure(image), 1.0, 64.0))
    h, w = image.shape[:2]
    scale = min(1.0, 900.0 / max(h, w))
    full = cv2.resize(to_srgb8(image, exposure)[..., ::-1], (max(1, round(w * scale)), max(1, round(h * scale))),
                      interpolation=cv2.INTER_AREA).copy()
    same = result.diffuse_image is result.chrome_image
    _draw(full, cam, result.alternative_sphere, None, RIVAL_BGR, scale, 0.0, 0.0, 1)
    _draw(full, cam, result.chrome_sphere, result.highlight, CHROME_BGR, scale, 0.0, 0.0, 1)
    if same or result.chrome_image is None:
        _draw(full, cam, result.diffuse_sphere, None, DIFFUSE_BGR, scale, 0.0, 0.0, 1)
    tiles, zoom = [], 300
    for sphere, img, hl, colour in ((result.chrome_sphere, result.chrome_image, result.highlight, CHROME_BGR),
                                    (result.diffuse_sphere, result.diffuse_image, None, DIFFUSE_BGR)):
        if sphere is None:
            continue
        cx, cy, r = detect.outline_circle(cam, sphere)
        half = 1.25 * r
        s = zoom / (2 * half)
        x0, y0 = cx - half, cy - half
        m = np.array([[s, 0, (0.5 - x0) * s - 0.5], [0, s, (0.5 - y0) * s - 0.5]])
        tile = cv2.warpAffine(np.ascontiguousarray(to_srgb8(img, exposure)[..., ::-1]), m, (zoom, zoom), flags=cv2.INTER_LINEAR)
        _draw(tile, cam, sphere, hl, colour, s, x0, y0, 2)
        tiles.append(tile)
    right = np.concatenate(tiles, 0)
    height = max(full.shape[0], right.shape[0])
    if exposure > 1.5:
        title = f"{title}  (shown {exposure:.0f}x brighter)"
    lines = [t for t in qa_caption(result.entry if entry is None else entry, title) if t]
    # wide enough for the caption lines (about 6 px a character at this font size), a row each
    panel = np.zeros((height + 10 + 20 * len(lines), max(full.shape[1] + right.shape[1] + 4, 800), 3), np.uint8)
    panel[:full.shape[0], :full.shape[1]] = full
    panel[:right.shape[0], full.shape[1] + 4:full.shape[1] + 4 + right.shape[1]] = right
    for i, text in enumerate(lines):
        cv2.putText(panel, text, (6, height + 18 + 20 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1,
                    cv2.LINE_AA)
    from relight.imageio import write_srgb8
    write_srgb8(path, panel[..., ::-1])   # OpenCV draws BGR

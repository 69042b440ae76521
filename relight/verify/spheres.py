"""Tiny Mitsuba probe scenes: a diffuse and a specular sphere (paper Figure 4) and a
pole with its cast shadow on a ground disc (paper Figure 5).

Each probe is lit by a *directional* light (a distant sun) coming from ``(pan_rel_deg,
tilt_deg)``: pan relative to the camera (0 front / camera side, 90 camera's right,
180 behind the scene, 270 left), tilt = elevation above the ground in degrees. The
camera sits at pan 0 and the given tilt, looking at the origin with +Z up, exactly as
in ``shared/conventions.md``, so world pan equals ``pan_rel``.

Light colour is the unit-norm linear RGB times ``SUN_IRRADIANCE`` (per channel pi for
white), so a white diffuse surface of albedo ``rho`` facing the light has radiance
``rho``. A dim constant sky keeps unlit sides from being pure black.

Scenes are loaded once per (kind, resolution) and updated in place (light direction,
colour, camera pose) through ``mi.traverse``.
"""
from __future__ import annotations

__all__ = [
    "SUN_IRRADIANCE", "SKY_RADIANCE", "SKY_SAMPLING_WEIGHT", "DIFFUSE_ALBEDO", "SPECULAR_ALPHA",
    "SPHERE_CAMERA_R_M", "SPHERE_FOV_DEG", "POLE_HEIGHT_M", "POLE_RADIUS_M", "GROUND_RADIUS_M",
    "POLE_CAMERA_R_M", "POLE_FOV_DEG", "GROUND_ALBEDO", "POLE_ALBEDO", "DEFAULT_SPP", "KINDS", "render_probe",
    "sphere_pair", "pole_inset", "overlay_pole", "gt_from_entry", "sphere_rows",
]

import math
import os

import numpy as np

from relight import backend, frames, render

SUN_IRRADIANCE = math.pi * math.sqrt(3.0)  # W/m^2 per unit of unit-norm rgb: white -> pi/channel
SKY_RADIANCE = 0.03            # dim ambient so shadows are dark grey, not black
SKY_SAMPLING_WEIGHT = 0.05     # the sun gets ~95% of light samples: far less noise
DIFFUSE_ALBEDO = 0.8
SPECULAR_ALPHA = 0.08          # GGX roughness of the specular (roughconductor) sphere
SPHERE_CAMERA_R_M = 5.0        # sphere radius 1 m at the origin
SPHERE_FOV_DEG = 30.0
POLE_HEIGHT_M = 0.6
POLE_RADIUS_M = 0.05
GROUND_RADIUS_M = 1.2
POLE_CAMERA_R_M = 7.0
POLE_FOV_DEG = 24.0
GROUND_ALBEDO = 0.6
POLE_ALBEDO = 0.85
DEFAULT_SPP = 32
KINDS = ("diffuse", "specular", "pole", "ground")

_scenes: dict = {}


def _scene(kind: str, res: int):
    """The loaded scene of one probe kind and size (cached)."""
    if kind not in KINDS:
        raise ValueError(f"unknown probe kind {kind!r}; expected one of {list(KINDS)}")
    key = (kind, int(res))
    if key in _scenes:
        return _scenes[key]
    mi = backend.mitsuba()
    pole_like = kind in ("pole", "ground")
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 4, "hide_emitters": True},
        "sensor": render.sensor(res, POLE_FOV_DEG if pole_like else SPHERE_FOV_DEG, pixel_format="rgba"),
        "sun": {"type": "directional", "direction": [0.0, 0.0, -1.0],
                "irradiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}},
        "sky": {"type": "constant", "sampling_weight": SKY_SAMPLING_WEIGHT, "radiance": {"type": "rgb", "value": [SKY_RADIANCE] * 3}},
    }
    if kind == "diffuse":
        scene["probe"] = {"type": "sphere", "radius": 1.0,
                          "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [DIFFUSE_ALBEDO] * 3}}}
    elif kind == "specular":
        scene["probe"] = {"type": "sphere", "radius": 1.0,
                          "bsdf": {"type": "roughconductor", "distribution": "ggx", "alpha": SPECULAR_ALPHA}}
    else:
        scene["ground"] = {"type": "disk",
                           "to_world": mi.ScalarTransform4f().scale([GROUND_RADIUS_M, GROUND_RADIUS_M, 1.0]),
                           "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [GROUND_ALBEDO] * 3}}}
        if kind == "pole":
            scene["pole"] = {"type": "cylinder", "p0": [0.0, 0.0, 0.0], "p1": [0.0, 0.0, POLE_HEIGHT_M],
                             "radius": POLE_RADIUS_M,
                             "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [POLE_ALBEDO] * 3}}}
            scene["cap"] = {"type": "disk",
                            "to_world": mi.ScalarTransform4f().translate([0.0, 0.0, POLE_HEIGHT_M])
                            @ mi.ScalarTransform4f().scale([POLE_RADIUS_M, POLE_RADIUS_M, 1.0]),
                            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [POLE_ALBEDO] * 3}}}
    loaded = mi.load_dict(scene)
    _scenes[key] = (loaded, mi.traverse(loaded))
    return _scenes[key]


def render_probe(kind: str, pan_rel_deg: float, tilt_deg: float, rgb, camera_tilt_deg: float,
                 res: int = 96, spp: int = DEFAULT_SPP, seed: int = 0) -> np.ndarray:
    """Render one probe under a distant light; returns linear RGBA ``(res, res, 4)`` float32.

    Args:
        kind: "diffuse" / "specular" (unit sphere at the origin), "pole" (a 0.6 m pole
            on a grey ground disc) or "ground" (the disc alone, for shadow tests).
        pan_rel_deg, tilt_deg: direction *toward* the light (degrees; pan relative to
            the camera, tilt = elevation, may be negative for a light below the horizon).
        rgb: light colour, linear, any positive scale (normalised here).
        camera_tilt_deg: camera elevation in (-90, 90) degrees.
    Alpha is 1 where a camera ray hits the probe, 0 on the background.
    """
    mi = backend.mitsuba()
    scene, params = _scene(kind, res)
    rgb = np.asarray(rgb, dtype=np.float64)
    if rgb.shape != (3,) or not np.isfinite(rgb).all() or (rgb < 0).any() or not rgb.max() > 0:
        raise ValueError(f"rgb must be three finite non-negative numbers, not all zero, got {rgb.tolist()}")
    rgb = rgb / np.linalg.norm(rgb)
    to_light = frames.direction(pan_rel_deg, tilt_deg)
    m = np.eye(4)
    m[:3, :3] = frames.frame_z_to(frames.travel_direction(to_light))  # emitter local +Z = travel
    pole_like = kind in ("pole", "ground")
    r_m = POLE_CAMERA_R_M if pole_like else SPHERE_CAMERA_R_M
    params["sun.to_world"] = mi.AffineTransform4f(m)
    params["sun.irradiance.value"] = mi.Color3f(*(SUN_IRRADIANCE * rgb).tolist())
    params["sensor.to_world"] = mi.AffineTransform4f(frames.mitsuba_sensor_to_world(camera_tilt_deg, r_m))
    params.update()
    return render.render_scene(scene, spp, seed)


def sphere_pair(pan_rel_deg: float, tilt_deg: float, rgb, camera_tilt_deg: float,
                res: int = 96, spp: int = DEFAULT_SPP) -> tuple[np.ndarray, np.ndarray]:
    """(diffuse, specular) linear RGB ``(res, res, 3)`` renders under one light."""
    return tuple(render_probe(kind, pan_rel_deg, tilt_deg, rgb, camera_tilt_deg, res, spp)[..., :3]
                 for kind in ("diffuse", "specular"))


def pole_inset(pan_rel_deg: float, tilt_deg: float, rgb, camera_tilt_deg: float,
               res: int = 96, spp: int = DEFAULT_SPP) -> np.ndarray:
    """Linear RGBA ``(res, res, 4)`` of the pole and its shadow, to paste on an image."""
    return render_probe("pole", pan_rel_deg, tilt_deg, rgb, camera_tilt_deg, res, spp)


def overlay_pole(image: np.ndarray, inset_rgba: np.ndarray, margin_px: int = 4) -> np.ndarray:
    """Alpha-blend a linear RGBA inset into the top-left corner of a linear ``(H, W, 3)``
    image (inset shrunk to fit if needed); returns a new float32 image."""
    out = np.array(image, dtype=np.float32, copy=True)
    h, w = out.shape[:2]
    size = min(inset_rgba.shape[0], max(1, min(h, w) - 2 * margin_px))
    inset = inset_rgba
    if size != inset_rgba.shape[0]:
        from PIL import Image
        chans = [np.asarray(Image.fromarray(inset_rgba[..., c].astype(np.float32)).resize(
            (size, size), Image.BILINEAR)) for c in range(4)]
        inset = np.stack(chans, -1)
    alpha = np.clip(inset[..., 3:4], 0.0, 1.0)
    y0 = x0 = margin_px
    region = out[y0:y0 + size, x0:x0 + size]
    region[...] = inset[..., :3] * alpha + region * (1.0 - alpha)
    return out


def gt_from_entry(pred) -> tuple[float, float, np.ndarray] | None:
    """Ground truth from an entry's gt_pan_deg / gt_tilt_deg / gt_rgb fields, if present."""
    from relight.predictions import PredictionsError
    keys = ("gt_pan_deg", "gt_tilt_deg", "gt_rgb")
    present = [k for k in keys if k in pred.extra]
    if not present:
        return None
    try:
        pan, tilt = float(pred.extra["gt_pan_deg"]), float(pred.extra["gt_tilt_deg"])
        rgb = np.asarray(pred.extra["gt_rgb"], dtype=np.float64)
        ok = math.isfinite(pan) and math.isfinite(tilt) and rgb.shape == (3,) \
            and np.isfinite(rgb).all() and (rgb >= 0).all() and rgb.max() > 0
    except (KeyError, TypeError, ValueError):
        ok = False
    if not ok:
        raise PredictionsError(f"entry {pred.id!r}: gt_pan_deg, gt_tilt_deg and gt_rgb must all be "
                               "given as finite numbers (rgb non-negative, non-zero)")
    return pan, tilt, rgb / np.linalg.norm(rgb)


def sphere_rows(predictions_path: str, data_dir: str | None, camera_tilt_deg: float,
                res: int, spp: int, limit: int | None = None) -> list[dict]:
    """Rows for :func:`relight.verify.figures.save_spheres_figure` (renders the spheres)."""
    from relight import metrics
    from relight.dataset import read_manifest, safe_join
    from relight.predictions import PredictionsError, read_predictions
    from relight.imageio import read_exr, read_image
    from relight.predictions import resolve_dataset_dir
    from relight.verify.compare import gt_light
    pfile = read_predictions(predictions_path)
    records, dataset_dir = {}, None
    if data_dir or pfile.dataset:
        dataset_dir = resolve_dataset_dir(predictions_path, data_dir, pfile.dataset)
        records = {r.get("id"): r for r in read_manifest(dataset_dir)}
    rows = []
    for pred in pfile.predictions[:limit]:
        record = records.get(pred.id)
        image = None
        if record is not None:
            cam_tilt = float(record["camera"]["tilt_deg"])
            g = gt_light(record)
            gt = (g.pan_rel_deg, g.tilt_deg, np.asarray(g.rgb))
            image = read_exr(safe_join(dataset_dir, record["exr"]))
        else:
            if dataset_dir is not None and "gt_pan_deg" not in pred.extra:
                raise PredictionsError(f"{predictions_path}: entry {pred.id!r}: id not in the manifest "
                                       f"of {dataset_dir} and no gt_* fields")
            cam_tilt = float(pred.extra.get("camera_tilt_deg", camera_tilt_deg))
            gt = gt_from_entry(pred)
            if isinstance(pred.extra.get("image"), str):
                base = os.path.dirname(os.path.abspath(predictions_path))
                image = read_image(os.path.join(base, pred.extra["image"]))[0]
        pan, tilt, rgb = pred.resolve(cam_tilt)
        pred_sph = np.concatenate(sphere_pair(pan, tilt, rgb, cam_tilt, res, spp), axis=1)
        gt_sph, errors = None, None
        if gt is not None:
            gt_sph = np.concatenate(sphere_pair(*gt, cam_tilt, res, spp), axis=1)
            errors = {k: float(v) for k, v in metrics.light_errors(pan, tilt, rgb, *gt).items()}
        rows.append({"id": pred.id, "image": image, "gt_spheres": gt_sph, "pred_spheres": pred_sph,
                     "errors": errors})
    return rows

"""Scoring a model where it matters: photographs with known light, and renders it did not make.

Two kinds of test set, both scored in the camera frame of ``docs/conventions.md`` (x right,
y up, z toward the camera), the only frame a photograph's light is known in:

* a *photo set*: a folder of images with a ``lights.txt`` (the count, then one unit vector
  per light, camera frame, object -> light) and images ``NAME.N.png`` lit by light ``N``
  (``shared/data/psm_objects`` and ``psm_spheres``: :func:`read_photo_set`);
* a *dataset* folder (``relight generate`` output, or its Cycles twin made by
  ``benchmarks/cycles_twin.py``): the true light and camera of every record are known, so
  the direction error is also given in the world frame with the true camera tilt (Table 1's
  figure) beside the camera-frame one with the model's own camera tilt.

Each scored image gives the direction error (degrees), whether its 90% cone covers the
truth (``cone90_deg`` >= error; an out-of-distribution image's cone is 180 degrees) and its
``ood`` flag; :func:`summary` turns them into the table rows of ``bench_photos.py``.
"""
from __future__ import annotations

import os
import re

import numpy as np

from relight import frames, metrics

__all__ = ["SHARED_DATA_ENV", "shared_data_dir", "read_photo_set", "score_photo_set", "score_dataset", "summary",
           "follows_light", "shading_split", "shrinkage", "response_gamma", "MIN_RESPONSE_PIXELS",
           "SURROUNDS", "replace_surround"]

SHARED_DATA_ENV = "RELIGHT_SHARED_DATA"


def shared_data_dir(explicit: str | None = None) -> str:
    """The folder of the real-photo evaluation sets (``psm_objects``, ``psm_spheres``):
    ``explicit`` when given, else ``$RELIGHT_SHARED_DATA``, else ``shared/data`` next to
    the checkout (``<repo>/../shared/data``). A worktree or another clone elsewhere points
    at the same photographs through the variable. The folder may be absent: callers skip."""
    if explicit:
        return explicit
    env = os.environ.get(SHARED_DATA_ENV)
    if env:
        return env
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    return os.path.normpath(os.path.join(repo, "..", "shared", "data"))

PHOTO_NAME = re.compile(r"^(?P<name>[A-Za-z0-9_-]+)\.(?P<light>\d+)\.(png|jpg|jpeg)$", re.IGNORECASE)


def read_photo_set(folder: str, names: tuple[str, ...] | None = None) -> tuple[list[str], np.ndarray]:
    """``(image files, true to-light vectors (N, 3), camera frame)`` of a photo set: every
    ``NAME.N.png`` of ``folder`` (only ``names`` when given) with light ``N`` of its
    ``lights.txt``. Raises :class:`relight.errors.DatasetError` when ``lights.txt`` is
    missing or malformed."""
    from relight.errors import DatasetError
    path = os.path.join(folder, "lights.txt")
    try:
        with open(path) as f:
            values = [float(v) for v in f.read().split()]
        count = int(values[0])
        lights = np.asarray(values[1:], np.float64).reshape(count, 3)
    except (OSError, ValueError, IndexError) as exc:
        raise DatasetError(f"{path}: expected the count, then one x y z line per light ({exc})") from None
    files, truth = [], []
    for fname in sorted(os.listdir(folder)):
        m = PHOTO_NAME.match(fname)
        if not m or (names is not None and m["name"] not in names):
            continue
        k = int(m["light"])
        if k >= count:
            raise DatasetError(f"{os.path.join(folder, fname)}: light {k} is not in {path} ({count} lights)")
        files.append(os.path.join(folder, fname))
        truth.append(lights[k])
    return files, np.asarray(truth, np.float64).reshape(-1, 3)


def _cone_covers(preds: list[dict], err: np.ndarray) -> np.ndarray:
    cones = np.array([p.get("cone90_deg", np.nan) for p in preds], dtype=np.float64)
    return cones >= err


SURROUNDS = ("black", "uniform", "upside-down", "rows", "rows-upside-down")


def replace_surround(image: np.ndarray, mask: np.ndarray, how: str) -> np.ndarray:
    """``image`` (H, W, 3, linear) with everything outside ``mask`` (H, W, bool: the object)
    changed one way, the object's pixels kept exactly: a diagnostic of what in the
    surroundings moves a model's answer (docs/photo.md, ninth round, part 7).

    ``how``: ``"black"``: zero; ``"uniform"``: the surroundings' mean colour everywhere (their
    level kept, their layout gone); ``"upside-down"``: the image's own surroundings flipped
    top to bottom (where the mirrored pixel is object, the mean colour); ``"rows"``: each row
    the mean colour of its own surrounding pixels (the vertical profile kept, everything
    across a row gone); ``"rows-upside-down"``: that profile reversed, bottom to top. A row
    with no surrounding pixels takes the mean colour."""
    x = np.asarray(image)
    m = np.asarray(mask, bool)
    if x.ndim != 3 or x.shape[2] != 3 or m.shape != x.shape[:2]:
        raise ValueError(f"image (H, W, 3) and mask (H, W) expected, got {x.shape} and {m.shape}")
    if how not in SURROUNDS:
        raise ValueError(f"surround: expected one of {', '.join(SURROUNDS)}, got {how!r}")
    if how == "black":
        return x * m[..., None]
    out = ~m
    if not out.any():
        return x.copy()
    mean = x[out].mean(axis=0)
    if how == "uniform":
        fill = np.broadcast_to(mean, x.shape)
    elif how == "upside-down":
        fill = np.where(out[::-1][..., None], x[::-1], mean)
    else:
        count = out.sum(axis=1)
        sums = (x * out[..., None]).sum(axis=1)
        rows = np.where(count[:, None] > 0, sums / np.maximum(count, 1)[:, None], mean)
        if how == "rows-upside-down":
            rows = rows[::-1]
        fill = np.broadcast_to(rows[:, None, :], x.shape)
    return np.where(m[..., None], x, fill)


def _with_surround(files: list[str], how: str, linear: bool = False) -> list[np.ndarray]:
    """Each photo as linear RGB with its surroundings (outside its ``NAME.mask.png``, white
    where the object is) changed by :func:`replace_surround`; ``linear``: 8-bit codes read
    as linear values, not sRGB."""
    from relight.colour import srgb_decode
    from relight.errors import DatasetError
    from relight.imageio import load_image
    out = []
    for f in files:
        mask_path = os.path.join(os.path.dirname(f), PHOTO_NAME.match(os.path.basename(f))["name"] + ".mask.png")
        if not os.path.exists(mask_path):
            raise DatasetError(f"{mask_path}: no mask for {os.path.basename(f)} (needed to change the surroundings)")
        px, enc, _ = load_image(f)
        mask = load_image(mask_path)[0][..., 0] > 0.5
        if mask.shape != px.shape[:2]:
            raise DatasetError(f"{mask_path}: {mask.shape[1]}x{mask.shape[0]} mask for a "
                               f"{px.shape[1]}x{px.shape[0]} photo")
        out.append(replace_surround(srgb_decode(px) if enc == "srgb" and not linear else px, mask, how))
    return out


def score_photo_set(model, folder: str, names: tuple[str, ...] | None = None,
                    camera_tilt_deg: float | None = None, surround: str | None = None,
                    linear: bool = False) -> dict:
    """Predict every image of a photo set (:func:`read_photo_set`) and score it against the
    true light, camera frame. ``camera_tilt_deg``: None = the model's own (camera head; else
    the paper's 45). ``surround``: everything outside the object (its ``NAME.mask.png``)
    changed first by :func:`replace_surround` in that way (``"black"``: the backdrop blacked
    out), a diagnostic of what in the surroundings moves the answer; a network of the objects
    alone always reads them with everything outside the mask black. ``linear``: the photos'
    8-bit codes read as linear values (a camera proportional to the light), not sRGB.
    Returns per-image arrays ``id``, ``group`` (the object: the name before the light's
    number), ``direction_deg``, ``covered``, ``ood``, ``camera_tilt_deg``,
    ``to_light_camera`` and ``true_to_light_camera``."""
    from relight.net.predict import model_surround, predict_arrays, predict_files
    files, truth = read_photo_set(folder, names)
    if surround is None and model_surround(model) == "black":   # a network of the objects alone
        surround = "black"
    if surround is not None:
        preds = predict_arrays(model, _with_surround(files, surround, linear), None if camera_tilt_deg is None else
                               [camera_tilt_deg] * len(files))
        for p, f in zip(preds, files):
            p["id"] = os.path.splitext(os.path.basename(f))[0]
    else:
        preds = predict_files(model, files, camera_tilt_deg, linear=linear)
    pred = np.array([p["to_light_camera"] for p in preds], dtype=np.float64).reshape(-1, 3)
    err = metrics.angle_deg(pred, truth)
    return {"id": [p["id"] for p in preds], "group": [i.split(".")[0] for i in (p["id"] for p in preds)],
            "direction_deg": err, "covered": _cone_covers(preds, err),
            "ood": np.array([bool(p.get("ood", False)) for p in preds]),
            "camera_tilt_deg": np.array([p["camera_tilt_deg"] for p in preds]),
            "to_light_camera": pred, "true_to_light_camera": np.asarray(truth, np.float64).reshape(-1, 3)}


def follows_light(pred, truth) -> tuple[float, float]:
    """Whether predictions follow the light across a set, not only sit near its average:
    Pearson's correlation of the predicted with the true right (x) and up (y) components of
    the camera-frame directions ``(N, 3)``. A constant answer scores NaN (no spread), one that
    tracks the light near 1; a median error alone cannot tell a well-placed constant from
    a reading of the image."""
    pred, truth = np.asarray(pred, np.float64).reshape(-1, 3), np.asarray(truth, np.float64).reshape(-1, 3)
    out = []
    for axis in (0, 1):
        p, t = pred[:, axis], truth[:, axis]
        if len(p) < 3 or np.std(p) < 1e-9 or np.std(t) < 1e-9:
            out.append(float("nan"))
        else:
            out.append(float(np.corrcoef(p, t)[0, 1]))
    return out[0], out[1]


def shrinkage(pred, truth, groups=None) -> dict[str, float]:
    """How far a set of camera-frame answers ``(N, 3)`` is pulled toward an average, and how
    far it is shifted: ``slope_x`` / ``slope_y``, the least-squares slope of the predicted on
    the true right (x) / up (y) component within each group (e.g. one object under every
    light; pooled over the groups, so that the objects' own offsets do not count), 1 for an
    answer that tracks the light, near 0 for one that stays put; ``bias_x`` / ``bias_y``,
    the mean of predicted minus true; ``bias_free_median_deg``, the median error once that
    mean bias is subtracted from every answer (z from the unit norm, toward the camera): a
    diagnostic that uses the truth, what removing the shift alone would give, never a method."""
    pred, truth = np.asarray(pred, np.float64).reshape(-1, 3), np.asarray(truth, np.float64).reshape(-1, 3)
    if not len(pred):
        return dict.fromkeys(("slope_x", "bias_x", "slope_y", "bias_y", "bias_free_median_deg"), float("nan"))
    groups = np.zeros(len(pred), int) if groups is None else np.asarray(groups)
    out = {}
    for axis, name in ((0, "x"), (1, "y")):
        dp = np.concatenate([pred[groups == g, axis] - pred[groups == g, axis].mean() for g in np.unique(groups)])
        dt = np.concatenate([truth[groups == g, axis] - truth[groups == g, axis].mean() for g in np.unique(groups)])
        out[f"slope_{name}"] = float(dp @ dt / (dt @ dt)) if dt @ dt > 1e-12 else float("nan")
        out[f"bias_{name}"] = float(np.mean(pred[:, axis] - truth[:, axis]))
    shifted = pred.copy()
    shifted[:, :2] -= (pred[:, :2] - truth[:, :2]).mean(axis=0)
    shifted[:, 2] = np.sqrt(np.clip(1.0 - (shifted[:, :2] ** 2).sum(axis=1), 0.0, 1.0))
    out["bias_free_median_deg"] = float(np.median(metrics.angle_deg(shifted, truth)))
    return out


def shading_split(pred, truth) -> dict[str, np.ndarray]:
    """A camera-frame direction error split into the part an object's shading fixes and the
    part it leaves open. Seen from the camera, a Lambertian object of unknown shape with its
    occluding contour in view looks the same under a light ``(x, y, z)`` and a bas-relief
    light ``(x, y, z / lambda)`` on a flattened or deepened object (Belhumeur, Kriegman &
    Yuille 1999, the contour fixing the other two parameters of the GBR transform): the
    light's direction in the image plane, ``atan2(y, x)``, is determined, its slant from the
    view axis only by cast shadows, highlights and priors.

    Returns per image ``image_angle_deg`` (the absolute difference of the two in-image
    directions, 0-180) and ``slant_error_deg`` (predicted minus true slant, signed:
    positive = the light placed further from the view axis). Unit vectors ``(N, 3)``;
    for a light on the view axis the in-image direction is undefined (NaN)."""
    pred, truth = np.asarray(pred, np.float64).reshape(-1, 3), np.asarray(truth, np.float64).reshape(-1, 3)
    ang = np.degrees(np.arctan2(pred[:, 1], pred[:, 0]) - np.arctan2(truth[:, 1], truth[:, 0]))
    image_angle = np.abs((ang + 180.0) % 360.0 - 180.0)
    on_axis = (np.hypot(pred[:, 0], pred[:, 1]) < 1e-9) | (np.hypot(truth[:, 0], truth[:, 1]) < 1e-9)
    image_angle[on_axis] = np.nan

    def slant(v):
        return np.degrees(np.arccos(np.clip(v[:, 2] / np.linalg.norm(v, axis=1), -1.0, 1.0)))
    return {"image_angle_deg": image_angle, "slant_error_deg": slant(pred) - slant(truth)}


MIN_RESPONSE_PIXELS = 50   # lit pixels a response fit needs (a ball of radius 5 px holds about 80)


def response_gamma(image: np.ndarray, mask: np.ndarray, to_light_camera, min_cos: float = 0.05) -> dict:
    """The camera's response curve read off a diffuse ball of known light: the fit of the
    stored codes ``v`` (``image``, ``(H, W)`` or ``(H, W, C)`` in [0, 1], channels averaged)
    inside ``mask`` (the ball, seen near-orthographically: its circle from the mask's area and
    centroid) to ``a * max(0, n . l) ** (1 / gamma) + b``, with ``l`` the light (camera frame,
    x right, y up, z toward the camera) and ``n`` the ball's normals. A camera that stores
    codes proportional to the light gives ``gamma`` 1, an sRGB or display gamma one about 2.2.
    Pixels near the rim (``n . z < 0.2``), in the shadow (``n . l < min_cos``) and clipped
    (``v >= 0.98``) are left out. Returns ``gamma``, ``a``, ``b`` and ``rms`` (of the fit).
    Raises ValueError when the mask does not match the image or leaves fewer than
    :data:`MIN_RESPONSE_PIXELS` lit pixels to fit."""
    from scipy.optimize import least_squares
    v = np.asarray(image, np.float64)
    v = v.mean(axis=2) if v.ndim == 3 else v
    mask = np.asarray(mask, bool)
    if mask.shape != v.shape:
        raise ValueError(f"mask {mask.shape} does not match the image {v.shape}")
    ys, xs = np.nonzero(mask)
    if len(xs) < MIN_RESPONSE_PIXELS:
        raise ValueError(f"the mask holds {len(xs)} pixels; a response fit needs {MIN_RESPONSE_PIXELS}")
    cx, cy, r = xs.mean() + 0.5, ys.mean() + 0.5, np.sqrt(mask.sum() / np.pi)
    yy, xx = np.mgrid[0:mask.shape[0], 0:mask.shape[1]]
    nx, ny = (xx + 0.5 - cx) / r, -(yy + 0.5 - cy) / r
    nz = np.sqrt(np.clip(1.0 - nx ** 2 - ny ** 2, 0.0, 1.0))
    shade = np.stack([nx, ny, nz], -1) @ np.asarray(to_light_camera, np.float64)
    use = mask & (nz > 0.2) & (shade > min_cos) & (v < 0.98)
    s, code = shade[use], v[use]
    if len(s) < MIN_RESPONSE_PIXELS:
        raise ValueError(f"{len(s)} lit, unclipped pixels on the ball; a response fit needs {MIN_RESPONSE_PIXELS}")

    def residual(p):
        return p[0] * s ** (1.0 / p[1]) + p[2] - code
    fit = least_squares(residual, [0.8, 1.5, 0.0], bounds=([0.0, 0.3, -0.5], [10.0, 5.0, 0.5]))
    a, gamma, b = (float(x) for x in fit.x)
    return {"gamma": gamma, "a": a, "b": b, "rms": float(np.sqrt(np.mean(fit.fun ** 2)))}


def score_dataset(model, data_dir: str, split: str = "all", limit: int | None = None) -> dict:
    """Score a model on a dataset folder: per image ``direction_deg`` (camera frame, the
    model's own camera tilt where it has a camera head, else the true one),
    ``world_direction_deg`` (Table 1's direction error: decoded with the true camera tilt),
    ``colour_deg``, ``covered``, ``ood``, ``camera_tilt_error_deg``, and the camera-frame
    directions ``to_light_camera`` (predicted) and ``true_to_light_camera``."""
    from relight.net.data import model_dataset
    from relight.net.evaluate import decode_outputs, target_frame_of
    from relight.net.predict import _predict_inputs
    ds = model_dataset(model, data_dir, split, cache=False)
    if limit is not None:
        ds.keep_first([min(limit, n) for n in ds.part_sizes()])
    truth = ds.truth()
    inputs = [ds.image_tensor(i) for i in range(len(ds))]
    own = bool(getattr(model, "has_camera", False))
    preds = _predict_inputs(model, inputs, None if own else truth["camera_tilt_deg"])
    true_cam = np.stack([frames.world_to_camera(frames.direction(p, t), c) for p, t, c in
                         zip(truth["pan_rel_deg"], truth["tilt_deg"], truth["camera_tilt_deg"])]).reshape(-1, 3)
    pred_cam = np.array([p["to_light_camera"] for p in preds], dtype=np.float64).reshape(-1, 3)
    err = metrics.angle_deg(pred_cam, true_cam)
    y = np.array([p["y"] for p in preds], dtype=np.float64).reshape(-1, 7)
    # the paper's y with the tilt the prediction used -> the network's own target -> decoded with the true tilt
    frame = target_frame_of(model)
    raw = frames.y_to_target(y, np.array([p["camera_tilt_deg"] for p in preds], dtype=np.float64), frame)
    pan_w, tilt_w = decode_outputs(raw, truth["camera_tilt_deg"], frame)[:2]
    world = metrics.direction_error_deg(pan_w, tilt_w, truth["pan_rel_deg"], truth["tilt_deg"])
    rgb = np.array([p["rgb"] for p in preds], dtype=np.float64).reshape(-1, 3)
    return {"id": [r["id"] for r in ds.records], "direction_deg": err, "world_direction_deg": np.asarray(world),
            "colour_deg": np.asarray(metrics.colour_error_deg(rgb, truth["rgb"])),
            "covered": _cone_covers(preds, err), "ood": np.array([bool(p.get("ood", False)) for p in preds]),
            "camera_tilt_error_deg": np.abs(np.array([p["camera_tilt_deg"] for p in preds]) - truth["camera_tilt_deg"]),
            "to_light_camera": pred_cam, "true_to_light_camera": true_cam}


def summary(scores: dict) -> dict:
    """Median and mean of each error, cone coverage (share of images whose 90% cone holds the
    truth, NaN for a model without cones), the share flagged out-of-distribution and, for a
    photo set, how well the predictions follow the light (:func:`follows_light`:
    ``follow_x_r``, ``follow_y_r``) and the error split by :func:`shading_split`
    (``image_angle_deg_median``; ``slant_error_deg_median`` of the absolute slant error and
    ``slant_bias_deg``, the median signed one)."""
    out = {"n": int(len(scores["direction_deg"]))}
    for key in ("direction_deg", "world_direction_deg", "colour_deg", "camera_tilt_error_deg"):
        if key in scores and len(scores[key]):
            out[f"{key}_median"] = float(np.median(scores[key]))
            out[f"{key}_mean"] = float(np.mean(scores[key]))
    covered = np.asarray(scores["covered"], dtype=bool)
    out["cone90_coverage"] = float(covered.mean()) if covered.size else float("nan")
    out["ood_share"] = float(np.mean(scores["ood"])) if len(scores["ood"]) else 0.0
    if "true_to_light_camera" in scores:
        pred, truth = scores["to_light_camera"], scores["true_to_light_camera"]
        out["follow_x_r"], out["follow_y_r"] = follows_light(pred, truth)
        nan, split = float("nan"), shading_split(pred, truth)
        slant = split["slant_error_deg"]
        out["image_angle_deg_median"] = float(np.nanmedian(split["image_angle_deg"])) if len(slant) else nan
        out["slant_bias_deg"] = float(np.median(slant)) if len(slant) else nan
        out["slant_error_deg_median"] = float(np.median(np.abs(slant))) if len(slant) else nan
    if "group" in scores and len(scores["group"]):
        out |= shrinkage(scores["to_light_camera"], scores["true_to_light_camera"], scores["group"])
    return out

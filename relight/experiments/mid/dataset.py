"""A MID-like dataset (``relight generate --preset mid``) and the paper's Tables 4-5.

Scenes, rendering and the *physical* ground truth are in :mod:`relight.experiments.mid.scene`.
This module writes the dataset (the format of :mod:`relight.dataset` and the machinery of
:mod:`relight.generator.run`: folder lock, atomic files, an append-only manifest, a card,
resume by re-running the same command)
and computes the *procedure's* ground truth: the sphere procedure
(:func:`relight.probe.run.run_probe`, perspective, the spheres' circles given as a
person marks them) on the rendered linear image, with the paper's **reference-image
correction**: the procedure's pan/tilt on the scene's reference image (flash along the
optical axis) are compared with the assumed ones and that pan/tilt offset is added to
every image of the scene. The paper assumes the light mounted 10 deg above the camera;
our rig's flash is :data:`relight.experiments.mid.scene.FLASH_OFFSET_M` above it, which is 2-6 deg
seen from the spheres at 1.2-3.2 m, so the assumed direction is the one from the chrome
sphere to the flash, the sphere's distance following from its outline and its known
radius (MID's probes are of known size too): :func:`expected_reference`.

Layout (besides ``dataset.json`` and ``manifest.jsonl``): ``images/ID.png`` (8-bit sRGB,
auto-exposed: median luminance 0.18), ``masked/ID.png`` (the same with both spheres
painted out by inpainting), ``exr/ID.exr`` (linear), ``probes/ID.exr`` (the probe
photograph the procedure measures: ``probe_zoom`` x the resolution, rendered only around
the two spheres, black elsewhere -- MID's photographs are large, its network inputs small), ``scenes/SSSS.json`` (the room,
the reference measurement; written last, it marks the scene finished). Image ids are
``SSSS_DD`` (scene, flash direction index); the reference images are ``SSSS_ref`` (files
only, no record). The record's ``light``, ``pan_rel_deg`` and ``y`` are the procedure's
(what the network trains on, as in the paper); ``physical`` and ``procedure`` hold both
ground truths.
"""
from __future__ import annotations

__all__ = [
    "MID_FORMAT", "REF_ELEVATION_DEG", "MASK_DILATE_PX", "MidStats", "sphere_mask", "masked_srgb8",
    "exposure_of", "run_procedure", "chrome_distance_m", "expected_reference", "reference_correction",
    "corrected", "mid_config", "generate_mid", "PAPER_TABLE4", "PAPER_TABLE5", "TABLE_METRICS", "is_front",
    "truth_arrays", "errors_against", "table4_rows", "table5_rows", "format_table4", "format_table5",
    "predict_split", "score", "procedure_vs_physical",
]

import json
import math
import os
import time
from dataclasses import dataclass

import numpy as np

from relight import frames
from relight.colour import luminance
from relight.errors import ConfigError, DatasetError, ProbeError
from relight.experiments.mid import scene as scene_mid
from relight.experiments.mid.scene import MidConfig
from relight.generator.sampling import read_config_file

MID_FORMAT = "relight.dataset.mid/v1"
REF_ELEVATION_DEG = math.degrees(math.atan(scene_mid.FLASH_OFFSET_M / 2.2))
MASK_DILATE_PX = 1.5


@dataclass
class MidStats:
    scenes_written: int = 0
    scenes_skipped: int = 0
    images: int = 0
    failed_probe: int = 0
    total_s: float = 0.0


def _id(scene: int, k) -> str:
    return f"{scene:04d}_{k if isinstance(k, str) else f'{k:02d}'}"


def sphere_mask(cfg: MidConfig, scene: scene_mid.MidScene, dilate_px: float = MASK_DILATE_PX) -> np.ndarray:
    """Boolean ``(res, res)`` mask of both spheres' image outlines, grown by ``dilate_px``."""
    import cv2
    from relight.probe.geometry import outline_polygon
    camera = scene_mid.probe_camera(cfg)
    mask = np.zeros((cfg.res, cfg.res), np.uint8)
    for which in ("chrome", "gray"):
        x, y = outline_polygon(camera, scene_mid.probe_sphere(scene, which), 128)
        pts = np.round(np.stack([x - 0.5, y - 0.5], -1) * 16).astype(np.int32)
        cv2.fillPoly(mask, [pts], 1, cv2.LINE_8, shift=4)
    k = int(math.ceil(dilate_px))
    if k:
        mask = cv2.dilate(mask, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * k + 1, 2 * k + 1)))
    return mask.astype(bool)


def masked_srgb8(srgb8: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``srgb8`` with the ``mask`` pixels painted out (OpenCV Telea inpainting)."""
    import cv2
    return cv2.inpaint(np.ascontiguousarray(srgb8), mask.astype(np.uint8), 3, cv2.INPAINT_TELEA)


def exposure_of(image: np.ndarray) -> float:
    """Auto exposure: the factor that brings the median luminance to 0.18."""
    lum = luminance(np.asarray(image, np.float64))
    med = float(np.median(lum))
    return scene_mid.EXPOSURE_KEY / med if med > 0 else 1.0


def run_procedure(exr_path: str, cfg: MidConfig, scene: scene_mid.MidScene) -> dict:
    """The sphere procedure on one linear probe photograph (``probe_zoom`` x the image
    size), the spheres' true outline circles given (MID ships its probes' positions)."""
    from relight.probe.run import ProbeConfig, run_probe
    from relight.probe.geometry import outline_circle
    camera = scene_mid.probe_camera(cfg, cfg.probe_zoom)
    circles = {w: outline_circle(camera, scene_mid.probe_sphere(scene, w)) for w in ("chrome", "gray")}
    pc = ProbeConfig(chrome=exr_path, chrome_circle=circles["chrome"], diffuse=exr_path,
                     diffuse_circle=circles["gray"], fov_deg=cfg.fov_deg, camera_tilt_deg=scene.camera_tilt_deg,
                     refine=False)
    return run_probe(pc).entry


def chrome_distance_m(entry: dict, cfg: MidConfig, radius_m: float) -> float:
    """Distance from the camera to the chrome sphere's centre, metres, from the outline
    circle the procedure used (``chrome_circle``, probe-photograph pixels) and the
    sphere's known radius: ``radius / sin(half-angle of its tangent cone)``."""
    from relight.probe.geometry import sphere_from_circle
    sphere = sphere_from_circle(scene_mid.probe_camera(cfg, cfg.probe_zoom), *entry["chrome_circle"])
    return float(radius_m) / float(sphere.radius)


def expected_reference(entry: dict, camera_tilt_deg: float, distance_m: float | None = None) -> tuple[float, float]:
    """The assumed ``(pan_rel, tilt)`` of the reference image: from the chrome sphere
    (``distance_m`` from the camera along ``chrome_centre_camera``) to the flash,
    :data:`relight.experiments.mid.scene.FLASH_OFFSET_M` above the camera (world up). Without a
    distance: toward the camera raised by :data:`REF_ELEVATION_DEG` (the sphere at 2.2 m).

    A sphere on the optical axis 2.2 m away, camera level: the flash is 3.1 deg above
    the horizon toward the camera (pan 0), at 1.2 m 5.7 deg:

    >>> p, t = expected_reference({"chrome_centre_camera": [0.0, 0.0, -1.0]}, 0.0)
    >>> round(p, 6) % 360, round(t, 2)
    (0.0, 3.12)
    >>> p, t = expected_reference({"chrome_centre_camera": [0.0, 0.0, -1.0]}, 0.0, distance_m=2.2)
    >>> round(p, 6) % 360, round(t, 2)
    (0.0, 3.12)
    >>> round(expected_reference({"chrome_centre_camera": [0.0, 0.0, -1.0]}, 0.0, distance_m=1.2)[1], 2)
    5.71
    """
    to_cam = -np.asarray(entry["chrome_centre_camera"], np.float64)
    to_cam /= np.linalg.norm(to_cam)
    if distance_m is not None:
        world_up_camera = frames.world_to_camera([0.0, 0.0, 1.0], camera_tilt_deg)
        to_flash = to_cam * float(distance_m) + scene_mid.FLASH_OFFSET_M * world_up_camera
        return frames.camera_to_pan_tilt(to_flash / np.linalg.norm(to_flash), camera_tilt_deg)
    up = np.array([0.0, 1.0, 0.0]) - to_cam[1] * to_cam
    up /= np.linalg.norm(up)
    e = math.radians(REF_ELEVATION_DEG)
    return frames.camera_to_pan_tilt(to_cam * math.cos(e) + up * math.sin(e), camera_tilt_deg)


def reference_correction(ref_entry: dict, camera_tilt_deg: float,
                         distance_m: float | None = None) -> tuple[float, float]:
    """``(dpan, dtilt)`` degrees to add to the procedure's pan/tilt of a scene's images."""
    pe, te = expected_reference(ref_entry, camera_tilt_deg, distance_m)
    pr, tr = frames.camera_to_pan_tilt(ref_entry["to_light_camera"], camera_tilt_deg)
    return float(frames.wrap180(pe - pr)), float(te - tr)


def corrected(entry: dict, camera_tilt_deg: float, correction: tuple[float, float]) -> tuple[float, float]:
    """The procedure's ``(pan_rel, tilt)`` of an image with the reference correction."""
    p, t = frames.camera_to_pan_tilt(entry["to_light_camera"], camera_tilt_deg)
    return frames.fold_over_zenith(p + correction[0], t + correction[1])


def _unit(v) -> list:
    v = np.asarray(v, np.float64)
    return (v / np.linalg.norm(v)).tolist()


def _write_card(out: str, seed: int, cfg: MidConfig, scenes: int, n_records: int) -> None:
    from relight.dataset import CARD, check_same_settings, read_card
    from relight.fileio import write_json
    settings = {"format": MID_FORMAT, "preset": "mid", "seed": int(seed), "config": cfg.to_dict()}
    path = os.path.join(out, CARD)
    if os.path.isfile(path) and n_records:
        old = read_card(out)
        check_same_settings(out, {k: old.get(k) for k in settings}, settings)
        scenes = max(scenes, int(old.get("scenes", 0)))
    write_json(path, {**settings, "scenes": int(scenes),
                      "flash_directions": [list(d) for d in scene_mid.FLASH_DIRECTIONS],
                      "description": "MID-like synthetic dataset (relight): indoor rooms, chrome + gray "
                                     "sphere, flash above the camera turned to 25 directions; records "
                                     "carry the physical and the sphere procedure's ground truths",
                      "split_rule": "per scene: i % 5 == 4 test, i % 10 == 2 val, else train",
                      "reference_expected": "from the chrome sphere (distance from its outline and known "
                                            f"radius) to the flash {scene_mid.FLASH_OFFSET_M} m above the camera"})


def _render_room(out: str, cfg: MidConfig, seed: int, index: int, stats: MidStats) -> tuple[list[dict], dict]:
    """Render, measure and write one scene's image files; returns its records and the
    scene file's content (written by the caller once the records are in)."""
    from relight.imageio import to_srgb8, write_exr, write_srgb8
    scene = scene_mid.sample_mid_scene(cfg, seed, index)
    renderer = scene_mid.MidRenderer(scene, cfg)
    mask = sphere_mask(cfg, scene)
    split = scene_mid.split_of_scene(index)
    tilt = scene.camera_tilt_deg

    def shoot(k, axis, render_seed):
        image, probe, truth = renderer.render(axis, render_seed)
        iid = _id(index, k)
        write_exr(os.path.join(out, "exr", f"{iid}.exr"), image)
        exr = os.path.join(out, "probes", f"{iid}.exr")
        write_exr(exr, probe)
        expo = exposure_of(image)
        srgb = to_srgb8(image, expo)
        write_srgb8(os.path.join(out, "images", f"{iid}.png"), srgb)
        write_srgb8(os.path.join(out, "masked", f"{iid}.png"), masked_srgb8(srgb, mask))
        try:
            entry = run_procedure(exr, cfg, scene)
        except ProbeError as exc:
            entry = {"error": str(exc)}
        return iid, truth, entry, expo

    base = (int(seed) * 1_000_003 + index * 101) % (2 ** 31)
    ref_id, ref_truth, ref_entry, _ = shoot(scene_mid.REFERENCE, scene_mid.reference_axis(tilt), base)
    if "error" in ref_entry:
        correction, note = (0.0, 0.0), f"reference probe failed: {ref_entry['error']}"
    else:
        distance = chrome_distance_m(ref_entry, cfg, scene.sphere_radius[0])
        correction, note = reference_correction(ref_entry, tilt, distance), "ok"
    records, failed = [], {}
    for k in cfg.directions:
        yaw, el = scene_mid.FLASH_DIRECTIONS[k]
        iid, truth, entry, expo = shoot(k, scene_mid.flash_axis(yaw, el), base + 2 * (k + 1))
        stats.images += 1
        phys_y = frames.encode_y(truth["pan_rel_deg"], truth["tilt_deg"], np.asarray(truth["rgb"]), tilt)
        physical = {**truth, "y": [float(v) for v in phys_y]}
        if "error" in entry:
            stats.failed_probe += 1
            failed[iid] = entry["error"]
            continue    # the procedure found no light: no ground truth, no record (as a person would drop it)
        pan, t = corrected(entry, tilt, correction)
        rgb = _unit(entry["rgb"])
        y = frames.encode_y(pan, t, np.asarray(rgb), tilt)
        raw_pan, raw_tilt = entry["pan_deg"], entry["tilt_deg"]
        records.append({
            "id": iid, "image": f"images/{iid}.png", "image_masked": f"masked/{iid}.png",
            "exr": f"exr/{iid}.exr", "scene": f"scenes/{index:04d}.json", "split": split,
            "scene_index": index, "preset": "mid",
            "light": {"pan_deg": float(pan), "tilt_deg": float(t), "rgb": rgb, "source": "procedure"},
            "camera": {"pan_deg": 0.0, "tilt_deg": tilt, "fov_deg": cfg.fov_deg,
                       "position_m": scene.camera_position.tolist()},
            "pan_rel_deg": float(pan), "y": [float(v) for v in y], "seed": int(seed),
            "flash": {"index": k, "yaw_deg": yaw, "elevation_deg": el},
            "exposure": expo,
            "physical": physical,
            "procedure": {"pan_rel_deg": float(pan), "tilt_deg": float(t), "rgb": rgb,
                          "raw_pan_rel_deg": raw_pan, "raw_tilt_deg": raw_tilt,
                          "to_light_camera": entry["to_light_camera"], "quality_deg": entry.get("quality_deg"),
                          "chrome_circle": entry.get("chrome_circle"), "diffuse_circle": entry.get("diffuse_circle"),
                          "reference_correction_deg": list(correction)},
        })
    return records, {
        "format": MID_FORMAT, "scene": scene.to_dict(), "config": cfg.to_dict(), "reference": {
            "id": ref_id, "physical": ref_truth, "procedure": ref_entry, "correction_deg": list(correction),
            "note": note}, "records": [r["id"] for r in records], "procedure_failed": failed}


def mid_config(path: str | None = None, refused: dict | None = None, **overrides) -> MidConfig:
    """The settings of ``generate --preset mid``: a JSON file of :class:`MidConfig` fields
    (optional) and command-line overrides (None: keep). ``refused`` maps options that do
    not apply to this preset to whether they were given (one line naming the first)."""
    for name, given in (refused or {}).items():
        if given:
            raise ConfigError(f"{name} does not apply to --preset mid")
    d = read_config_file(path) if path is not None else {}
    d.update({k: v for k, v in overrides.items() if v is not None})
    try:
        return MidConfig.from_dict(d)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, ConfigError):
            raise
        raise ConfigError(f"mid preset: bad settings ({str(exc).splitlines()[0]})") from None


def generate_mid(out_dir: str | os.PathLike, scenes: int, seed: int = 0, cfg: MidConfig | None = None,
                 progress: bool = True, threads: int | None = None) -> MidStats:
    """Generate (or resume) a MID-like dataset of ``scenes`` rooms in ``out_dir``.

    Scene ``i`` depends only on (seed, i, cfg). A scene is finished when its
    ``scenes/SSSS.json`` exists (written after its records are in the manifest);
    re-running the same command skips finished scenes and redoes the others (a record
    appended twice with identical content is read once and repaired).
    """
    from tqdm import tqdm
    from relight import backend
    from relight.dataset import MANIFEST, SEED_LIMIT, read_manifest
    from relight.fileio import FolderLock, append_line, remove_temps, write_json
    cfg = cfg or MidConfig()
    if isinstance(scenes, bool) or not isinstance(scenes, int) or not 0 <= scenes <= 9999:
        raise DatasetError(f"scenes must be an integer in [0, 9999], got {scenes!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < SEED_LIMIT:
        raise DatasetError(f"seed must be an integer in [0, 2**32), got {seed!r}")
    out = os.fspath(out_dir)
    lock = FolderLock.take(out, "dataset")[0]
    stats = MidStats()
    t0 = time.perf_counter()
    try:
        subs = ("images", "masked", "exr", "probes", "scenes")
        remove_temps(out, ("",) + subs)
        for sub in subs:
            os.makedirs(os.path.join(out, sub), exist_ok=True)
        manifest_path = os.path.join(out, MANIFEST)
        n_records = len(read_manifest(out, repair=True)) if os.path.exists(manifest_path) else 0
        _write_card(out, seed, cfg, scenes, n_records)
        todo = [i for i in range(scenes) if not os.path.isfile(os.path.join(out, "scenes", f"{i:04d}.json"))]
        stats.scenes_skipped = scenes - len(todo)
        if todo:
            backend.init(threads=threads)
        bar = tqdm(total=len(todo) * len(cfg.directions), unit="img", disable=not progress, desc="generate mid")
        with open(manifest_path, "ab") as manifest:
            for i in todo:
                records, doc = _render_room(out, cfg, seed, i, stats)
                append_line(manifest, b"".join((json.dumps(r) + "\n").encode() for r in records), manifest_path)
                write_json(os.path.join(out, "scenes", f"{i:04d}.json"), doc)   # marks the scene finished
                stats.scenes_written += 1
                bar.update(len(cfg.directions))
        bar.close()
    finally:
        lock.release()
    stats.total_s = time.perf_counter() - t0
    return stats


# --------------------------------------------------------------------------- tables
PAPER_TABLE4 = {("masked", "mean"): (21.38, 10.14, 22.72, 0.63), ("masked", "median"): (13.74, 7.64, 17.80, 0.40),
                ("unmasked", "mean"): (14.28, 6.96, 15.44, 0.36), ("unmasked", "median"): (8.20, 4.83, 10.83, 0.24)}
PAPER_TABLE5 = {"front": (11.51, 6.33, 13.09, 0.34), "back": (32.90, 11.21, 31.23, 0.52)}
TABLE_METRICS = ("pan", "tilt", "direction", "colour")


def is_front(pan_rel_deg) -> np.ndarray:
    """Front light: from the camera's half of the horizon (|wrap180(pan_rel)| < 90).

    >>> is_front(np.array([0.0, 89.0, 91.0, 180.0, 300.0])).tolist()
    [True, True, False, False, True]
    """
    return np.abs(frames.wrap180(np.asarray(pan_rel_deg, np.float64))) < 90.0


def truth_arrays(records: list[dict], which: str) -> dict:
    """``pan_rel_deg``, ``tilt_deg``, ``rgb`` arrays of the ``physical`` or ``procedure`` truth."""
    return {"pan_rel_deg": np.array([r[which]["pan_rel_deg"] for r in records], np.float64),
            "tilt_deg": np.array([r[which]["tilt_deg"] for r in records], np.float64),
            "rgb": np.array([r[which]["rgb"] for r in records], np.float64).reshape(-1, 3)}


def errors_against(pred: dict, truth: dict) -> dict:
    """Per-image errors (degrees) of predictions ``{pan_rel_deg, tilt_deg, rgb}``."""
    from relight import metrics
    return metrics.light_errors(pred["pan_rel_deg"], pred["tilt_deg"], pred["rgb"],
                                truth["pan_rel_deg"], truth["tilt_deg"], truth["rgb"])


def table4_rows(errors: dict) -> dict:
    """``{"mean": (pan, tilt, direction, colour), "median": (...)}`` of per-image errors."""
    return {stat: tuple(float(getattr(np, stat)(errors[m])) if len(errors[m]) else float("nan")
                        for m in TABLE_METRICS) for stat in ("mean", "median")}


def table5_rows(errors: dict, truth: dict, stat: str = "mean") -> dict:
    """``{"front": (...), "back": (...), "n_front", "n_back"}``: the errors split by the
    truth's light side (:func:`is_front`); ``stat`` mean (the paper's) or median."""
    front = is_front(truth["pan_rel_deg"])
    out = {}
    for name, sel in (("front", front), ("back", ~front)):
        out[name] = tuple(float(getattr(np, stat)(np.asarray(errors[m])[sel])) if sel.any() else float("nan")
                          for m in TABLE_METRICS)
        out[f"n_{name}"] = int(sel.sum())
    return out


def format_table4(results: dict) -> str:
    """Markdown Table 4: ``results[(images, truth)] = table4_rows(...)`` beside the paper."""
    lines = ["| Dataset (Error) | ground truth | Pan | Tilt | Direction | Colour | paper: Pan | Tilt | Direction | Colour |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for images in ("masked", "unmasked"):
        for stat in ("mean", "median"):
            for truth in ("procedure", "physical"):
                if (images, truth) not in results:
                    continue
                ours = results[(images, truth)][stat]
                paper = PAPER_TABLE4[(images, stat)]
                lines.append(f"| {images.capitalize()} MID-like ({stat.capitalize()}) | {truth} | "
                             + " | ".join(f"{v:.2f}" for v in ours) + " | "
                             + " | ".join(f"{v:.2f}" for v in paper) + " |")
    return "\n".join(lines)


def format_table5(results: dict, label: str = "") -> str:
    """Markdown Table 5: ``results[truth] = table5_rows(...)`` beside the paper's."""
    lines = [f"| Light position{label} | ground truth | n | Pan | Tilt | Direction | Colour | paper: Pan | Tilt | Direction | Colour |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for side in ("front", "back"):
        for truth, rows in results.items():
            lines.append(f"| {side.capitalize()} | {truth} | {rows[f'n_{side}']} | "
                         + " | ".join(f"{v:.2f}" for v in rows[side]) + " | "
                         + " | ".join(f"{v:.2f}" for v in PAPER_TABLE5[side]) + " |")
    return "\n".join(lines)


def predict_split(model, data_dir: str, image_key: str = "image", split: str = "test", res: int | None = None):
    """A model's predictions on one split of a MID-like dataset: ``(records, pred)`` with
    ``pred = {pan_rel_deg, tilt_deg, rgb}`` decoded with each record's camera tilt."""
    from relight.net.data import LightDataset
    from relight.net.evaluate import decode_outputs, run_model, target_frame_of
    ds = LightDataset(data_dir, split, res or model.config.res, image_key=image_key)
    if len(ds) == 0:
        raise DatasetError(f"{data_dir}: no records in split {split!r}")
    y = run_model(model, ds, 64)
    pan, tilt, rgb = decode_outputs(y, np.array([r["camera"]["tilt_deg"] for r in ds.records]),
                                    target_frame_of(model))
    return ds.records, {"pan_rel_deg": np.asarray(pan), "tilt_deg": np.asarray(tilt), "rgb": np.asarray(rgb)}


def score(records: list[dict], pred: dict) -> dict:
    """Tables 4 and 5 rows of predictions against both ground truths:
    ``{truth: {"table4": ..., "table5": ..., "table5_median": ...}}``."""
    out = {}
    for which in ("procedure", "physical"):
        truth = truth_arrays(records, which)
        err = errors_against(pred, truth)
        out[which] = {"table4": table4_rows(err), "table5": table5_rows(err, truth),
                      "table5_median": table5_rows(err, truth, "median")}
    return out


def procedure_vs_physical(records: list[dict], corrected: bool = True) -> dict:
    """The procedure's ground truth scored against the physical one, split by the
    physical light's side: ``{"all"|"front"|"back": {"mean"|"median": (pan, tilt, direction, colour)}, "n_*"}``.
    ``corrected=False`` scores the procedure's directions before the reference-image correction."""
    phys = truth_arrays(records, "physical")
    proc = truth_arrays(records, "procedure")
    if not corrected:
        proc["pan_rel_deg"] = np.array([r["procedure"]["raw_pan_rel_deg"] for r in records], np.float64)
        proc["tilt_deg"] = np.array([r["procedure"]["raw_tilt_deg"] for r in records], np.float64)
    err = errors_against(proc, phys)
    front = is_front(phys["pan_rel_deg"])
    out = {}
    for name, sel in (("all", np.ones(len(front), bool)), ("front", front), ("back", ~front)):
        out[name] = table4_rows({m: np.asarray(err[m])[sel] for m in TABLE_METRICS})
        out[f"n_{name}"] = int(sel.sum())
    return out

"""The physically based verifier: re-render each scene under its predicted light.

For every prediction of a ``relight.predictions/v1`` or ``/v2`` file this module

1. finds the image's record in the dataset manifest and loads its scene file;
2. resolves the prediction with the image's camera tilt (``Prediction.resolve``);
3. renders (b), the same scene (camera, geometry, materials, resolution, samples
   and seed) under the predicted light. A prediction holds only a direction and a
   chromaticity, so the light's **distance and strength are taken from the ground
   truth** (:data:`STRENGTH_NOTE`);
4. renders the ground-truth scene again with another seed: two renders of the same
   light, whose difference is the Monte Carlo **noise floor** of the image errors;
5. reads (a), the original linear EXR, and computes the light errors
   (:func:`relight.metrics.light_errors`, degrees) and image errors (a) vs (b) in
   linear space (:func:`relight.verify.imagemetrics.image_errors`) beside the noise
   floor (a) vs (a');
6. scores that mean the same for a point light and an environment map: one global
   scale fitted of (b) to (a), then relative RMSE, per-channel scale-invariant RMSE and
   the mean per-pixel RGB angle (:func:`relight.verify.imagemetrics.light_scores`), and
   the shadow term (:mod:`relight.verify.shadows`: soft IoU of the occluded-fraction
   images from exact ray tests).

An **environment-map** entry (v2, :mod:`relight.verify.envmap`) is re-rendered with
Mitsuba's ``envmap`` emitter in place of the point light (the map turned into the world
by its frame and the scene's camera), at the scene's resolution, sample count and seed;
its light errors are those of the map's dominant light, so both kinds share Table 1.
A map's exposure is its estimator's own, so its (b) is shown and measured after the
fitted scale (the ``scale`` column says by how much). Mitsuba's map is infinitely far,
the dataset's point light 20-50 m away inside the room, so even the true light made a
map cannot give (a) back: with ``map_floor`` each map entry also renders that map (the
**map floor**, ``map_floor_*`` columns), the least error any map reaches on that scene. An entry with
a map and a point light is verified as its map.

Loaded Mitsuba scenes are reused through one :class:`relight.scene.build.SceneBuilder`
(one loaded scene per structure); each render uses every Dr.Jit thread. Errors that a
bad input causes raise :class:`CompareError` (a ``PredictionsError``: one line naming
the entry, exit 2 in the CLI) unless ``skip_bad`` collects them instead.
"""
from __future__ import annotations

__all__ = [
    "NOISE_SEED_OFFSET", "STRENGTH_NOTE", "IMAGE_METRICS", "CompareError", "Light", "ImageComparison",
    "Comparison", "gt_light", "Task", "prepare", "compare_one", "BAD_INPUT",
    "compare_predictions", "moved_light_predictions",
]

import os
import time
from dataclasses import dataclass, field

import numpy as np

from relight import frames, metrics
from relight.dataset import DatasetError, load_spec, read_manifest, safe_join
from relight.predictions import Prediction, PredictionsError, read_predictions, resolve_dataset_dir
from relight.imageio import ImageError, read_exr
from relight.scene.spec import SceneFileError
from relight.verify.imagemetrics import image_errors, light_scores

NOISE_SEED_OFFSET = 1_000_003   # seed of the noise-floor render = record seed + this
STRENGTH_NOTE = ("A prediction gives only the light's direction and chromaticity; the "
                 "re-render takes the light's distance (r_m) and strength from the ground "
                 "truth scene.")
IMAGE_METRICS = ("rmse", "psnr_db", "ssim")
LIGHT_SCORES = ("rel_rmse", "si_rmse", "rgb_angle_deg")   # after the fitted global scale
KINDS = ("point", "envmap")
ENVMAP_NOTE = ("Environment maps are re-rendered with Mitsuba's envmap emitter (a light at "
               "infinity); their direction and colour errors are those of the map's dominant "
               "light, and (b) is scaled by the one fitted global scale.")


class CompareError(PredictionsError):
    """A prediction cannot be compared (unknown id, missing or bad scene/EXR file)."""


@dataclass(frozen=True)
class Light:
    """A light as compared: pan relative to the camera and tilt (degrees), unit rgb."""
    pan_rel_deg: float
    tilt_deg: float
    rgb: tuple[float, float, float]

    def to_dict(self) -> dict:
        return {"pan_rel_deg": self.pan_rel_deg, "tilt_deg": self.tilt_deg, "rgb": list(self.rgb)}


@dataclass
class ImageComparison:
    """One compared image. Images are linear ``(res, res, 3)`` float32."""
    id: str
    camera_tilt_deg: float
    gt: Light
    pred: Light
    light_errors_deg: dict          # pan, tilt, direction, colour (degrees)
    image_errors: dict              # (a) vs (b): rmse, psnr_db, ssim
    noise_floor: dict               # (a) vs (a'): same keys
    original: np.ndarray            # (a) the dataset's EXR
    rerender: np.ndarray            # (b) under the predicted light, same seed
    res: int = 0
    spp: int = 0
    seed: int = 0
    kind: str = "point"             # "point" or "envmap"
    scores: dict = field(default_factory=dict)        # (a) vs (b): scale + LIGHT_SCORES
    noise_scores: dict = field(default_factory=dict)  # (a) vs (a'): the same
    shadow_iou: float = float("nan")                  # soft IoU of the occluded fractions
    envmap: str | None = None       # the map's path (envmap entries)
    map_floor: dict = field(default_factory=dict)     # (a) vs the true light's own map (envmap entries)

    @property
    def difference(self) -> np.ndarray:
        """(c) = (b) - (a), linear RGB."""
        return self.rerender - self.original

    def row(self) -> dict:
        """Flat dict for ``metrics.csv`` (angles in degrees, linear image units)."""
        r = {"id": self.id, "camera_tilt_deg": self.camera_tilt_deg,
             "gt_pan_rel_deg": self.gt.pan_rel_deg, "gt_tilt_deg": self.gt.tilt_deg,
             "gt_r": self.gt.rgb[0], "gt_g": self.gt.rgb[1], "gt_b": self.gt.rgb[2],
             "pred_pan_rel_deg": self.pred.pan_rel_deg, "pred_tilt_deg": self.pred.tilt_deg,
             "pred_r": self.pred.rgb[0], "pred_g": self.pred.rgb[1], "pred_b": self.pred.rgb[2]}
        r.update({f"{m}_error_deg": float(v) for m, v in self.light_errors_deg.items()})
        r.update({m: self.image_errors[m] for m in IMAGE_METRICS})
        r.update({f"noise_{m}": self.noise_floor[m] for m in IMAGE_METRICS})
        nf = self.noise_floor["rmse"]
        r["rmse_over_noise"] = self.image_errors["rmse"] / nf if nf > 0 else float("nan")
        r["kind"] = self.kind
        r["scale"] = self.scores.get("scale", float("nan"))
        r.update({m: self.scores.get(m, float("nan")) for m in LIGHT_SCORES})
        r.update({f"noise_{m}": self.noise_scores.get(m, float("nan")) for m in LIGHT_SCORES})
        r["shadow_iou"] = self.shadow_iou
        # empty where there is no map floor (point lights; maps without --map-floor)
        r.update({f"map_floor_{m}": self.map_floor.get(m, "") for m in LIGHT_SCORES + ("shadow_iou",)})
        r.update(res=self.res, spp=self.spp, seed=self.seed)
        return r


@dataclass
class Comparison:
    """Everything one compare run produced."""
    predictions_path: str
    dataset_dir: str
    items: list[ImageComparison]
    bad: list[tuple[str, str]] = field(default_factory=list)   # (entry, one-line reason)
    seconds: float = 0.0
    render_seconds: float = 0.0


def gt_light(record: dict) -> Light:
    light = record["light"]
    rgb = np.asarray(light["rgb"], dtype=np.float64)
    rgb = rgb / np.linalg.norm(rgb)
    return Light(float(record["pan_rel_deg"]), float(light["tilt_deg"]), tuple(float(c) for c in rgb))


@dataclass(frozen=True)
class Task:
    """One validated prediction, ready to render (everything checked but the EXR pixels)."""
    prediction: Prediction
    spec: object          # SceneSpec of the image (ground-truth light)
    exr_path: str
    gt: Light
    pred: Light
    envmap: np.ndarray | None = None     # checked map x envmap_scale (envmap entries)
    envmap_frame: str = "camera"


def prepare(dataset_dir: str, record: dict, prediction: Prediction) -> Task:
    """Check one prediction against its record without rendering (scene file, EXR path,
    light fields, prediction decoding). Raises SceneFileError / DatasetError /
    ImageError / PredictionsError; the caller names the entry."""
    spec = load_spec(dataset_dir, record)
    exr_path = safe_join(dataset_dir, record["exr"])
    if not os.path.isfile(exr_path):
        raise ImageError(f"original image not found: {record['exr']}")
    try:
        gt = gt_light(record)
    except (KeyError, TypeError, ValueError) as exc:
        raise DatasetError(f"manifest record lacks a valid light ({exc})") from None
    if prediction.envmap is not None:
        from relight.verify.envmap import envmap_light, read_envmap
        image = read_envmap(prediction.envmap) * np.float32(prediction.envmap_scale)
        pan, tilt, rgb, _ = envmap_light(image, prediction.envmap_frame, float(spec.camera.tilt_deg),
                                         float(spec.camera.pan_deg))
        return Task(prediction, spec, exr_path, gt, Light(pan, tilt, tuple(float(c) for c in rgb)),
                    envmap=image, envmap_frame=prediction.envmap_frame)
    # colour-only predictions (colour-constancy baselines) keep the true direction
    pan, tilt, rgb = prediction.resolve(float(spec.camera.tilt_deg),
                                        direction_if_missing=(spec.pan_rel_deg, spec.light.tilt_deg))
    spec.with_light(pan, tilt, rgb)  # validates the light (finite values)
    return Task(prediction, spec, exr_path, gt, Light(pan, tilt, tuple(float(c) for c in rgb)))


def compare_one(builder, task: Task, noise_seed_offset: int = NOISE_SEED_OFFSET,
                map_floor: bool = False) -> tuple[ImageComparison, float]:
    """Render and measure one prepared task; returns (result, render seconds). With
    ``map_floor`` a map entry also renders the true light made a map (one more render)."""
    spec, pred, gt = task.spec, task.pred, task.gt
    original = read_exr(task.exr_path)
    res, spp, seed = spec.render.res, spec.render.spp, spec.render.seed
    if original.shape != (res, res, 3):
        raise ImageError(f"{task.exr_path}: shape {original.shape} does not match the scene's "
                         f"{res}x{res}")
    from relight.verify import shadows
    cam = spec.camera

    t0 = time.perf_counter()
    template = builder.template_for(spec)               # ground-truth light applied
    noise = template.render(spp, seed + noise_seed_offset)
    surface = shadows.surface_points(template.scene, res)
    objects = shadows.object_cylinders(spec)
    shadow_a = shadows.point_shadow(template.scene, surface, spec.light.position_m, objects)
    floor = {}
    if task.envmap is None:
        pred_spec = spec.with_light(pred.pan_rel_deg, pred.tilt_deg, pred.rgb)
        rerender = template.render_under(pred_spec.light.position_m, pred_spec.light.intensity, spp, seed)
        shadow_b = shadows.point_shadow(template.scene, surface, pred_spec.light.position_m, objects)
    else:
        rotation = frames.envmap_rotation(task.envmap_frame, cam.tilt_deg, cam.pan_deg)
        shadow_b = shadows.envmap_shadow(template.scene, surface, task.envmap, rotation, occluders=objects)
        env_template = builder.template_for(spec, envmap_shape=task.envmap.shape[:2])
        to_world = frames.mitsuba_envmap_to_world(task.envmap_frame, cam.tilt_deg, cam.pan_deg)
        from relight.verify.envmap import light_envmap, mitsuba_layout
        rerender = env_template.render_under_envmap(mitsuba_layout(task.envmap), to_world, spp, seed)
        if map_floor:   # the true light as a map of the same size (what any map can reach here)
            true_map = light_envmap(spec, task.envmap.shape[1], task.envmap_frame)
            floor = light_scores(original, env_template.render_under_envmap(mitsuba_layout(true_map), to_world,
                                                                            spp, seed))
            floor["shadow_iou"] = shadows.soft_iou(shadow_a, shadows.envmap_shadow(
                template.scene, surface, true_map, rotation, occluders=objects))
    render_s = time.perf_counter() - t0
    scores = light_scores(original, rerender)
    if task.envmap is not None:   # a map's exposure is its own: (b) after the fitted scale
        rerender = (rerender * np.float32(scores["scale"])).astype(np.float32)

    errs = metrics.light_errors(pred.pan_rel_deg, pred.tilt_deg, np.asarray(pred.rgb),
                                gt.pan_rel_deg, gt.tilt_deg, np.asarray(gt.rgb))
    item = ImageComparison(
        id=task.prediction.id, camera_tilt_deg=float(spec.camera.tilt_deg), gt=gt, pred=pred,
        light_errors_deg={k: float(v) for k, v in errs.items()},
        image_errors=image_errors(original, rerender), noise_floor=image_errors(original, noise),
        original=original, rerender=rerender, res=res, spp=spp, seed=seed,
        kind="point" if task.envmap is None else "envmap", scores=scores,
        noise_scores=light_scores(original, noise), shadow_iou=shadows.soft_iou(shadow_a, shadow_b),
        envmap=task.prediction.envmap, map_floor=floor)
    return item, render_s


BAD_INPUT = (SceneFileError, DatasetError, ImageError, PredictionsError)


def compare_predictions(predictions_path: str | os.PathLike, data_dir: str | None = None,
                        limit: int | None = None, skip_bad: bool = False, progress: bool = True,
                        builder=None, noise_seed_offset: int = NOISE_SEED_OFFSET,
                        scheduler=None, map_floor: bool = False) -> Comparison:
    """Re-render every prediction of a file and measure its errors.

    Every entry is checked first (ids, scene files, EXR paths), so a bad one fails
    before any rendering.

    Args:
        predictions_path: a ``relight.predictions/v1`` or ``/v2`` file.
        data_dir: dataset folder (default: the file's ``dataset`` field).
        limit: compare only the first N valid predictions (None: all).
        skip_bad: collect bad entries in ``Comparison.bad`` instead of raising.
        progress: progress bar on stderr (shown only when stderr is a terminal).
        builder: a :class:`~relight.scene.build.SceneBuilder` to reuse (default: new).
        scheduler: render on Dask (``local:N`` or an address, :mod:`relight.engine`):
            shards of images render in worker processes, the results come back here;
            the same Comparison as without it.
        map_floor: for map entries, also render the true light made a map (the map
            floor columns; one more render per map entry).

    Returns:
        A :class:`Comparison`: one :class:`ImageComparison` per compared entry, with the
        four light errors in degrees (pan, tilt, direction, colour), the image errors of
        the re-render (b) against the dataset's EXR (a) (RMSE, PSNR in dB, SSIM), the
        render noise floor, and both linear ``(res, res, 3)`` float32 images.

    Raises:
        CompareError / PredictionsError naming the entry (unless ``skip_bad``).

    Predictions equal to the truth re-render the dataset's image exactly (same seed):

    >>> import relight, tempfile
    >>> tmp = tempfile.TemporaryDirectory()
    >>> data, pred = os.path.join(tmp.name, "data"), os.path.join(tmp.name, "pred.json")
    >>> _ = relight.generate(data, 1, seed=2, cfg=relight.GeneratorConfig(res=16, spp=4), progress=False)
    >>> relight.write_predictions(pred, [{"id": r["id"], "pan_deg": r["pan_rel_deg"], "tilt_deg": r["light"]["tilt_deg"],
    ...                           "rgb": r["light"]["rgb"]} for r in read_manifest(data)], dataset=data)
    >>> item = compare_predictions(pred, progress=False).items[0]
    >>> item.original.shape, item.light_errors_deg["direction"], item.image_errors["rmse"]
    ((16, 16, 3), 0.0, 0.0)
    >>> tmp.cleanup()
    """
    from relight import backend
    from relight.scene.build import SceneBuilder
    predictions_path = os.fspath(predictions_path)
    if limit is not None and limit < 1:
        raise CompareError(f"limit must be a positive integer, got {limit}")
    pfile = read_predictions(predictions_path, skip_bad=skip_bad)
    dataset_dir = resolve_dataset_dir(predictions_path, data_dir, pfile.dataset)
    records = {r.get("id"): r for r in read_manifest(dataset_dir)}
    bad = list(pfile.bad)

    def fail(pred: Prediction, reason: str):
        label = f"entry {pred.id!r}"
        if reason.startswith(label + ": "):   # the reason names the entry already
            reason = reason[len(label) + 2:]
        if not skip_bad:
            raise CompareError(f"{predictions_path}: {label}: {reason}")
        bad.append((label, reason))

    def one_line(exc) -> str:
        return str(exc).splitlines()[0] if str(exc) else type(exc).__name__

    tasks = []
    for pred in (pfile.predictions[:limit] if limit else pfile.predictions):
        record = records.get(pred.id)
        if record is None:
            fail(pred, f"id not in the manifest of {dataset_dir}")
            continue
        try:
            tasks.append(prepare(dataset_dir, record, pred))
        except BAD_INPUT as exc:
            fail(pred, one_line(exc))

    items, render_s, t0 = [], 0.0, time.perf_counter()
    if scheduler is not None:
        outcomes = _compare_on_engine(scheduler, tasks, noise_seed_offset, progress, map_floor)
    else:
        backend.init()
        outcomes = _compare_here(builder or SceneBuilder(), tasks, noise_seed_offset, progress, map_floor)
    for task, (item, seconds, reason) in zip(tasks, outcomes):
        if reason is not None:
            fail(task.prediction, reason)
            continue
        items.append(item)
        render_s += seconds
    return Comparison(predictions_path=os.path.abspath(predictions_path), dataset_dir=dataset_dir,
                      items=items, bad=bad, seconds=time.perf_counter() - t0, render_seconds=render_s)


def _outcome(builder, task: Task, noise_seed_offset: int, map_floor: bool = False):
    """``(item, render seconds, None)``, or ``(None, 0, one-line reason)`` for a bad input."""
    try:
        return (*compare_one(builder, task, noise_seed_offset, map_floor), None)
    except BAD_INPUT as exc:
        return None, 0.0, str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def _compare_here(builder, tasks: list[Task], noise_seed_offset: int, progress: bool, map_floor: bool = False):
    from tqdm import tqdm
    for task in tqdm(tasks, desc="compare", unit="img", disable=None if progress else True):
        yield _outcome(builder, task, noise_seed_offset, map_floor)


def _compare_shard(context, shard: list[int]) -> list:
    """Engine task (in a worker process): the outcomes of tasks ``shard`` (indices into
    the context's task list), with one scene builder per process."""
    from relight import engine
    from relight.scene.build import SceneBuilder
    tasks, noise_seed_offset, map_floor = context
    builder = engine.worker_cache("scene_builder", SceneBuilder)
    return [_outcome(builder, tasks[k], noise_seed_offset, map_floor) for k in shard]


def _compare_on_engine(scheduler, tasks: list[Task], noise_seed_offset: int, progress: bool,
                       map_floor: bool = False) -> list:
    """The outcomes of ``tasks`` rendered on Dask, gathered here in task order."""
    from relight import engine
    return engine.map_ordered(scheduler, _compare_shard, (tasks, noise_seed_offset, map_floor), len(tasks),
                              "compare", engine.ShardPlan(progress=progress))


def moved_light_predictions(dataset_dir: str | os.PathLike, spread_deg: float = 30.0,
                            colour_spread: float = 0.1, seed: int = 0, limit: int | None = None) -> list[dict]:
    """Demo predictions: each record's light with its pan and tilt moved by random
    angles in [-spread_deg, spread_deg] (a tilt past 90 goes over the zenith, one below 0
    stops at the horizon) and its rgb scaled per
    channel by ``1 + U(-colour_spread, colour_spread)``. Entries for
    :func:`relight.predictions.write_predictions`."""
    rng = np.random.default_rng(seed)
    out = []
    for rec in read_manifest(dataset_dir)[:limit]:
        gt = gt_light(rec)
        d_pan, d_tilt = rng.uniform(-spread_deg, spread_deg, 2)
        rgb = np.asarray(gt.rgb) * (1.0 + rng.uniform(-colour_spread, colour_spread, 3))
        pan, tilt = frames.fold_over_zenith(gt.pan_rel_deg + d_pan, gt.tilt_deg + d_tilt)
        out.append({"id": rec["id"], "pan_deg": float(pan), "tilt_deg": float(max(tilt, 0.0)),
                    "rgb": [float(c) for c in rgb]})
    return out

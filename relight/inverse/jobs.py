"""Batches of inverse-rendering jobs: the images of a dataset split or one scene file,
their starting directions (grid, the network, a predictions file), the runs, and the
per-iteration trace file. ``relight invert`` and ``relight baseline`` call these."""
from __future__ import annotations

__all__ = [
    "Job", "dataset_jobs", "network_starts", "file_starts", "invert_jobs", "TRACE_FIELDS", "write_trace_csv",
]

import csv
from dataclasses import dataclass


@dataclass(frozen=True)
class Job:
    """One image to invert: its id, scene, linear image file and camera tilt (deg)."""
    id: str
    scene_path: str
    image_path: str
    camera_tilt_deg: float


def dataset_jobs(data_dir: str, split: str = "test", limit: int | None = None) -> list[Job]:
    """Jobs of a dataset split (``"all"`` for every record), in manifest order; the
    target of each is its linear EXR."""
    from relight.dataset import DatasetError, read_manifest, safe_join, split_records
    records = split_records(read_manifest(data_dir), split)
    if limit is not None:
        records = records[:limit]
    if not records:
        raise DatasetError(f"{data_dir}: no records in split {split!r}")
    for r in records:
        if "scene" not in r or "exr" not in r:
            raise DatasetError(f"{data_dir}: record {r['id']!r} has no scene or exr file")
    return [Job(r["id"], safe_join(data_dir, r["scene"]), safe_join(data_dir, r["exr"]),
                float(r["camera"]["tilt_deg"])) for r in records]


def network_starts(jobs: list[Job], model_path: str | None = None) -> dict[str, tuple[float, float]]:
    """``{id: (pan_rel_deg, tilt_deg)}`` predicted by the trained network (the default
    shipped model, or ``model_path``: a shipped name, a file or a run folder)."""
    from relight.inverse.optimize import InverseError
    from relight.imageio import read_image
    try:
        from relight.net.predict import load_model, predict_arrays
    except ImportError as exc:
        raise InverseError(f"--init network: the network predictor is unavailable ({exc})") from None
    model = load_model(model_path)
    images = [read_image(j.image_path)[0] for j in jobs]
    preds = predict_arrays(model, images, [j.camera_tilt_deg for j in jobs])
    return {j.id: (float(p["pan_deg"]), float(p["tilt_deg"])) for j, p in zip(jobs, preds)}


def file_starts(path: str, jobs: list[Job]) -> dict[str, tuple[float, float]]:
    """Starts from a predictions file; a single-entry file also serves a single job
    whose id differs."""
    from relight.inverse.optimize import InverseError
    from relight.predictions import read_predictions
    preds = {p.id: p for p in read_predictions(path).predictions}
    out = {}
    for j in jobs:
        p = preds.get(j.id)
        if p is None and len(preds) == 1 and len(jobs) == 1:
            p = next(iter(preds.values()))
        if p is None:
            raise InverseError(f"--init {path}: no prediction for image {j.id!r}")
        pan, tilt, _ = p.resolve(j.camera_tilt_deg)
        out[j.id] = (pan, tilt)
    return out


def invert_jobs(jobs: list[Job], init: str, cfg, progress: bool = True,
                model_path: str | None = None, scheduler=None) -> list[tuple[Job, object]]:
    """Run :func:`relight.inverse.optimize.invert` on each job, in job order; ``init`` is
    ``"grid"``, ``"network"`` or a predictions file path. ``scheduler``: invert shards of
    jobs on Dask (``local:N`` or an address, :mod:`relight.engine`); the starts are found
    here and the results gathered here, the same as without it."""
    from tqdm import tqdm

    if scheduler is None:
        from relight import backend
        backend.init()
    if init == "grid":
        starts = {}
    elif init == "network":
        starts = network_starts(jobs, model_path)
    else:
        starts = file_starts(init, jobs)
    work = [(job, starts.get(job.id, "grid")) for job in jobs]
    if scheduler is None:
        return [(job, _invert_one(job, start, cfg))
                for job, start in tqdm(work, desc="invert", unit="img", disable=not progress)]
    from relight import engine
    plan = engine.ShardPlan(shard_size=1, progress=progress)   # seconds an image: one a task balances best
    results = engine.map_ordered(scheduler, _invert_shard, (work, cfg), len(work), "invert", plan)
    return [(job, res) for (job, _), res in zip(work, results)]


def _invert_one(job: Job, start, cfg):
    from relight.imageio import read_image
    from relight.inverse.optimize import invert
    from relight.scene.build import SceneBuilder
    from relight.scene.spec import load_scene
    spec = load_scene(job.scene_path)
    image, _ = read_image(job.image_path)
    # a fresh builder per image: every live Mitsuba scene enlarges Dr.Jit's virtual-call
    # tables; one shared builder measured 1.1-1.2 s per image against 0.9 s (10 images)
    return invert(spec, image, start, cfg, SceneBuilder(max_templates=2))


def _invert_shard(context, shard: list[int]) -> list:
    """Engine task (in a worker process): the results of jobs ``shard`` (indices into the
    context's ``(job, start)`` list)."""
    work, cfg = context
    return [_invert_one(*work[k], cfg) for k in shard]


TRACE_FIELDS = ("id", "iteration", "stage", "start", "loss", "pan_deg", "tilt_deg", "r_m",
                "r", "g", "b", "renders", "seconds")


def write_trace_csv(path: str, results, transaction=None) -> None:
    """One CSV row per logged optimiser state (pan_deg = pan_rel), atomically (or staged
    in ``transaction``)."""
    from relight.fileio import atomic_write
    (transaction.stage if transaction is not None else atomic_write)(
        path, lambda tmp: _write_trace(tmp, results))


def _write_trace(tmp: str, results) -> None:
    with open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(TRACE_FIELDS)
        for job, res in results:
            for t in res.trace:
                w.writerow([job.id, t["iteration"], t["stage"], t["start"], f"{t['loss']:.6e}",
                            f"{t['pan_deg']:.4f}", f"{t['tilt_deg']:.4f}", f"{t['r_m']:.4f}",
                            *[f"{c:.6f}" for c in t["rgb"]], t["renders"], t["seconds"]])

"""Generate SID2-style datasets (resumable, crash-safe); :mod:`relight.dataset` reads them back.

Layout of a dataset folder (see ``shared/conventions.md``)::

    dataset.json      the card: format, seed, generator settings, counts
    manifest.jsonl    one JSON record per finished image
    images/ID.png     8-bit sRGB, for the network
    exr/ID.exr        linear HDR float32
    scenes/ID.json    the scene description that re-renders the image exactly
    masks/ID.png      (config object_masks only) each pixel's share covered by the objects

Crash safety: every file is written to a temporary name and renamed; an image's
manifest record is appended (one ``write`` of one line, then flush and fsync) only
after its three files are in place. A kill at any moment can therefore leave at most
a partial *last line* of the manifest, which readers ignore and the next run cuts
off, and possibly finished files without a record, which the next run rewrites.
Re-running the same command resumes: image ``i`` depends only on (seed, i).

One writer per dataset: :func:`generate` holds an OS lock on ``FOLDER/.relight.lock``
for the whole run (a second writer gets :class:`~relight.fileio.OutputError`), so it
can remove the temporary files that killed runs left (readers skip such names).
Several render processes (``workers`` or a ``scheduler``) run on the Dask engine
(:mod:`relight.engine`): their workers die with this process, and only this process
appends records.
A run that fails before finishing any image leaves the folder as it was.
"""
from __future__ import annotations

__all__ = [
    "GenerateStats", "generate",
]

import contextlib
import json
import os
import time
from concurrent.futures import Future
from dataclasses import dataclass

import numpy as np

from relight.dataset.format import (CARD, DATASET_FORMAT, MANIFEST, MAX_COUNT, SEED_LIMIT, check_same_settings,
                                    read_card, read_manifest, record_for)
from relight.fileio import LOCK_NAME, FolderLock, append_line, remove_temps, write_bytes, write_json
from relight.timing import NO_TIMER
from relight.generator.sampling import LEGACY_CONFIG, GeneratorConfig, sample_scene, split_of
from relight.scene.spec import SceneSpec
from relight.errors import DatasetError, DiskFullError, RelightError


@dataclass
class GenerateStats:
    """What a :func:`generate` call did and where its time went (seconds)."""
    written: int = 0
    skipped: int = 0
    total_s: float = 0.0
    render_s: float = 0.0
    tasks: int = 0          # engine tasks (shards) run, with --scheduler
    task_s: float = 0.0     # summed wall time inside those tasks (render + write)
    startup_s: float = 0.0  # time to start or reach the cluster (part of total_s)

    @property
    def images_per_s(self) -> float:
        return self.written / self.total_s if self.total_s > 0 else float("nan")

    @property
    def overhead_ratio(self) -> float:
        """Total generation time over time inside Mitsuba's render call."""
        return self.total_s / self.render_s if self.render_s > 0 else float("nan")


def _write_card(out: str, seed: int, cfg: GeneratorConfig, count: int, n_records: int) -> None:
    card_path = os.path.join(out, CARD)
    settings = {"format": DATASET_FORMAT, "seed": int(seed), "config": cfg.to_dict()}
    if os.path.isfile(card_path) and n_records:  # a card without records binds nothing
        old = read_card(out)
        same = {k: old.get(k) for k in settings}
        if isinstance(same["config"], dict):   # a setting added later reads as its old value
            same["config"] = {**LEGACY_CONFIG, **same["config"]}
        check_same_settings(out, same, settings)
        count = max(count, int(old.get("count", 0)))
    card = {**settings, "count": int(count), "spp": cfg.render_spp,
            "description": "SID2-style synthetic dataset rendered with Mitsuba 3 by relight "
                           "(Sial et al., 'Light Direction and Color Estimation from Single Image "
                           "with Deep Regression')",
            "split_rule": "sha256(id) -> train/val/test by config.split fractions"}
    write_json(card_path, card)


def _prepare(cfg: GeneratorConfig, seed: int, index: int, timer=NO_TIMER):
    """Stage 1 (helper thread): sample the spec and make its meshes and textures, which
    land in the builder's caches so the render stage only uploads them."""
    from relight.scene import build
    with timer.image(index):
        with timer.stage("scene sampling"):
            spec = sample_scene(cfg, seed, index)
        with timer.stage("meshes"):
            meshes = [build.object_mesh(o) for o in spec.objects]
        with timer.stage("textures"):
            for params in spec.room.wall_textures + (spec.room.floor_texture,):
                build.texture(params, spec.room.texture_res)
    return spec, meshes


def _write(out: str, spec: SceneSpec, image: np.ndarray, split: str, timer=NO_TIMER,
           mask: np.ndarray | None = None) -> dict:
    """Stage 3 (writer thread): the scene file, EXR and PNG (and with ``mask``, the
    object mask), each atomically; returns the record to append once all are in place."""
    from relight.imageio import write_exr, write_mask, write_png
    from relight.fileio import write_text
    parts = [("scenes", ".json"), ("exr", ".exr"), ("images", ".png")] + ([("masks", ".png")] if mask is not None else [])
    paths = [os.path.join(out, sub, f"{spec.id}{ext}") for sub, ext in parts]
    try:
        with timer.stage("write: scene JSON"):
            write_text(paths[0], spec.to_json())
        with timer.stage("write: EXR"):
            write_exr(paths[1], image)
        with timer.stage("write: PNG"):
            write_png(paths[2], image)
        if mask is not None:
            with timer.stage("write: mask"):
                write_mask(paths[3], mask)
    except BaseException:   # no record will name them: leave no file of this image behind
        for path in paths:
            with contextlib.suppress(OSError):
                os.remove(path)
        raise
    record = record_for(spec, split)
    if mask is not None:
        record["mask"] = f"masks/{spec.id}.png"
    return record


class _Inline:
    """An executor that runs each task at once in the calling thread (``overlap=False``)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    @staticmethod
    def submit(fn, *args, **kwargs) -> Future:
        future = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # noqa: BLE001 - handed to .result(), as a thread would
            future.set_exception(exc)
        return future


def _pipeline(out: str, cfg: GeneratorConfig, seed: int, indices: list[int], on_record,
              builder=None, timer=NO_TIMER, overlap: bool = True) -> None:
    """Generate ``indices`` in order with three overlapping stages: prepare the next
    scene and write the previous image while Mitsuba renders the current one.
    ``on_record(record, render_s)`` is called in index order from the writer thread,
    only after the image's files are complete. ``builder``: a SceneBuilder to reuse
    (its loaded templates) across calls; a new one by default. ``timer``: a
    :class:`~relight.timing.StageTimer` to time each stage; ``overlap=False``
    runs every stage in this thread, one after the other (same files; for profiling)."""
    from concurrent.futures import ThreadPoolExecutor

    from relight.scene.build import SceneBuilder
    builder = builder or SceneBuilder()
    pool = (lambda name: ThreadPoolExecutor(1, thread_name_prefix=name)) if overlap else (lambda name: _Inline())
    with pool("prepare") as prep, pool("write") as writer:
        pending_writes = []
        with timer.stage("hand-off to helper threads"):   # the first call starts the thread
            next_prep = prep.submit(_prepare, cfg, seed, indices[0], timer) if indices else None
        for k in range(len(indices)):
            with timer.image(indices[k]):
                with timer.stage("wait: prepare"):
                    spec, meshes = next_prep.result()
                if k + 1 < len(indices):
                    with timer.stage("hand-off to helper threads"):
                        next_prep = prep.submit(_prepare, cfg, seed, indices[k + 1], timer)
            with timer.image(indices[k]):
                template = builder.template(spec, meshes, timer=timer)
                t0 = time.perf_counter()
                image = template.render(spec.render.spp, spec.render.seed, timer=timer)
                render_s = time.perf_counter() - t0
                if cfg.object_masks:
                    with timer.stage("object mask"):
                        mask = template.object_mask()
                else:
                    mask = None

            def write_and_record(spec=spec, image=image, render_s=render_s, index=indices[k], mask=mask):
                with timer.image(index):
                    on_record(_write(out, spec, image, split_of(spec.id, cfg.split), timer, mask), render_s)
            with timer.image(indices[k]), timer.stage("hand-off to helper threads"):
                pending_writes.append(writer.submit(write_and_record))
            with timer.image(indices[k]), timer.stage("wait: writes"):
                while len(pending_writes) > 2 or (pending_writes and pending_writes[0].done()):
                    pending_writes.pop(0).result()  # re-raises a writer error here
        with timer.stage("wait: writes"):
            for f in pending_writes:
                f.result()


def generate(out_dir: str | os.PathLike, count: int, seed: int = 0,
             cfg: GeneratorConfig | None = None, workers: int = 1, progress: bool = True,
             threads: int | None = None, scheduler=None, timer=None, overlap: bool = True) -> GenerateStats:
    """Generate (or resume) a dataset of ``count`` images in ``out_dir``.

    Args:
        out_dir: dataset folder (created).
        count: total number of images wanted; existing records count.
        seed: dataset seed; image ``i`` depends only on (seed, i) and ``cfg``.
        cfg: generator settings (default :class:`GeneratorConfig`).
        workers: processes rendering in parallel (each gets cores / workers threads): more
            than one runs on the engine's ``local:N``, at most one per image left
            (:func:`relight.engine.for_workers`, needs Dask).
        progress: show a progress bar (images/s) on stderr.
        threads: Dr.Jit threads per process (default: cores / workers).
        scheduler: run on Dask instead (:class:`relight.engine.Scheduler` or its text,
            ``local:N`` or an address; the command line's is
            :func:`relight.engine.scheduler_from_args`); ``workers`` is then ignored. Same output.
        timer: a :class:`relight.timing.StageTimer` that times every stage of
            every image (one process only: not with ``workers`` or ``scheduler``).
        overlap: prepare, render and write on three threads (default); ``False`` runs
            them one after the other (for profiling; same files).

    Returns:
        :class:`GenerateStats`: images written and skipped (already there), and where the
        time went (seconds). The folder holds ``dataset.json``, ``manifest.jsonl`` and per
        image ``images/ID.png`` (8-bit sRGB), ``exr/ID.exr`` (linear) and ``scenes/ID.json``.

    Raises:
        DatasetError / ConfigError (bad settings, a folder made with other settings),
        OutputError (another writer holds the folder): nothing is left half-written.

    Two 16-pixel images, then the same command again (it resumes: nothing to do):

    >>> import tempfile
    >>> from relight.dataset import read_manifest
    >>> from relight.generator.sampling import GeneratorConfig
    >>> tmp = tempfile.TemporaryDirectory()
    >>> stats = generate(tmp.name, 2, seed=7, cfg=GeneratorConfig(res=16, spp=1), progress=False)
    >>> stats.written, [r["id"] for r in read_manifest(tmp.name)]
    (2, ['000000', '000001'])
    >>> generate(tmp.name, 2, seed=7, cfg=GeneratorConfig(res=16, spp=1), progress=False).skipped
    2
    >>> tmp.cleanup()
    """
    cfg = cfg or GeneratorConfig()
    if isinstance(count, bool) or not isinstance(count, int) or not 0 <= count <= MAX_COUNT:
        raise DatasetError(f"count must be an integer in [0, {MAX_COUNT}], got {count!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < SEED_LIMIT:
        raise DatasetError(f"seed must be an integer in [0, 2**32), got {seed!r}")
    if workers < 1:
        raise DatasetError(f"workers must be >= 1, got {workers}")
    if threads is not None and threads < 1:
        raise DatasetError(f"threads must be >= 1, got {threads}")
    if timer is not None and (scheduler is not None or workers > 1):
        raise DatasetError("a stage timer times one process: not with workers or a scheduler")
    from relight import engine
    # a bad scheduler fails here, before the folder is touched; workers N > 1 is local:N
    scheduler = engine.as_scheduler(scheduler) if scheduler is not None else engine.for_workers(workers)
    out = os.fspath(out_dir)
    before = set(os.listdir(out)) if os.path.isdir(out) else set()
    card_path = os.path.join(out, CARD)
    lock, existed = FolderLock.take(out, "dataset")
    old_card = open(card_path, "rb").read() if os.path.isfile(card_path) else None
    stats = GenerateStats()
    try:
        try:
            return _generate_locked(out, count, seed, cfg, progress, threads, stats, scheduler,
                                    timer or NO_TIMER, overlap)
        except DiskFullError as exc:
            raise DiskFullError(f"{exc}{_room_needed(out, count)}") from None
    except BaseException:
        if stats.written == 0:   # nothing made: leave the folder as it was
            if not existed:
                lock.remove_made()   # the folder and any parents made for it
            elif old_card is not None:
                write_bytes(card_path, old_card)
            elif os.path.isfile(card_path) and not _has_records(out):
                os.remove(card_path)
            if existed:   # and what this run added: empty folders, the lock file
                for name in set(os.listdir(out)) - before:
                    path = os.path.join(out, name)
                    with contextlib.suppress(OSError):
                        if os.path.isdir(path):
                            os.rmdir(path)
                        elif name == LOCK_NAME or (name == MANIFEST and os.path.getsize(path) == 0):
                            os.remove(path)
        raise
    finally:
        lock.release()


def _room_needed(out: str, count: int) -> str:
    """`` (the N images left need about X)`` from the finished images' files, or ''."""
    from relight.fileio import human_size, is_temp_name
    try:
        done = {r["id"] for r in read_manifest(out)} if _has_records(out) else set()
        size = sum(os.path.getsize(os.path.join(out, sub, n)) for sub in ("images", "exr", "scenes")
                   for n in os.listdir(os.path.join(out, sub))
                   if not is_temp_name(n) and os.path.splitext(n)[0] in done)
    except (OSError, RelightError):
        return ""
    left = count - len(done)
    if not done or left <= 0:
        return ""
    return f" (the {left} images left need about {human_size(size / len(done) * left)})"


def _check_meshes(cfg: GeneratorConfig) -> None:
    """Load every mesh of ``cfg.mesh_dir`` once, so a bad file fails before any render."""
    if cfg.mesh_dir:
        from relight.scene.build import _user_mesh
        from relight.generator.sampling import mesh_files
        for path in mesh_files(cfg.mesh_dir):
            _user_mesh(path)


def _has_records(out: str) -> bool:
    path = os.path.join(out, MANIFEST)
    return os.path.isfile(path) and os.path.getsize(path) > 0


def _generate_locked(out: str, count: int, seed: int, cfg: GeneratorConfig,
                     progress: bool, threads: int | None, stats: GenerateStats,
                     scheduler=None, timer=NO_TIMER, overlap: bool = True) -> GenerateStats:
    from tqdm import tqdm
    subs = ("images", "exr", "scenes") + (("masks",) if cfg.object_masks else ())
    remove_temps(out, ("",) + subs)   # left by killed runs (we hold the lock)
    for sub in subs:
        os.makedirs(os.path.join(out, sub), exist_ok=True)
    manifest_path = os.path.join(out, MANIFEST)
    done = set()
    if os.path.exists(manifest_path):
        done = {r["id"] for r in read_manifest(out, repair=True)}
    _write_card(out, seed, cfg, count, len(done))
    todo = [i for i in range(count) if f"{i:06d}" not in done]
    stats.skipped = count - len(todo)
    if not todo:
        return stats
    from relight.engine import fit_to_work
    scheduler = fit_to_work(scheduler, len(todo))   # --workers N: at most one per image left
    renders_here = scheduler is None   # else workers render; this process checks meshes
    if renders_here or cfg.mesh_dir:
        from relight import backend
        backend.init(threads=(threads or os.cpu_count() or 1) if renders_here else 1)
        _check_meshes(cfg)   # a bad mesh fails here, before the manifest is touched
    bar = tqdm(total=len(todo), unit="img", disable=not progress, desc="generate", smoothing=0.1)
    t_start = time.perf_counter()
    with open(manifest_path, "ab") as manifest:
        def append(record, render_s):
            with timer.stage("write: manifest append"):
                append_line(manifest, (json.dumps(record) + "\n").encode(), manifest_path)
            stats.written += 1
            stats.render_s += render_s
            bar.update(1)

        if scheduler is not None:
            _run_engine(scheduler, threads, out, cfg, seed, todo, append, stats, progress)
        else:
            _pipeline(out, cfg, seed, todo, append, timer=timer, overlap=overlap)
    stats.total_s = time.perf_counter() - t_start
    bar.close()
    return stats


def _render_shard(context, indices: list[int]) -> list[tuple[dict, float]]:
    """Engine task (in a worker process): render and write ``indices`` of the dataset with
    the same three-stage pipeline as the single-process path, keeping one scene builder
    per process; returns ``(record, render seconds)`` of each image, in index order, once
    every image's files are in place."""
    from relight import engine
    from relight.scene.build import SceneBuilder
    out, cfg, seed = context
    done = []
    _pipeline(out, cfg, seed, indices, lambda record, render_s: done.append((record, render_s)),
              builder=engine.worker_cache("scene_builder", SceneBuilder))
    return done


def _run_engine(scheduler, threads, out, cfg, seed, todo, append, stats, progress) -> None:
    """Render ``todo`` on Dask (:mod:`relight.engine`); ``append`` each record of a
    finished task here, in the client, once (a re-run task's records are skipped)."""
    from relight import engine
    appended = set()

    def on_result(indices, done):
        for record, render_s in done:
            if record["id"] not in appended:
                appended.add(record["id"])
                append(record, render_s)
    run = engine.EngineStats()
    try:
        engine.map_shards(scheduler, _render_shard, (out, cfg, seed), todo, on_result,
                          engine.ShardPlan(threads=threads, progress=progress), stats=run)
    finally:
        stats.tasks, stats.task_s, stats.startup_s = run.tasks, run.task_s, run.startup_s

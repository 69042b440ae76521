"""Generate SID2-style datasets (resumable, crash-safe) and read them back.

Layout of a dataset folder (see ``shared/conventions.md``)::

    dataset.json      the card: format, seed, generator settings, counts
    manifest.jsonl    one JSON record per finished image
    images/ID.png     8-bit sRGB, for the network
    exr/ID.exr        linear HDR float32
    scenes/ID.json    the scene description that re-renders the image exactly

Crash safety: every file is written to a temporary name and renamed; an image's
manifest record is appended (one ``write`` of one line, then flush and fsync) only
after its three files are in place. A kill at any moment can therefore leave at most
a partial *last line* of the manifest, which readers ignore and the next run cuts
off, and possibly finished files without a record, which the next run rewrites.
Re-running the same command resumes: image ``i`` depends only on (seed, i).

One writer per dataset: :func:`generate` holds an OS lock on ``FOLDER/.relight.lock``
for the whole run (a second writer gets :class:`~relight.fileio.OutputError`), so it
can remove the temporary files that killed runs left (readers skip such names).
Worker processes die with their parent (a parent-death signal and a watched pipe).
A run that fails before finishing any image leaves the folder as it was.
"""
from __future__ import annotations

import contextlib
import json
import math
import multiprocessing as mp
import os
import signal
import sys
import threading
import time
from dataclasses import dataclass

import numpy as np

from relight import frames
from relight.fileio import LOCK_NAME, FolderLock, append_line, remove_temps, write_bytes, write_json
from relight.scene.sampling import LEGACY_CONFIG, GeneratorConfig, sample_scene, split_of
from relight.scene.spec import SceneSpec
from relight.errors import DatasetError, DiskFullError, RelightError

DATASET_FORMAT = "relight.dataset/v1"
MANIFEST = "manifest.jsonl"
CARD = "dataset.json"
MAX_COUNT = 1_000_000      # ids are six digits
SEED_LIMIT = 2 ** 32       # dataset seeds are in [0, 2**32)
SPLITS = ("train", "val", "test")
SPLIT_CHOICES = SPLITS + ("all",)   # what a reader may ask for: one split or all of them


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


def record_for(spec: SceneSpec, split: str) -> dict:
    """The manifest record of one image (paths relative to the dataset folder)."""
    light, cam = spec.light, spec.camera
    y = frames.encode_y(light.pan_deg, light.tilt_deg, np.asarray(light.rgb), cam.tilt_deg, cam.pan_deg)
    return {
        "id": spec.id,
        "image": f"images/{spec.id}.png",
        "exr": f"exr/{spec.id}.exr",
        "scene": f"scenes/{spec.id}.json",
        "split": split,
        "light": {"pan_deg": light.pan_deg, "tilt_deg": light.tilt_deg, "r_m": light.r_m,
                  "rgb": list(light.rgb), "cct_k": light.cct_k, "duv": light.duv,
                  "strength": light.strength, "position_m": light.position_m.tolist()},
        "camera": {"pan_deg": cam.pan_deg, "tilt_deg": cam.tilt_deg, "r_m": cam.r_m,
                   "fov_deg": cam.fov_deg, "position_m": cam.position_m.tolist()},
        "pan_rel_deg": spec.pan_rel_deg,
        "y": [float(v) for v in y],
        "seed": spec.render.seed,
        "n_objects": len(spec.objects),
        "colour_prior": spec.colour_prior,
    }


def read_manifest(dataset_dir: str | os.PathLike, repair: bool = False) -> list[dict]:
    """Records of a dataset, in file order, each checked (:func:`check_record`).

    A partial last line (a killed writer) is ignored, and cut off when ``repair`` is
    true. Records repeated with identical content (two writers of an older relight)
    are kept once -- and removed from the file when ``repair`` is true; the same id
    with different content is an error. Raises :class:`DatasetError` naming the file
    and line.
    """
    path = os.path.join(os.fspath(dataset_dir), MANIFEST)
    if not os.path.isfile(path):
        raise DatasetError(f"{os.fspath(dataset_dir)}: no {MANIFEST} (not a relight dataset?)")
    with open(path, "rb") as f:
        data = f.read()
    records, seen, good_end, pos, line_no, duplicates = [], {}, 0, 0, 0, 0
    while pos < len(data):
        nl = data.find(b"\n", pos)
        if nl < 0:
            break  # partial last line: its writer was killed
        line_no += 1
        line = data[pos:nl]
        try:
            rec = json.loads(line)
        except (json.JSONDecodeError, UnicodeDecodeError):
            if data.find(b"\n", nl + 1) >= 0:
                raise DatasetError(f"{path}: corrupt record on line {line_no}") from None
            break
        check_record(rec, f"{path}: line {line_no}")
        first = seen.get(rec["id"])
        if first is not None:
            if first != rec:
                raise DatasetError(f"{path}: line {line_no}: id {rec['id']!r} appears twice with "
                                   "different content")
            duplicates += 1
        else:
            seen[rec["id"]] = rec
            records.append(rec)
        pos = good_end = nl + 1
    if repair and (good_end < len(data) or duplicates):
        text = b"".join((json.dumps(r) + "\n").encode() for r in records) if duplicates else data[:good_end]
        if duplicates:
            write_bytes(path, text)
        else:
            with open(path, "r+b") as f:
                f.truncate(good_end)
    return records


def _finite_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def check_record(rec, where: str) -> None:
    """Check the fields of a manifest record that readers use; raises
    :class:`DatasetError` (``where`` names file and line)."""
    if not isinstance(rec, dict):
        raise DatasetError(f"{where}: expected a JSON object, got {type(rec).__name__}")
    rid = rec.get("id")
    if not isinstance(rid, str) or not rid or "/" in rid or "\\" in rid or rid in (".", ".."):
        raise DatasetError(f"{where}: 'id' must be a plain name, got {rid!r}")
    where = f"{where} (id {rid!r})"
    for key in ("image", "exr", "scene"):   # exr and scene may be absent (hand-made datasets)
        if (key in rec or key == "image") and not isinstance(rec.get(key), str):
            raise DatasetError(f"{where}: {key!r} must be a relative path string, got {rec.get(key)!r}")
    if rec.get("split") not in SPLITS:
        raise DatasetError(f"{where}: 'split' must be one of {', '.join(SPLITS)}, got {rec.get('split')!r}")
    for part, keys in (("light", ("pan_deg", "tilt_deg")), ("camera", ("pan_deg", "tilt_deg"))):
        obj = rec.get(part)
        if not isinstance(obj, dict):
            raise DatasetError(f"{where}: {part!r} must be an object")
        for k in keys:
            if not _finite_number(obj.get(k)):
                raise DatasetError(f"{where}: {part}.{k} must be a finite number, got {obj.get(k)!r}")
    rgb = rec["light"].get("rgb")
    if not (isinstance(rgb, list) and len(rgb) == 3 and all(_finite_number(c) and c >= 0 for c in rgb)
            and max(rgb) > 0):
        raise DatasetError(f"{where}: light.rgb must be three finite non-negative numbers, got {rgb!r}")
    if not _finite_number(rec.get("pan_rel_deg")):
        raise DatasetError(f"{where}: pan_rel_deg must be a finite number, got {rec.get('pan_rel_deg')!r}")
    y = rec.get("y")
    if not (isinstance(y, list) and len(y) == frames.Y_SIZE and all(_finite_number(v) for v in y)):
        raise DatasetError(f"{where}: 'y' must be a list of {frames.Y_SIZE} finite numbers")


def split_records(records: list[dict], split: str) -> list[dict]:
    """Records of one split (``"train"``, ``"val"``, ``"test"``) or all of them (``"all"``)."""
    if split not in SPLIT_CHOICES:
        raise DatasetError(f"unknown split {split!r}; expected one of {', '.join(SPLIT_CHOICES)}")
    return list(records) if split == "all" else [r for r in records if r.get("split") == split]


def read_card(dataset_dir: str | os.PathLike) -> dict:
    """The dataset card (settings it was made with)."""
    path = os.path.join(os.fspath(dataset_dir), CARD)
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, json.JSONDecodeError) as exc:
        raise DatasetError(f"cannot read dataset card {path}: {exc}") from None


def check_same_settings(out: str, there: dict, here: dict) -> None:
    """Refuse to add to the dataset in ``out`` (card settings ``there``) with other
    settings (``here``, the same keys, ``config`` a dict): :class:`DatasetError` naming
    the first settings that differ."""
    there, here = json.loads(json.dumps(there)), json.loads(json.dumps(here))
    if there == here:
        return
    diff = [f"{k} {there.get(k)} there, {v} here" for k, v in here.items() if k != "config" and there.get(k) != v]
    old_cfg = there.get("config") if isinstance(there.get("config"), dict) else {}
    diff += [f"{k} {old_cfg.get(k)} there, {v} here" for k, v in here["config"].items() if old_cfg.get(k) != v]
    raise DatasetError(f"{out} holds a dataset made with other settings ({'; '.join(diff[:3]) or 'config'}); "
                       "use another --out or the same settings to resume")


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


def _prepare(cfg: GeneratorConfig, seed: int, index: int):
    """Stage 1 (helper thread): sample the spec and make its meshes and textures, which
    land in the builder's caches so the render stage only uploads them."""
    from relight.scene import build
    spec = sample_scene(cfg, seed, index)
    meshes = [build.object_mesh(o) for o in spec.objects]
    for params in spec.room.wall_textures + (spec.room.floor_texture,):
        build.texture(params, spec.room.texture_res)
    return spec, meshes


def _write(out: str, spec: SceneSpec, image: np.ndarray, split: str) -> dict:
    """Stage 3 (writer thread): the scene file, EXR and PNG, each atomically; returns
    the record to append once all three are in place."""
    from relight.imageio import write_exr, write_png
    from relight.fileio import write_text
    paths = [os.path.join(out, sub, f"{spec.id}{ext}") for sub, ext in
             (("scenes", ".json"), ("exr", ".exr"), ("images", ".png"))]
    try:
        write_text(paths[0], spec.to_json())
        write_exr(paths[1], image)
        write_png(paths[2], image)
    except BaseException:   # no record will name them: leave no file of this image behind
        for path in paths:
            with contextlib.suppress(OSError):
                os.remove(path)
        raise
    return record_for(spec, split)


def _pipeline(out: str, cfg: GeneratorConfig, seed: int, indices: list[int], on_record,
              builder=None) -> None:
    """Generate ``indices`` in order with three overlapping stages: prepare the next
    scene and write the previous image while Mitsuba renders the current one.
    ``on_record(record, render_s)`` is called in index order from the writer thread,
    only after the image's files are complete. ``builder``: a SceneBuilder to reuse
    (its loaded templates) across calls; a new one by default."""
    from concurrent.futures import ThreadPoolExecutor

    from relight.scene.build import SceneBuilder
    builder = builder or SceneBuilder()
    with ThreadPoolExecutor(1, thread_name_prefix="prepare") as prep, \
            ThreadPoolExecutor(1, thread_name_prefix="write") as writer:
        pending_writes = []
        next_prep = prep.submit(_prepare, cfg, seed, indices[0]) if indices else None
        for k in range(len(indices)):
            spec, meshes = next_prep.result()
            if k + 1 < len(indices):
                next_prep = prep.submit(_prepare, cfg, seed, indices[k + 1])
            template = builder.template(spec, meshes)
            t0 = time.perf_counter()
            image = template.render(spec.render.spp, spec.render.seed)
            render_s = time.perf_counter() - t0

            def write_and_record(spec=spec, image=image, render_s=render_s):
                on_record(_write(out, spec, image, split_of(spec.id, cfg.split)), render_s)
            pending_writes.append(writer.submit(write_and_record))
            while len(pending_writes) > 2 or (pending_writes and pending_writes[0].done()):
                pending_writes.pop(0).result()  # re-raises a writer error here
        for f in pending_writes:
            f.result()


def _die_with_parent(parent_pid: int, watch) -> None:
    """Make this worker process end when its parent ends, however the parent ends: a
    parent-death signal (Linux) and a thread that exits when the pipe from the parent
    closes (everywhere)."""
    if sys.platform.startswith("linux"):
        try:
            import ctypes
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)   # PR_SET_PDEATHSIG = 1
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:   # the parent died before prctl took effect
        os._exit(3)

    def watch_parent():
        try:
            watch.recv()   # the parent never sends: returns (EOFError) when it dies
        except (EOFError, OSError):
            pass
        os._exit(3)
    threading.Thread(target=watch_parent, name="parent-watch", daemon=True).start()


def _worker(out, cfg, seed, indices, threads, queue, parent_pid=None, watch=None):
    from relight import backend
    if watch is not None:
        _die_with_parent(parent_pid, watch)
    try:
        backend.init(threads=threads)
        _pipeline(out, cfg, seed, indices, lambda record, render_s: queue.put(("ok", record, render_s)))
    except BaseException as exc:  # report to the parent, which stops cleanly
        if isinstance(exc, RelightError):   # a user error (a full disk...): said as the worker said it
            queue.put(("disk-full" if isinstance(exc, DiskFullError) else "user-error", str(exc), 0.0))
        else:
            queue.put(("error", f"{type(exc).__name__}: {exc}", 0.0))


def generate(out_dir: str | os.PathLike, count: int, seed: int = 0,
             cfg: GeneratorConfig | None = None, workers: int = 1, progress: bool = True,
             threads: int | None = None, scheduler=None) -> GenerateStats:
    """Generate (or resume) a dataset of ``count`` images in ``out_dir``.

    Args:
        out_dir: dataset folder (created).
        count: total number of images wanted; existing records count.
        seed: dataset seed; image ``i`` depends only on (seed, i) and ``cfg``.
        cfg: generator settings (default :class:`GeneratorConfig`).
        workers: processes rendering in parallel (each gets cores / workers threads).
        progress: show a progress bar (images/s) on stderr.
        threads: Dr.Jit threads per process (default: cores / workers).
        scheduler: run on Dask instead (:class:`relight.engine.Scheduler` or its text,
            ``local:N`` or an address); ``workers`` is then ignored. Same output.
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
    if isinstance(scheduler, str):
        from relight.engine import parse_scheduler
        scheduler = parse_scheduler(scheduler)
    out = os.fspath(out_dir)
    before = set(os.listdir(out)) if os.path.isdir(out) else set()
    card_path = os.path.join(out, CARD)
    lock, existed = FolderLock.take(out, "dataset")
    old_card = open(card_path, "rb").read() if os.path.isfile(card_path) else None
    stats = GenerateStats()
    try:
        try:
            return _generate_locked(out, count, seed, cfg, workers, progress, threads, stats, scheduler)
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
        from relight.scene.sampling import mesh_files
        for path in mesh_files(cfg.mesh_dir):
            _user_mesh(path)


def _has_records(out: str) -> bool:
    path = os.path.join(out, MANIFEST)
    return os.path.isfile(path) and os.path.getsize(path) > 0


def _generate_locked(out: str, count: int, seed: int, cfg: GeneratorConfig, workers: int,
                     progress: bool, threads: int | None, stats: GenerateStats,
                     scheduler=None) -> GenerateStats:
    from tqdm import tqdm
    remove_temps(out, ("", "images", "exr", "scenes"))   # left by killed runs (we hold the lock)
    for sub in ("images", "exr", "scenes"):
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
    cores = os.cpu_count() or 1
    workers = min(workers, len(todo))
    user_threads = threads
    threads = threads or max(1, cores // workers)
    if scheduler is not None:
        workers = 2   # the client renders nothing; it checks meshes with one thread
    if workers == 1 or cfg.mesh_dir:
        from relight import backend
        backend.init(threads=threads if workers == 1 else 1)
        _check_meshes(cfg)   # a bad mesh fails here, before the manifest is touched
    bar = tqdm(total=len(todo), unit="img", disable=not progress, desc="generate", smoothing=0.1)
    t_start = time.perf_counter()
    with open(manifest_path, "ab") as manifest:
        def append(record, render_s):
            append_line(manifest, (json.dumps(record) + "\n").encode(), manifest_path)
            stats.written += 1
            stats.render_s += render_s
            bar.update(1)

        if scheduler is not None:
            _run_engine(scheduler, user_threads, out, cfg, seed, todo, append, stats, progress)
        elif workers == 1:
            _pipeline(out, cfg, seed, todo, append)
        else:
            ctx = mp.get_context("spawn")
            queue = ctx.Queue()
            watch, keep_alive = ctx.Pipe(duplex=False)   # workers watch it; closes when we die
            procs = [ctx.Process(target=_worker, args=(out, cfg, seed, todo[w::workers], threads, queue,
                                                       os.getpid(), watch),
                                 daemon=True) for w in range(workers)]
            for p in procs:
                p.start()
            try:
                for _ in range(len(todo)):
                    status, payload, render_s = queue.get()
                    if status == "disk-full":
                        raise DiskFullError(payload)
                    if status == "user-error":
                        raise DatasetError(payload)
                    if status == "error":
                        raise DatasetError(f"a worker failed: {payload}")
                    append(payload, render_s)
            finally:
                for p in procs:
                    if p.is_alive():
                        p.terminate()
                    p.join()
                keep_alive.close()
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
                          threads=threads, progress=progress, stats=run)
    finally:
        stats.tasks, stats.task_s, stats.startup_s = run.tasks, run.task_s, run.startup_s


def load_spec(dataset_dir: str | os.PathLike, record: dict) -> SceneSpec:
    """The scene spec of a manifest record (path checked to stay inside the dataset)."""
    from relight.scene.spec import load_scene
    return load_scene(safe_join(dataset_dir, record["scene"]))


def safe_join(dataset_dir: str | os.PathLike, relative: str) -> str:
    """Join a relative path from a manifest or predictions file to a dataset folder,
    refusing anything that escapes it (absolute paths, ``..``)."""
    base = os.path.realpath(os.fspath(dataset_dir))
    if not isinstance(relative, str) or os.path.isabs(relative):
        raise DatasetError(f"expected a relative path inside the dataset, got {relative!r}")
    path = os.path.realpath(os.path.join(base, relative))
    if os.path.commonpath([base, path]) != base:
        raise DatasetError(f"path {relative!r} escapes the dataset folder")
    return path

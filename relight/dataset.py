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
"""
from __future__ import annotations

import json
import multiprocessing as mp
import os
import time
from dataclasses import dataclass

import numpy as np

from relight import frames
from relight.scene.sampling import GeneratorConfig, sample_scene, split_of
from relight.scene.spec import SceneSpec

DATASET_FORMAT = "relight.dataset/v1"
MANIFEST = "manifest.jsonl"
CARD = "dataset.json"


class DatasetError(ValueError):
    """A dataset folder is missing, inconsistent or was made with other settings."""


@dataclass
class GenerateStats:
    """What a :func:`generate` call did and where its time went (seconds)."""
    written: int = 0
    skipped: int = 0
    total_s: float = 0.0
    render_s: float = 0.0

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
    }


def read_manifest(dataset_dir: str | os.PathLike, repair: bool = False) -> list[dict]:
    """Records of a dataset, in file order. A partial last line (a killed writer) is
    ignored, and cut off when ``repair`` is true. Raises :class:`DatasetError`."""
    path = os.path.join(os.fspath(dataset_dir), MANIFEST)
    if not os.path.isfile(path):
        raise DatasetError(f"{os.fspath(dataset_dir)}: no {MANIFEST} (not a relight dataset?)")
    with open(path, "rb") as f:
        data = f.read()
    records, good_end, pos = [], 0, 0
    while pos < len(data):
        nl = data.find(b"\n", pos)
        if nl < 0:
            break  # partial last line: its writer was killed
        line = data[pos:nl]
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            if data.find(b"\n", nl + 1) >= 0:
                raise DatasetError(f"{path}: corrupt record at byte {pos}") from None
            break
        records.append(rec)
        pos = good_end = nl + 1
    if repair and good_end < len(data):
        with open(path, "r+b") as f:
            f.truncate(good_end)
    return records


def read_card(dataset_dir: str | os.PathLike) -> dict:
    """The dataset card (settings it was made with)."""
    path = os.path.join(os.fspath(dataset_dir), CARD)
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, json.JSONDecodeError) as exc:
        raise DatasetError(f"cannot read dataset card {path}: {exc}") from None


def _write_card(out: str, seed: int, cfg: GeneratorConfig, count: int) -> None:
    card_path = os.path.join(out, CARD)
    settings = {"format": DATASET_FORMAT, "seed": int(seed), "config": cfg.to_dict()}
    if os.path.isfile(card_path):
        old = read_card(out)
        same = {k: old.get(k) for k in settings}
        if json.loads(json.dumps(same)) != json.loads(json.dumps(settings)):
            raise DatasetError(f"{out} holds a dataset made with other settings (seed or config); "
                               "use another --out or the same settings to resume")
        count = max(count, int(old.get("count", 0)))
    card = {**settings, "count": int(count),
            "description": "SID2-style synthetic dataset rendered with Mitsuba 3 by relight "
                           "(Sial et al., 'Light Direction and Color Estimation from Single Image "
                           "with Deep Regression')",
            "split_rule": "sha256(id) -> train/val/test by config.split fractions"}
    tmp = card_path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(card, f, indent=1)
    os.replace(tmp, card_path)


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
    from relight.render import write_exr, write_png
    spec.save(os.path.join(out, "scenes", f"{spec.id}.json"))
    write_exr(os.path.join(out, "exr", f"{spec.id}.exr"), image)
    write_png(os.path.join(out, "images", f"{spec.id}.png"), image)
    return record_for(spec, split)


def _pipeline(out: str, cfg: GeneratorConfig, seed: int, indices: list[int], on_record) -> None:
    """Generate ``indices`` in order with three overlapping stages: prepare the next
    scene and write the previous image while Mitsuba renders the current one.
    ``on_record(record, render_s)`` is called in index order from the writer thread,
    only after the image's files are complete."""
    from concurrent.futures import ThreadPoolExecutor

    from relight.scene.build import SceneBuilder
    builder = SceneBuilder()
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


def _worker(out, cfg, seed, indices, threads, queue):
    from relight import backend
    try:
        backend.init(threads=threads)
        _pipeline(out, cfg, seed, indices, lambda record, render_s: queue.put(("ok", record, render_s)))
    except BaseException as exc:  # report to the parent, which stops cleanly
        queue.put(("error", f"{type(exc).__name__}: {exc}", 0.0))


def generate(out_dir: str | os.PathLike, count: int, seed: int = 0,
             cfg: GeneratorConfig | None = None, workers: int = 1, progress: bool = True,
             threads: int | None = None) -> GenerateStats:
    """Generate (or resume) a dataset of ``count`` images in ``out_dir``.

    Args:
        out_dir: dataset folder (created).
        count: total number of images wanted; existing records count.
        seed: dataset seed; image ``i`` depends only on (seed, i) and ``cfg``.
        cfg: generator settings (default :class:`GeneratorConfig`).
        workers: processes rendering in parallel (each gets cores / workers threads).
        progress: show a progress bar (images/s) on stderr.
        threads: Dr.Jit threads per process (default: cores / workers).
    """
    from tqdm import tqdm
    cfg = cfg or GeneratorConfig()
    if count < 0:
        raise DatasetError(f"count must be >= 0, got {count}")
    if workers < 1:
        raise DatasetError(f"workers must be >= 1, got {workers}")
    out = os.fspath(out_dir)
    for sub in ("images", "exr", "scenes"):
        os.makedirs(os.path.join(out, sub), exist_ok=True)
    _write_card(out, seed, cfg, count)
    manifest_path = os.path.join(out, MANIFEST)
    done = set()
    if os.path.exists(manifest_path):
        done = {r["id"] for r in read_manifest(out, repair=True)}
    todo = [i for i in range(count) if f"{i:06d}" not in done]
    stats = GenerateStats(skipped=count - len(todo))
    if not todo:
        return stats
    cores = os.cpu_count() or 1
    workers = min(workers, len(todo))
    threads = threads or max(1, cores // workers)
    bar = tqdm(total=len(todo), unit="img", disable=not progress, desc="generate", smoothing=0.1)
    t_start = time.perf_counter()
    with open(manifest_path, "ab") as manifest:
        def append(record, render_s):
            manifest.write((json.dumps(record) + "\n").encode())
            manifest.flush()
            os.fsync(manifest.fileno())
            stats.written += 1
            stats.render_s += render_s
            bar.update(1)

        if workers == 1:
            from relight import backend
            backend.init(threads=threads)
            _pipeline(out, cfg, seed, todo, append)
        else:
            ctx = mp.get_context("spawn")
            queue = ctx.Queue()
            procs = [ctx.Process(target=_worker, args=(out, cfg, seed, todo[w::workers], threads, queue),
                                 daemon=True) for w in range(workers)]
            for p in procs:
                p.start()
            try:
                for _ in range(len(todo)):
                    status, payload, render_s = queue.get()
                    if status == "error":
                        raise DatasetError(f"a worker failed: {payload}")
                    append(payload, render_s)
            finally:
                for p in procs:
                    if p.is_alive():
                        p.terminate()
                    p.join()
    stats.total_s = time.perf_counter() - t_start
    bar.close()
    return stats


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

"""Run per-image jobs on a Dask cluster: ``--scheduler local:N`` or ``--scheduler ADDRESS``.

The unit of work is a *shard*: a list of image indices rendered by one task in one
worker process. Each image depends only on its id and seed, so a shard's output is
byte-identical to what the single-process path writes. Tasks write their files
atomically and return the records; only the client (the calling process) appends
them to the manifest, and only once a task has finished, so resume, kill -9 safety
and "no duplicates" hold as in the single-process path. A worker killed mid-task
loses only that task, which Dask runs again elsewhere (its files are rewritten
with the same bytes); the client ignores a record it already appended.

Each worker process initialises Mitsuba/Dr.Jit once (:func:`relight.backend.init`)
and keeps one scene builder (loaded templates, compiled kernels) for all its tasks;
a lock serialises tasks within a process, so give workers one Dask thread each.
Workers must see the output folder at the same path (a shared file system).

Dask is an optional dependency (``pip install relight[dask]``); this module imports
it only when a scheduler is used.
"""
from __future__ import annotations

import contextlib
import math
import os
import re
import sys
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from relight.errors import EngineError

LOCAL_RE = re.compile(r"^local:(\d+)$")
CONNECT_TIMEOUT_S = 20
MAX_SHARD = 8          # images per task: small enough to balance load and to lose little to a kill
SHARDS_PER_WORKER = 4  # aim for at least this many tasks per worker


@dataclass(frozen=True)
class Scheduler:
    """Where to run: ``local`` worker processes (a LocalCluster) or a scheduler ``address``."""
    local: int = 0
    address: str = ""

    def __post_init__(self):
        if bool(self.local) == bool(self.address):
            raise EngineError("a scheduler is either local:N or an address, not both or neither")


def parse_scheduler(text: str) -> Scheduler:
    """``local:N`` (N worker processes, 1..256) or a Dask scheduler address
    with its port (``tcp://host:8786``, ``host:8786``). Raises :class:`EngineError`."""
    text = (text or "").strip()
    m = LOCAL_RE.match(text)
    if m:
        n = int(m.group(1))
        if not 1 <= n <= 256:
            raise EngineError(f"local:N needs N in [1, 256], got {text!r}")
        return Scheduler(local=n)
    if text.startswith("local"):
        raise EngineError(f"expected local:N with N a positive integer, got {text!r}")
    if not re.match(r"^([a-z]+://)?[^\s/:]+:\d{1,5}$", text):
        raise EngineError(f"expected local:N or a scheduler address like tcp://host:8786, got {text!r}")
    return Scheduler(address=text)


def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise EngineError("--scheduler needs Dask: pip install 'relight[dask]' "
                          "(or 'dask[distributed]')") from None
    return distributed


@contextlib.contextmanager
def client(scheduler: Scheduler, threads: int | None = None):
    """A Dask ``Client`` on a new LocalCluster (``local``: N processes, one Dask thread
    each) or attached to ``address``; closed (and the cluster stopped) on exit.

    Yields ``(client, threads_by_host)`` where ``threads_by_host`` maps a worker host
    to the Dr.Jit threads each of its worker processes should use (``threads`` if
    given, else the host's cores over its worker processes).
    """
    distributed = _import_distributed()
    import logging
    if os.environ.get("RELIGHT_WARNINGS") != "1":   # our one line says what went wrong
        for name in ["distributed", *logging.root.manager.loggerDict]:
            if name.startswith("distributed"):
                logging.getLogger(name).setLevel(logging.CRITICAL)
    cluster = None
    try:
        if scheduler.local:
            cluster = distributed.LocalCluster(
                n_workers=scheduler.local, threads_per_worker=1, processes=True,
                dashboard_address=":0",
                silence_logs=logging.CRITICAL)
            c = distributed.Client(cluster)
        else:
            c = distributed.Client(scheduler.address, timeout=CONNECT_TIMEOUT_S)
    except EngineError:
        raise
    except (OSError, TimeoutError, RuntimeError, ValueError) as exc:   # RuntimeError: a worker did not start
        if cluster is not None:
            cluster.close()
        where = f"local:{scheduler.local}" if scheduler.local else scheduler.address
        raise EngineError(f"cannot start or reach the Dask scheduler {where}: "
                          f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
    try:
        yield c, _threads_by_host(c, threads, scheduler.local)
    finally:
        with contextlib.suppress(Exception):
            c.close(timeout=5)
        if cluster is not None:
            with contextlib.suppress(Exception):
                cluster.close(timeout=10)


def _has_dashboard() -> bool:
    try:
        import bokeh  # noqa: F401
    except ImportError:
        return False
    return True


def dashboard_link(c, local: bool = False) -> str | None:
    """The dashboard address of a client's scheduler, or None when it has none (a local
    cluster serves the dashboard pages only when bokeh is installed)."""
    if local and not _has_dashboard():
        return None
    try:
        services = c.scheduler_info().get("services", {})
    except Exception:  # noqa: BLE001 - no dashboard information is not an error
        return None
    return c.dashboard_link if "dashboard" in services else None


def _threads_by_host(c, threads: int | None, local: int) -> dict[str, int]:
    workers = c.scheduler_info().get("workers", {})
    hosts = Counter(_host(addr) for addr in workers)
    if local:
        per = threads or max(1, (os.cpu_count() or 1) // local)
        return {h: per for h in hosts} | {"": per}
    return {h: threads or 0 for h in hosts} | {"": threads or 0}


def _host(address: str) -> str:
    return address.split("://")[-1].rsplit(":", 1)[0]


def n_workers(c) -> int:
    """Worker processes currently attached to the client's scheduler (at least 1)."""
    return max(1, len(c.scheduler_info().get("workers", {})))


def shards(indices: list[int], workers: int) -> list[list[int]]:
    """Split ``indices`` into consecutive shards of at most :data:`MAX_SHARD`, enough for
    :data:`SHARDS_PER_WORKER` tasks per worker when there are that many indices."""
    if not indices:
        return []
    size = max(1, min(MAX_SHARD, math.ceil(len(indices) / (workers * SHARDS_PER_WORKER))))
    return [indices[i:i + size] for i in range(0, len(indices), size)]


# --- worker side ---------------------------------------------------------------------

_worker_state: dict = {}
_worker_lock = threading.Lock()


def _worker_threads(threads_by_host: dict[str, int]) -> int:
    try:
        from distributed import get_worker
        host = _host(get_worker().address)
    except (ImportError, ValueError):
        host = ""
    n = threads_by_host.get(host, threads_by_host.get("", 0))
    if n:
        return n
    return int(os.environ.get("RELIGHT_THREADS", 0)) or os.cpu_count() or 1


@dataclass
class ShardResult:
    """What one task did: its records (index order) and where its time went (seconds)."""
    records: list = field(default_factory=list)
    render_s: list = field(default_factory=list)
    task_s: float = 0.0
    pid: int = 0


def render_shard(out: str, cfg, seed: int, indices: list[int], threads_by_host: dict) -> ShardResult:
    """Task body (in a worker process): render and write ``indices`` of the dataset in
    ``out`` with the same three-stage pipeline as the single-process path; returns the
    records once every image's files are in place. Mitsuba is initialised and the scene
    builder made once per process."""
    from relight import backend
    from relight.dataset import _pipeline
    with _worker_lock:
        t0 = time.perf_counter()
        backend.init(threads=_worker_threads(threads_by_host))
        if "builder" not in _worker_state:
            from relight.scene.build import SceneBuilder
            _worker_state["builder"] = SceneBuilder()
        result = ShardResult(pid=os.getpid())

        def collect(record, render_s):
            result.records.append(record)
            result.render_s.append(render_s)
        _pipeline(out, cfg, seed, indices, collect, builder=_worker_state["builder"])
        result.task_s = time.perf_counter() - t0
        return result


# --- client side ---------------------------------------------------------------------

def run_shards(c, threads_by_host: dict, out: str, cfg, seed: int, todo: list[int], on_result) -> int:
    """Submit ``todo`` as shards to client ``c`` and call ``on_result(ShardResult)`` in
    this thread as each task finishes (any order). Returns the number of tasks.

    Raises :class:`EngineError` when the scheduler is lost or a task keeps failing.
    """
    distributed = _import_distributed()
    parts = shards(todo, n_workers(c))
    try:
        futures = [c.submit(render_shard, out, cfg, seed, part, threads_by_host, pure=False,
                            key=f"relight-shard-{part[0]:06d}-{time.monotonic_ns()}")
                   for part in parts]
        for fut in distributed.as_completed(futures):
            if fut.status == "error":   # the task itself raised (not a lost worker or scheduler)
                exc = fut.exception()
                if type(exc).__name__ == "KilledWorker":
                    raise EngineError(_lost_message(exc))
                raise EngineError(f"a task failed: {type(exc).__name__}: {exc}")
            on_result(fut.result())
            fut.release()
    except EngineError:
        raise
    except (OSError, TimeoutError, distributed.client.FutureCancelledError) as exc:
        raise EngineError(_lost_message(exc)) from None
    except Exception as exc:   # noqa: BLE001 - classify Dask's own failures
        if type(exc).__name__ in ("KilledWorker", "CancelledError", "CommClosedError"):
            raise EngineError(_lost_message(exc)) from None
        raise
    return len(parts)


def _lost_message(exc: BaseException) -> str:
    name = type(exc).__name__
    if name == "KilledWorker":
        return ("a task killed its workers repeatedly (out of memory?); re-run the same command "
                "to resume")
    return f"lost the Dask scheduler ({name}); re-run the same command to resume"


def describe(c, local: bool = False) -> str:
    """One line for stderr: worker count and the dashboard when there is one."""
    link = dashboard_link(c, local)
    text = f"dask: {n_workers(c)} worker processes"
    return text + (f", dashboard {link}" if link else "")


def announce(c, local: bool = False) -> None:
    """Print :func:`describe` on stderr above a progress bar."""
    from tqdm import tqdm
    tqdm.write(describe(c, local), file=sys.stderr)

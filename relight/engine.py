"""Run per-image jobs on a Dask cluster: ``--scheduler local:N`` or ``--scheduler ADDRESS``.

One engine for every verb that works image by image (``generate``, ``compare``,
``invert``, ``evaluate``, ``baseline``). The caller gives a *task function* and a
picklable *context*; the unit of work is a *shard*, a list of image ids (or indices)
that one task handles in one worker process::

    def my_shard(context, shard):      # module level, so workers import it by name
        return [work(context, i) for i in shard]

    engine.map_shards("local:2", my_shard, context, ids, on_result)

``on_result(shard, value)`` runs in the calling process (the *client*) as each task
finishes, in completion order; the client alone writes the verb's outputs, from the
gathered values, exactly as its single-process path does, so the outputs are
byte-identical. Each image's result depends only on its id (and seed), never on the
worker or the shard it ran in. A worker killed mid-task loses only that task, which
Dask runs again elsewhere; the client sees each shard's value once. The context is sent
once (a task of its own that the scheduler can recompute), not with every shard.

Each worker process initialises Mitsuba/Dr.Jit once (:func:`relight.backend.init`,
when the task function needs it), with a thread count of its cores: ``threads`` if the
caller gives it (``--threads``), else ``$RELIGHT_THREADS`` of the worker, else on a
``local:N`` cluster the machine's cores over N, and on a remote cluster the worker's
Dask thread count (``dask worker --nthreads``, dask-jobqueue's ``cores / processes``).
A lock serialises tasks within a process (they share one Mitsuba state), so a worker
with several Dask threads runs one task at a time with all of them in Dr.Jit. Task
functions keep per-process state (loaded scene templates) with :func:`worker_cache`.
On a machine with CUDA GPUs, ``local:N`` pins worker ``i`` to GPU ``i mod G``
(``CUDA_VISIBLE_DEVICES``): one worker per GPU with ``local:G``.
Workers must see the input and output folders at the same paths (a shared file system).

Dask (``dask[distributed]``, a dependency of relight) is imported only when a
scheduler is used: ``--scheduler``, or ``generate --workers N`` (``local:N``).

The command-line options live here too, so that following ``--scheduler`` from the
command line to the engine crosses three files: the command module (which calls
:func:`add_arguments` and hands :func:`scheduler_from_args` to its library function),
this module (the options, their checks, ``--workers N`` as ``local:N``, and their use)
and the library function that passes the scheduler on to :func:`map_shards`.
"""
from __future__ import annotations

__all__ = [
    "LOCAL_RE", "MAX_LOCAL", "CONNECT_TIMEOUT_S", "MAX_SHARD", "SHARDS_PER_WORKER", "Scheduler",
    "parse_scheduler", "as_scheduler", "for_workers", "fit_to_work", "scheduler_arg", "worker_count",
    "add_arguments", "scheduler_from_args", "local_worker_env", "client", "worker_threads", "dashboard_link",
    "n_workers", "shards",
    "worker_cache", "TaskResult", "run_task", "worker_info", "run_shards", "EngineStats", "map_shards",
    "describe", "announce", "map_ordered",
    "ShardPlan",
]

import argparse
import contextlib
import math
import os
import re
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

from relight.errors import ConfigError, EngineError, RelightError

LOCAL_RE = re.compile(r"^local:(\d+)$")
MAX_LOCAL = 256        # worker processes of a local:N cluster (and of --workers N)
CONNECT_TIMEOUT_S = 20
MAX_SHARD = 8          # images per task: small enough to balance load and to lose little to a kill
SHARDS_PER_WORKER = 4  # aim for at least this many tasks per worker


@dataclass(frozen=True)
class Scheduler:
    """Where to run: ``local`` worker processes (a LocalCluster) or a scheduler ``address``.

    ``fit_to_work``: ``local`` is an upper bound, what ``--workers N`` asks for: at most
    one worker per item left, and none (this process) for a single item (see
    :func:`fit_to_work`); ``--scheduler local:N`` starts N workers whatever the work.
    """
    local: int = 0
    address: str = ""
    fit_to_work: bool = False

    def __post_init__(self):
        if bool(self.local) == bool(self.address):
            raise EngineError("a scheduler is either local:N or an address, not both or neither")
        if self.fit_to_work and not self.local:
            raise EngineError("only a local:N scheduler is fitted to the work")


def parse_scheduler(text: str) -> Scheduler:
    """``local:N`` (N worker processes, 1..256) or a Dask scheduler address
    with its port (``tcp://host:8786``, ``host:8786``). Raises :class:`EngineError`."""
    text = (text or "").strip()
    m = LOCAL_RE.match(text)
    if m:
        n = int(m.group(1))
        if not 1 <= n <= MAX_LOCAL:
            raise EngineError(f"local:N needs N in [1, {MAX_LOCAL}], got {text!r}")
        return Scheduler(local=n)
    if text.startswith("local"):
        raise EngineError(f"expected local:N with N a positive integer, got {text!r}")
    if not re.match(r"^([a-z]+://)?[^\s/:]+:\d{1,5}$", text):
        raise EngineError(f"expected local:N or a scheduler address like tcp://host:8786, got {text!r}")
    return Scheduler(address=text)


def as_scheduler(scheduler) -> Scheduler | None:
    """``None``, a :class:`Scheduler` or its text (parsed) -> ``Scheduler | None``."""
    if scheduler is None or isinstance(scheduler, Scheduler):
        return scheduler
    if isinstance(scheduler, str):
        return parse_scheduler(scheduler)
    raise EngineError(f"expected local:N or a scheduler address, got {scheduler!r}")


def for_workers(workers: int) -> Scheduler | None:
    """What ``--workers N`` (``generate(workers=N)``) means on the engine.

    Args:
        workers: render processes asked for (>= 1).

    Returns:
        ``None`` for one (this process renders), else ``local:N`` fitted to the work
        (:func:`fit_to_work`).

    >>> for_workers(1) is None, for_workers(2).local
    (True, 2)
    """
    return Scheduler(local=workers, fit_to_work=True) if workers > 1 else None


def fit_to_work(scheduler: Scheduler | None, items: int) -> Scheduler | None:
    """The scheduler to run ``items`` pieces of work on: a ``--workers N`` scheduler
    (``fit_to_work``) starts at most one worker per item, and for a single item none
    (``None``: this process does the work); any other scheduler is returned as it is.

    Args:
        scheduler: ``None`` or a :class:`Scheduler`.
        items: pieces of work left (images to render), >= 1.

    Returns:
        ``Scheduler | None``.

    >>> fit_to_work(for_workers(4), 2).local, fit_to_work(for_workers(4), 1)
    (2, None)
    >>> fit_to_work(parse_scheduler("local:4"), 1).local
    4
    """
    if scheduler is None or not scheduler.fit_to_work:
        return scheduler
    n = min(scheduler.local, items)
    return Scheduler(local=n, fit_to_work=True) if n > 1 else None


# --- the command-line options of every verb that runs on the engine -----------------

def scheduler_arg(text: str) -> Scheduler:
    """The argparse type of ``--scheduler``: :func:`parse_scheduler`, its error one line.

    Args:
        text: the option's value, ``local:N`` or ``tcp://host:8786``.

    Returns:
        The :class:`Scheduler`; bad text raises ``argparse.ArgumentTypeError``.
    """
    try:
        return parse_scheduler(text)
    except EngineError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def worker_count(text: str) -> int:
    """The argparse type of ``--workers``: an integer in ``[1, MAX_LOCAL]``.

    Args:
        text: the option's value.

    Returns:
        The process count; bad text raises ``argparse.ArgumentTypeError``.
    """
    try:
        n = int(text)
    except (ValueError, OverflowError):
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if not 1 <= n <= MAX_LOCAL:
        raise argparse.ArgumentTypeError(f"expected a process count in [1, {MAX_LOCAL}], got {text!r}")
    return n


def add_arguments(parser, work: str = "the images", workers: bool = False) -> None:
    """Add ``--scheduler local:N | ADDRESS`` (and with ``workers`` also ``--workers N``) to
    the parser of a verb that runs on the engine; read them back with
    :func:`scheduler_from_args`.

    Args:
        parser: an ``argparse`` (sub)parser.
        work: what runs on the engine, for the help text ("the re-renders").
        workers: also add ``--workers N`` (N processes on this machine: ``local:N``).
    """
    if workers:
        parser.add_argument("--workers", type=worker_count, default=1,
                            help="parallel render processes (default 1)")
    parser.add_argument("--scheduler", type=scheduler_arg, default=None, metavar="local:N|ADDRESS",
                        help=f"run {work} on Dask: local:N (N worker processes on this machine, one "
                             "per GPU when there are GPUs) or the address of a running scheduler "
                             "(tcp://host:8786; workers must see the files at the same paths); the "
                             "same output as the default, this process"
                             + (" (see --workers)" if workers else ""))


def scheduler_from_args(args) -> Scheduler | None:
    """The scheduler the options of :func:`add_arguments` ask for.

    Args:
        args: parsed arguments with ``scheduler`` (and ``workers`` when the verb has it).

    Returns:
        The ``--scheduler`` given, else ``local:N`` for ``--workers N`` (N > 1, fitted to
        the work: :func:`fit_to_work`), else ``None`` (this process).

    Raises:
        ConfigError: ``--workers`` and ``--scheduler`` both given (one line, exit 2).

    >>> parser = argparse.ArgumentParser()
    >>> add_arguments(parser, workers=True)
    >>> scheduler_from_args(parser.parse_args(["--workers", "2"])).local
    2
    >>> scheduler_from_args(parser.parse_args(["--scheduler", "tcp://node1:8786"])).address
    'tcp://node1:8786'
    >>> scheduler_from_args(parser.parse_args([])) is None
    True
    """
    scheduler, workers = args.scheduler, getattr(args, "workers", 1)
    if scheduler is not None and workers != 1:
        raise ConfigError("--workers and --scheduler exclude each other (local:N gives N workers)")
    return scheduler if scheduler is not None else for_workers(workers)


def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise EngineError("--workers N and --scheduler need Dask: pip install 'dask[distributed]' "
                          "(a dependency of relight)") from None
    return distributed


def local_worker_env(n: int, gpus: list[str]) -> list[dict]:
    """The extra environment of each of ``n`` local workers: with GPUs, worker ``i``
    sees only GPU ``gpus[i % len(gpus)]`` (``CUDA_VISIBLE_DEVICES``); else nothing."""
    return [{"CUDA_VISIBLE_DEVICES": gpus[i % len(gpus)]} if gpus else {} for i in range(n)]


def _local_cluster(distributed, n: int, logging):
    from relight import backend
    gpus = backend.cuda_devices()
    if not gpus:
        return distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                        dashboard_address=":0", silence_logs=logging.CRITICAL)
    workers = {i: {"cls": distributed.Nanny,
                   "options": {"nthreads": 1, "env": env, "host": "127.0.0.1",
                               "silence_logs": logging.CRITICAL}}
               for i, env in enumerate(local_worker_env(n, gpus))}
    scheduler = {"cls": distributed.Scheduler,
                 "options": {"host": "127.0.0.1", "dashboard_address": ":0"}}
    return distributed.SpecCluster(workers=workers, scheduler=scheduler, silence_logs=logging.CRITICAL)


@contextlib.contextmanager
def client(scheduler: Scheduler | str, threads: int | None = None):
    """A Dask ``Client`` on a new local cluster (``local``: N processes, one Dask thread
    each, one GPU each when there are GPUs) or attached to ``address``; closed (and the
    cluster stopped) on exit.

    Yields ``(client, threads)``: the Dr.Jit threads a worker process uses (``threads``
    if given, else ``$RELIGHT_THREADS`` of this process, else for ``local:N`` the cores
    over N; 0 means "decide in the worker": its Dask thread count).
    """
    scheduler = as_scheduler(scheduler)
    distributed = _import_distributed()
    import logging
    if os.environ.get("RELIGHT_WARNINGS") != "1":   # our one line says what went wrong
        for name in ["distributed", *logging.root.manager.loggerDict]:
            if name.startswith("distributed"):
                logging.getLogger(name).setLevel(logging.CRITICAL)
    cluster = None
    try:
        if scheduler.local:
            cluster = _local_cluster(distributed, scheduler.local, logging)
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
        yield c, worker_threads(threads, scheduler.local)
    finally:
        with contextlib.suppress(Exception):
            c.close(timeout=5)
        if cluster is not None:
            with contextlib.suppress(Exception):
                cluster.close(timeout=10)


def worker_threads(threads: int | None, local: int) -> int:
    """Dr.Jit threads for each worker process, decided in the client: ``threads``, else
    ``$RELIGHT_THREADS``, else for ``local:N`` this machine's cores over N; 0 for a
    remote cluster (each worker then uses its own Dask thread count)."""
    if threads:
        return int(threads)
    env = int(os.environ.get("RELIGHT_THREADS", 0) or 0)
    if env:
        return env
    return max(1, (os.cpu_count() or 1) // local) if local else 0


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


def n_workers(c) -> int:
    """Worker processes currently attached to the client's scheduler (at least 1)."""
    return max(1, len(c.scheduler_info().get("workers", {})))


def shards(indices: list, workers: int, size: int | None = None) -> list[list]:
    """Split ``indices`` into consecutive shards: of ``size`` if given, else of at most
    :data:`MAX_SHARD`, enough for :data:`SHARDS_PER_WORKER` tasks per worker when there
    are that many indices."""
    if not indices:
        return []
    if size is None:
        size = max(1, min(MAX_SHARD, math.ceil(len(indices) / (workers * SHARDS_PER_WORKER))))
    return [indices[i:i + size] for i in range(0, len(indices), size)]


# --- worker side ---------------------------------------------------------------------

_worker_state: dict = {}
_worker_lock = threading.Lock()


def worker_cache(key: str, make: Callable[[], Any]):
    """A per-process object (made once by ``make()``) that a task function keeps across
    its tasks, e.g. a scene builder with its loaded templates."""
    if key not in _worker_state:
        _worker_state[key] = make()
    return _worker_state[key]


def _dask_threads() -> int:
    try:
        from distributed import get_worker
        w = get_worker()
    except (ImportError, ValueError):
        return 0
    state = getattr(w, "state", None)
    return int(getattr(state, "nthreads", 0) or getattr(w, "nthreads", 0) or 0)


def _threads_here(threads: int) -> int:
    """The Dr.Jit thread count of this worker process (see :func:`worker_threads`)."""
    return (threads or int(os.environ.get("RELIGHT_THREADS", 0) or 0) or _dask_threads()
            or os.cpu_count() or 1)


@dataclass
class TaskResult:
    """What one task returned, with its wall time (seconds) and worker process id."""
    value: Any
    task_s: float = 0.0
    pid: int = 0


def _identity(x):
    return x


def run_task(fn: Callable, context, shard: list, threads: int, mitsuba: bool = True) -> TaskResult:
    """Task body (in a worker process): initialise Mitsuba once per process (with
    :func:`_threads_here` threads) when ``mitsuba``, then ``fn(context, shard)``."""
    with _worker_lock:
        t0 = time.perf_counter()
        if mitsuba:
            from relight import backend
            n = _threads_here(threads)
            if _worker_state.get("threads") != n:
                backend.init(threads=n)
                _worker_state["threads"] = n
        value = fn(context, shard)
        return TaskResult(value, time.perf_counter() - t0, os.getpid())


def worker_info(context, shard) -> dict:
    """A task function that reports its worker: pid, Dr.Jit threads, Mitsuba variant and
    ``CUDA_VISIBLE_DEVICES`` (for tests and for checking a cluster)."""
    from relight import backend
    mi = backend.mitsuba()
    return {"pid": os.getpid(), "threads": int(backend.drjit().thread_count()),
            "variant": mi.variant(), "cuda_visible_devices": os.environ.get("CUDA_VISIBLE_DEVICES"),
            "shard": list(shard)}


# --- client side ---------------------------------------------------------------------

def run_shards(c, fn: Callable, context, parts: list[list], on_result: Callable, threads: int = 0,
               mitsuba: bool = True) -> int:
    """Submit ``fn(context, part)`` for each of ``parts`` to client ``c`` and call
    ``on_result(part, TaskResult)`` in this thread as each task finishes (any order).
    ``threads``: Dr.Jit threads per worker (0: the worker decides). Returns the number
    of tasks.

    Raises :class:`EngineError` when the scheduler is lost or a task keeps failing.
    """
    distributed = _import_distributed()
    if not parts:
        return 0
    stamp = time.monotonic_ns()
    try:
        ctx = c.submit(_identity, context, pure=False, key=f"relight-context-{stamp}")
        futures = {c.submit(run_task, fn, ctx, part, threads, mitsuba, pure=False,
                            key=f"relight-shard-{k:06d}-{stamp}"): part
                   for k, part in enumerate(parts)}
        for fut in distributed.as_completed(list(futures)):
            if fut.status == "error":   # the task itself raised (not a lost worker or scheduler)
                exc = fut.exception()
                if type(exc).__name__ == "KilledWorker":
                    raise EngineError(_lost_message(exc))
                if isinstance(exc, RelightError):   # bad input met in a worker: the user's to fix
                    raise exc
                raise EngineError(f"a task failed: {type(exc).__name__}: {exc}")
            on_result(futures[fut], fut.result())
            fut.release()
        ctx.release()
    except EngineError:
        raise
    except (OSError, TimeoutError, distributed.client.FutureCancelledError) as exc:
        raise EngineError(_lost_message(exc)) from None
    except Exception as exc:   # noqa: BLE001 - classify Dask's own failures
        if type(exc).__name__ in ("KilledWorker", "CancelledError", "CommClosedError"):
            raise EngineError(_lost_message(exc)) from None
        raise
    return len(parts)


@dataclass
class EngineStats:
    """What a :func:`map_shards` call did: tasks, their summed wall time and the time
    to start or reach the cluster (seconds)."""
    tasks: int = 0
    task_s: float = 0.0
    startup_s: float = 0.0


@dataclass(frozen=True)
class ShardPlan:
    """How :func:`map_shards` runs a verb's shards (every field has the usual default).

    >>> ShardPlan(shard_size=1, mitsuba=False)
    ShardPlan(threads=None, mitsuba=False, shard_size=1, progress=True)
    """
    threads: int | None = None      # Dr.Jit threads per worker process (None: the worker decides)
    mitsuba: bool = True            # the task function needs Mitsuba (initialised once per process)
    shard_size: int | None = None   # ids per task (None: see :func:`shards`)
    progress: bool = True           # print the worker count and dashboard on stderr


def map_shards(scheduler, fn: Callable, context, ids: list, on_result: Callable,
               plan: ShardPlan = ShardPlan(), stats: EngineStats | None = None) -> EngineStats:
    """Run ``fn(context, shard)`` over shards of ``ids`` on ``scheduler`` (``local:N``,
    an address or a :class:`Scheduler`) and call ``on_result(shard, value)`` here, in
    the client, as each shard finishes. ``fn`` must be a module-level function and
    ``context`` picklable; ``plan``: threads, Mitsuba, shard size and progress
    (:class:`ShardPlan`; with ``progress`` the worker count and dashboard go to stdout).
    ``stats`` is filled as the run goes (also when it fails)."""
    scheduler = as_scheduler(scheduler)
    stats = stats if stats is not None else EngineStats()
    t0 = time.perf_counter()
    with client(scheduler, plan.threads) as (c, n_threads):
        stats.startup_s = time.perf_counter() - t0
        if plan.progress:
            announce(c, local=bool(scheduler.local))

        def done(part, result: TaskResult):
            stats.tasks += 1
            stats.task_s += result.task_s
            on_result(part, result.value)
        run_shards(c, fn, context, shards(list(ids), n_workers(c), plan.shard_size), done, n_threads,
                   plan.mitsuba)
    return stats


def _lost_message(exc: BaseException) -> str:
    name = type(exc).__name__
    if name == "KilledWorker":
        return ("a task killed its workers repeatedly (out of memory?); re-run the same command "
                "to resume")
    return f"lost the Dask scheduler ({name}); re-run the same command to resume"


def describe(c, local: bool = False) -> str:
    """One line for stdout: worker count and the dashboard when there is one."""
    link = dashboard_link(c, local)
    text = f"dask: {n_workers(c)} worker processes"
    return text + (f", dashboard {link}" if link else "")


def announce(c, local: bool = False) -> None:
    """Print :func:`describe` on stdout, with a command's other reports (stderr carries
    progress bars and, for bad input, the one error line alone)."""
    from tqdm import tqdm
    tqdm.write(describe(c, local), file=sys.stdout)


def map_ordered(scheduler, fn: Callable, context, n: int, desc: str, plan: ShardPlan = ShardPlan(),
                bar: bool = True) -> list:
    """The per-item values of ``fn(context, shard)`` (a list per shard) for items
    ``0..n-1``, gathered here in item order under one progress bar (``desc``, items/s);
    ``bar``: show the bar (with ``plan.progress``); ``plan`` as for :func:`map_shards`. The
    gathering verbs (compare, invert, baseline) use it, so their outputs are written by the
    client exactly as on one process."""
    from tqdm import tqdm
    values = [None] * n
    pbar = tqdm(total=n, desc=desc, unit="img", disable=None if plan.progress and bar else True)

    def on_result(shard, shard_values):
        for k, value in zip(shard, shard_values):
            values[k] = value
        pbar.update(len(shard))
    try:
        map_shards(scheduler, fn, context, list(range(n)), on_result, plan)
    finally:
        pbar.close()
    return values

"""Where time goes: an optional stage timer for the generator pipeline (and the render path).

:class:`StageTimer` is passed down the generator (``generate(..., timer=...)``) to the
places that do the work: scene sampling, meshes, textures, template update, tracing,
the render kernel, readback and each write. Each ``with timer.stage(name):`` adds its
wall time to the current image (set per thread by ``with timer.image(i):``) and thread.
Without a timer the code gets :data:`NO_TIMER`, whose stages are one shared empty
context manager (no clock read, no lock), so an untimed run pays nothing measurable.

Dr.Jit launches kernels asynchronously: ``mi.render`` returns once the kernel is
traced and queued, and it runs while Python goes on (the template's acceleration
structure is also built in the background). A stage opened with ``sync=True`` waits
for that work (``dr.sync_thread``) before it closes, so with a timer the kernel's run
lands in its own stage ("render: kernel") instead of in whatever reads the image next.
The timer is given the ``drjit`` module (``relight.backend.drjit()``) to do both; it
imports nothing itself. With ``kernels=True`` it also reads Dr.Jit's kernel history
(``dr.kernel_history``: execution, IR generation and compile times of every kernel)
after each synchronised stage of the thread that renders; the time those reads take
is itself a stage (``profiler: kernel history``), so the stages still add up to the
wall time.
"""
from __future__ import annotations

__all__ = [
    "StageTimer", "NO_TIMER", "KernelStats", "kernel_stats",
]

import contextlib
import threading
import time
from collections import defaultdict
from dataclasses import dataclass

PROFILER_STAGE = "profiler: kernel history"


@dataclass
class KernelStats:
    """Summed Dr.Jit kernel history (milliseconds)."""
    jit_kernels: int = 0        # just-in-time compiled kernels launched
    jit_exec_ms: float = 0.0    # their execution time
    largest_ms: float = 0.0     # the longest one (the path-tracing kernel of a render)
    codegen_ms: float = 0.0     # generating their IR (needed even when cached)
    compile_ms: float = 0.0     # LLVM/PTX compilation (cache misses only)
    cache_misses: int = 0       # kernels found in no cache (compiled)
    disk_loads: int = 0         # kernels loaded from the on-disk cache
    other_ops: int = 0          # memcpy, memset, reductions, host functions
    other_exec_ms: float = 0.0

    def add(self, other: "KernelStats") -> None:
        for name in self.__dataclass_fields__:
            if name == "largest_ms":
                self.largest_ms = max(self.largest_ms, other.largest_ms)
            else:
                setattr(self, name, getattr(self, name) + getattr(other, name))


def kernel_stats(history: list[dict], dr) -> KernelStats:
    """Sum one ``dr.kernel_history()`` list (its times are in milliseconds); ``dr``: the
    ``drjit`` module."""
    s = KernelStats()
    for k in history:
        if k["type"] == dr.KernelType.JIT:
            s.jit_kernels += 1
            s.jit_exec_ms += k["execution_time"]
            s.largest_ms = max(s.largest_ms, k["execution_time"])
            s.codegen_ms += k.get("codegen_time", 0.0)
            s.compile_ms += k.get("backend_time", 0.0)
            s.disk_loads += bool(k.get("cache_disk", False))
            s.cache_misses += not (k.get("cache_hit", True) or k.get("cache_disk", False))
        else:
            s.other_ops += 1
            s.other_exec_ms += k["execution_time"]
    return s


class _NoTimer:
    """The timer of an untimed run: every stage is the same empty context."""
    enabled = False
    _null = contextlib.nullcontext()

    def stage(self, name: str, sync: bool = False):   # noqa: ARG002 - same signature as StageTimer
        return self._null

    def image(self, index: int):   # noqa: ARG002
        return self._null


NO_TIMER = _NoTimer()


class StageTimer:
    """Wall time per (image, stage, thread), optionally with Dr.Jit's kernel history.

    Args:
        drjit: the ``drjit`` module (``relight.backend.drjit()``), needed by ``sync`` and
            ``kernels``; without it stages only read the clock.
        kernels: read Dr.Jit's kernel history after synchronised stages (turns on
            ``JitFlag.KernelHistory`` while the timer is active; :meth:`close` restores it).
        sync: honour ``sync=True`` stages (wait for Dr.Jit's queued work); off, stages
            only read the clock and the kernel's run falls in the stage that reads its result.

    A stage opened inside another one is counted in its own row, and its time is taken
    out of the outer one (the outer row keeps only its own time), so the rows of one
    thread never count a second twice.
    """
    enabled = True

    def __init__(self, drjit=None, kernels: bool = False, sync: bool = True):
        if drjit is None and kernels:
            raise ValueError("reading the kernel history needs the drjit module (drjit=...)")
        self.kernels = kernels
        self.sync = sync and drjit is not None
        self.seconds: dict[tuple, float] = defaultdict(float)   # (image, stage, thread) -> s
        self.counts: dict[tuple, int] = defaultdict(int)
        self.kernel: dict[tuple, KernelStats] = defaultdict(KernelStats)  # (image, stage) -> stats
        self._lock = threading.Lock()
        self._local = threading.local()
        self._dr = drjit
        self._old_flag = None
        self._dr_thread = None
        if kernels:
            self._dr_thread = threading.get_ident()
            self._old_flag = self._dr.flag(self._dr.JitFlag.KernelHistory)
            self._dr.kernel_history_clear()
            self._dr.set_flag(self._dr.JitFlag.KernelHistory, True)

    def close(self) -> None:
        """Restore Dr.Jit's kernel-history flag (and drop any history left)."""
        if self._old_flag is not None:
            self._dr.kernel_history_clear()
            self._dr.set_flag(self._dr.JitFlag.KernelHistory, self._old_flag)
            self._old_flag = None

    @contextlib.contextmanager
    def image(self, index: int):
        """Attribute the stages this thread runs inside the block to image ``index``."""
        old = getattr(self._local, "image", None)
        self._local.image = index
        try:
            yield
        finally:
            self._local.image = old

    @contextlib.contextmanager
    def stage(self, name: str, sync: bool = False):
        """Time the block as stage ``name`` of the current image; ``sync``: wait for
        Dr.Jit's queued kernels before closing (their run is part of this stage)."""
        local = self._local
        stack = getattr(local, "stack", None)
        if stack is None:
            stack = local.stack = []
        stack.append(0.0)   # time of stages nested in this one
        t0 = time.perf_counter()
        try:
            yield
            if sync and self.sync:
                self._dr.sync_thread()
        finally:
            elapsed = time.perf_counter() - t0
            nested = stack.pop()
            if stack:
                stack[-1] += elapsed
            self._add(getattr(local, "image", None), name, elapsed - nested)
        if sync and self.kernels and threading.get_ident() == self._dr_thread:
            self._read_history(getattr(local, "image", None), name)

    def _add(self, image, name: str, seconds: float) -> None:
        key = (image, name, threading.current_thread().name)
        with self._lock:
            self.seconds[key] += seconds
            self.counts[key] += 1

    def _read_history(self, image, name: str) -> None:
        t0 = time.perf_counter()
        stats = kernel_stats(self._dr.kernel_history(), self._dr)
        with self._lock:
            self.kernel[(image, name)].add(stats)
        elapsed = time.perf_counter() - t0
        stack = self._local.stack
        if stack:
            stack[-1] += elapsed
        self._add(image, PROFILER_STAGE, elapsed)

    # ---- reading the results -------------------------------------------------------------

    def images(self) -> list:
        """The image indices that have stages, sorted (``None``: outside any image)."""
        return sorted({k[0] for k in self.seconds if k[0] is not None})

    def stages(self) -> list[str]:
        """Stage names in the order they were first timed."""
        return list(dict.fromkeys(k[1] for k in self.seconds))

    def threads(self) -> list[str]:
        return list(dict.fromkeys(k[2] for k in self.seconds))

    def total(self, stage: str | None = None, thread: str | None = None, image=...) -> float:
        """Seconds summed over the keys matching ``stage``, ``thread`` and ``image``
        (each ``None``/omitted: any)."""
        return sum(s for (i, n, t), s in self.seconds.items()
                   if (stage is None or n == stage) and (thread is None or t == thread)
                   and (image is ... or i == image))

    def per_image(self, image) -> dict[str, float]:
        """Stage -> seconds of one image (all threads)."""
        out: dict[str, float] = defaultdict(float)
        for (i, n, _), s in self.seconds.items():
            if i == image:
                out[n] += s
        return dict(out)

    def kernels_total(self, stage: str | None = None) -> KernelStats:
        total = KernelStats()
        for (_, n), s in self.kernel.items():
            if stage is None or n == stage:
                total.add(s)
        return total

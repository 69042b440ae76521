"""Rendering backend set-up: a good libLLVM for Dr.Jit, the Mitsuba variant, threads, cache.

Dr.Jit 1.5's LLVM backend emits ``llvm.minimum/maximum``, which LLVM 14/15 cannot
select on x86-64: with such a libLLVM the whole process aborts ("LLVM ERROR: Cannot
select ... fminimum"). Dr.Jit honours ``DRJIT_LIBLLVM_PATH``, else tries
``libLLVM.so``, else the last ``/usr/lib/x86_64-linux-gnu/libLLVM*.so.*`` in sorted
order, which may be a bad one. So before Dr.Jit is imported :func:`init` sets
``DRJIT_LIBLLVM_PATH`` to a libLLVM >= 17 (the user's own choice is respected but
checked), verifies the version Dr.Jit then reports, and raises :class:`BackendError`
with what to install otherwise. Never import ``drjit`` or ``mitsuba`` before calling
:func:`init` (use :func:`mitsuba` to get the module).
"""
from __future__ import annotations

__all__ = [
    "MIN_LLVM_MAJOR", "INSTALL_HINT", "llvm_candidates", "choose_libllvm", "default_cache_dir", "init",
    "mitsuba", "drjit", "describe", "cuda_devices",
]

import ctypes
import glob
import os
import re
import sys
from relight.errors import BackendError

MIN_LLVM_MAJOR = 17
INSTALL_HINT = ("install Debian's libllvm19 (apt-get install libllvm19) or the pip wheel "
                "karellen-llvm-core, or point DRJIT_LIBLLVM_PATH at a libLLVM >= 17")

_state: dict = {}


def _llvm_version_of(path: str) -> tuple[int, int, int] | None:
    """Version of a libLLVM shared library via ``LLVMGetVersion`` (LLVM >= 16), else None."""
    try:
        lib = ctypes.CDLL(path)
    except OSError:
        return None
    fn = getattr(lib, "LLVMGetVersion", None)
    if fn is None:  # LLVM <= 15 lacks this symbol, and is too old for Dr.Jit anyway
        m = re.search(r"libLLVM[-.](?:so\.)?(\d+)", os.path.basename(path))
        return (int(m.group(1)), 0, 0) if m else None
    major, minor, patch = ctypes.c_uint(), ctypes.c_uint(), ctypes.c_uint()
    fn(ctypes.byref(major), ctypes.byref(minor), ctypes.byref(patch))
    return (major.value, minor.value, patch.value)


def _major_from_name(path: str) -> int:
    """Best-effort LLVM major version from a file name (0 when unknown)."""
    name = os.path.basename(path)
    for pattern in (r"libLLVM-(\d+)", r"libLLVM\.so\.(\d+)", r"llvm-(\d+)"):
        m = re.search(pattern, name if pattern != r"llvm-(\d+)" else path)
        if m:
            return int(m.group(1))
    return 0


def llvm_candidates() -> list[str]:
    """libLLVM files that may be >= 17, best first (newest system one, then pip wheels)."""
    system = []
    for pattern in ("/usr/lib/x86_64-linux-gnu/libLLVM*.so*", "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
                    "/usr/lib/llvm-*/lib/libLLVM*.so*", "/usr/lib64/libLLVM*.so*"):
        system += glob.glob(pattern)
    system = sorted({p for p in system if _major_from_name(p) >= MIN_LLVM_MAJOR},
                    key=lambda p: (-_major_from_name(p), len(p)))
    wheels = []
    for prefix in dict.fromkeys([sys.prefix, sys.base_prefix]):
        wheels += glob.glob(os.path.join(prefix, "lib", "libLLVM*.so*"))
    wheels = sorted(wheels, key=lambda p: (-_major_from_name(p), len(p)))
    return system + wheels


def choose_libllvm() -> str:
    """Path of a libLLVM >= 17 for Dr.Jit; respects a ``DRJIT_LIBLLVM_PATH`` the user set.

    Raises:
        BackendError: the user's choice is too old, or no good libLLVM is installed.
    """
    user = os.environ.get("DRJIT_LIBLLVM_PATH")
    if user:
        version = _llvm_version_of(user)
        if version is None:
            raise BackendError(f"DRJIT_LIBLLVM_PATH={user} cannot be loaded; {INSTALL_HINT}")
        if version[0] < MIN_LLVM_MAJOR:
            raise BackendError(f"DRJIT_LIBLLVM_PATH={user} is LLVM {version[0]}, but Dr.Jit needs "
                               f">= {MIN_LLVM_MAJOR}; {INSTALL_HINT}")
        return user
    for path in llvm_candidates():
        version = _llvm_version_of(path)
        if version is not None and version[0] >= MIN_LLVM_MAJOR:
            return path
    raise BackendError(f"no libLLVM >= {MIN_LLVM_MAJOR} found for Dr.Jit; {INSTALL_HINT}")


def default_cache_dir() -> str:
    """Dr.Jit kernel cache: ``$DRJIT_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/relight/drjit``."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "relight", "drjit")


def init(threads: int | None = None, variant: str | None = None):
    """Prepare Dr.Jit and Mitsuba once per process and return the ``mitsuba`` module.

    Args:
        threads: worker threads for Dr.Jit (default: ``$RELIGHT_THREADS`` or all cores).
            DRJIT_NUM_THREADS is ignored by Dr.Jit, so the count is set explicitly.
        variant: Mitsuba variant; default ``cuda_ad_rgb`` when a CUDA GPU is usable,
            else ``llvm_ad_rgb``.
    """
    if "mi" in _state:
        if threads is not None:
            _state["dr"].set_thread_count(int(threads))
        return _state["mi"]
    if "drjit" not in sys.modules:
        os.environ["DRJIT_LIBLLVM_PATH"] = choose_libllvm()
    os.environ.setdefault("DRJIT_CACHE_DIR", default_cache_dir())
    os.makedirs(os.environ["DRJIT_CACHE_DIR"], exist_ok=True)
    import drjit as dr
    import mitsuba as mi

    if variant is None:
        variant = "cuda_ad_rgb" if (_has_cuda(dr) and "cuda_ad_rgb" in mi.variants()) else "llvm_ad_rgb"
    if variant.startswith("llvm"):
        if not dr.has_backend(dr.JitBackend.LLVM):
            raise BackendError(f"Dr.Jit's LLVM backend did not start; {INSTALL_HINT}")
        version = tuple(dr.detail.llvm_version())
        if version[0] < MIN_LLVM_MAJOR:
            raise BackendError(f"Dr.Jit loaded LLVM {'.'.join(map(str, version))}, needs >= "
                               f"{MIN_LLVM_MAJOR}; {INSTALL_HINT}")
        _state["llvm_version"] = version
    mi.set_variant(variant)
    if threads is None:
        threads = int(os.environ.get("RELIGHT_THREADS", 0)) or os.cpu_count() or 1
    dr.set_thread_count(int(threads))
    _state.update(mi=mi, dr=dr, variant=variant)
    return mi


def _has_cuda(dr) -> bool:
    try:
        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # noqa: BLE001 - any driver problem means "no GPU"
        return False


def mitsuba():
    """The initialised ``mitsuba`` module (calls :func:`init` with defaults if needed)."""
    return _state["mi"] if "mi" in _state else init()


def drjit():
    """The initialised ``drjit`` module."""
    mitsuba()
    return _state["dr"]


def describe() -> str:
    """One line: variant, libLLVM path and version, threads, kernel cache."""
    mi = mitsuba()
    dr = _state["dr"]
    llvm = ".".join(map(str, _state.get("llvm_version", ()))) or "n/a"
    return (f"mitsuba {mi.__version__} variant={_state['variant']} libLLVM={llvm} "
            f"({os.environ.get('DRJIT_LIBLLVM_PATH')}) threads={dr.thread_count()} "
            f"cache={os.environ.get('DRJIT_CACHE_DIR')}")


def cuda_devices() -> list[str]:
    """The CUDA GPUs this process may use, as ``CUDA_VISIBLE_DEVICES`` entries, without
    starting Dr.Jit: the entries of ``$CUDA_VISIBLE_DEVICES`` when it is set (empty or
    ``-1``: none), else ``0..G-1`` for the G devices the CUDA driver reports (none when
    there is no driver). The Dask engine gives each local worker one of them."""
    visible = os.environ.get("CUDA_VISIBLE_DEVICES")
    if visible is not None:
        ids = [v.strip() for v in visible.split(",") if v.strip()]
        return [] if not ids or ids[0] == "-1" else ids
    try:
        lib = ctypes.CDLL("libcuda.so.1")
        count = ctypes.c_int(0)
        if lib.cuInit(0) != 0 or lib.cuDeviceGetCount(ctypes.byref(count)) != 0:
            return []
    except (OSError, AttributeError):
        return []
    return [str(i) for i in range(count.value)]

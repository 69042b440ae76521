"""Child processes that end with their parent.

relight runs Cycles in a separate Python (the bpy environment): an export, a render
worker, the probe set's renders. Such a child must not outlive the process that started
it: killed at any moment, a long job leaves no renderer running on. The parent marks the
child's environment (:func:`child_env`); the child, first thing, asks the kernel for
``SIGTERM`` when its parent dies (:func:`die_with_parent`; Linux ``prctl``), and exits at
once if the parent is already gone. Run by hand (no mark), a module is left alone.

The kernel sends the signal when the *thread* that started the child ends: start a child
from a thread that lives as long as the child is needed (relight starts them from the
main thread).
"""
from __future__ import annotations

__all__ = ["PARENT_ENV", "child_env", "die_with_parent"]

import ctypes
import ctypes.util
import os
import signal
import sys

PARENT_ENV = "RELIGHT_PARENT_PID"
_PR_SET_PDEATHSIG = 1


def child_env(env: dict | None = None) -> dict:
    """A copy of ``env`` (default: this process's) marking its holder as this process's child."""
    out = dict(os.environ if env is None else env)
    out[PARENT_ENV] = str(os.getpid())
    return out


def die_with_parent() -> None:
    """In a child started with :func:`child_env`: be sent ``SIGTERM`` when the parent
    dies, and exit now if it already has. Does nothing without the mark, and (beyond the
    check) where the kernel offers no parent-death signal."""
    parent = os.environ.pop(PARENT_ENV, "")   # (not passed on: a grandchild is not ours)
    if not parent.isdigit():
        return
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
    if os.getppid() != int(parent):     # the parent died before the request took hold
        raise SystemExit(1)

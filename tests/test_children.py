"""Child processes end with their parent (relight.children): a Cycles export, render worker
or probe-set render started by relight does not run on once the process that started it
is killed."""
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from relight.children import PARENT_ENV, child_env

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal is Linux's")

CHILD = "from relight.children import die_with_parent; die_with_parent(); import time; time.sleep(60)"


def _parent_code(marked: bool) -> str:
    # a parent that starts one child (marked as its own or not), says the child's pid, waits
    return textwrap.dedent(f"""
        import os, subprocess, sys, time
        from relight.children import child_env
        env = child_env() if {marked} else dict(os.environ)
        child = subprocess.Popen([sys.executable, "-c", {CHILD!r}], env=env)
        print(child.pid, flush=True)
        time.sleep(60)
    """)


def _alive(pid: int) -> bool:
    """Running (a zombie nobody has reaped yet counts as ended)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False


def _env():
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (REPO, os.environ.get("PYTHONPATH")) if p))
    env.pop(PARENT_ENV, None)
    return env


def _child_after_parent_killed(marked: bool) -> tuple[int, bool]:
    parent = subprocess.Popen([sys.executable, "-c", _parent_code(marked)], env=_env(), stdout=subprocess.PIPE,
                              text=True)
    try:
        pid = int(parent.stdout.readline())
        time.sleep(1.0)                     # the child is up and has asked for the signal
        assert _alive(pid)
    finally:
        parent.kill()                       # SIGKILL: no chance to clean up after itself
        parent.wait()
    deadline = time.monotonic() + 10.0
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    return pid, _alive(pid)


def test_a_marked_child_ends_when_its_parent_is_killed():
    pid, alive = _child_after_parent_killed(marked=True)
    if alive:
        os.kill(pid, signal.SIGKILL)
    assert not alive


def test_an_unmarked_child_outlives_its_parent():
    # the control: without the mark the same child runs on (so the test above can fail)
    pid, alive = _child_after_parent_killed(marked=False)
    if alive:
        os.kill(pid, signal.SIGKILL)
    assert alive


def test_a_child_whose_parent_is_already_gone_exits_at_once():
    code = "from relight.children import die_with_parent; die_with_parent(); print('ran')"
    stray = dict(_env(), **{PARENT_ENV: "1"})     # marked by a process that is not its parent
    done = subprocess.run([sys.executable, "-c", code], env=stray, capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and "ran" not in done.stdout
    done = subprocess.run([sys.executable, "-c", code], env=_env(), capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout.strip() == "ran"     # run by hand: left alone


def test_the_mark_names_this_process_and_is_not_passed_on():
    assert child_env({})[PARENT_ENV] == str(os.getpid())
    code = ("import os; from relight.children import die_with_parent, PARENT_ENV; die_with_parent(); "
            "print(PARENT_ENV in os.environ)")
    done = subprocess.run([sys.executable, "-c", code], env=child_env(_env()), capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0 and done.stdout.strip() == "False"

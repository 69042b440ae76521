"""Safe file output: atomic writes that never replace an input, multi-file transactions,
one writer per folder, and temporary names that readers recognise and skip.

Every file relight writes goes through :func:`atomic_write` (or a :class:`Transaction`
for commands that write several files): the bytes go to a temporary file beside the
target, named ``.NAME.relight-tmp-PID-TOKEN.EXT`` (unique per process and call), which
is renamed over the target only once complete. A command refuses, before any work,
an output that resolves to one of its inputs (:func:`check_outputs`), including the
files a dataset folder owns. A folder written by a long job (a dataset, a training
run) is held with an OS lock (:class:`FolderLock`) for the whole run; a second writer
gets :class:`OutputError`. Temporary files left by a killed process are removed by
the next writer (:func:`remove_temps`) and ignored by every folder reader
(:func:`is_temp_name`).
"""
from __future__ import annotations

import contextlib
import errno
import io
import os
import re
import secrets
import shutil
import sys
from relight.errors import OutputError

TEMP_MARK = ".relight-tmp-"
LOCK_NAME = ".relight.lock"
# Files and folders a relight dataset owns (nothing else may write them).
DATASET_OWNED = ("manifest.jsonl", "dataset.json", "images", "exr", "scenes", LOCK_NAME)
# Temporary names of this module, and the older ``NAME.tmpPID[.ext]`` / ``NAME.tmp`` forms.
_TEMP_RE = re.compile(r"\.relight-tmp-(\d+)-[0-9a-f]+|\.tmp(\d*)(?:\.[A-Za-z0-9]+)?$")


# --- names ---------------------------------------------------------------------------

def temp_path(path: str | os.PathLike) -> str:
    """A fresh temporary name beside ``path`` (same folder and extension, hidden)."""
    path = os.fspath(path)
    folder, name = os.path.split(path)
    stem, ext = os.path.splitext(name)
    return os.path.join(folder, f".{stem}{TEMP_MARK}{os.getpid()}-{secrets.token_hex(4)}{ext}")


def is_temp_name(name: str) -> bool:
    """True for a temporary file name (ours or an older relight's): readers skip these."""
    return _TEMP_RE.search(os.path.basename(name)) is not None


def remove_temps(folder: str | os.PathLike, subfolders: tuple[str, ...] = ("",)) -> int:
    """Delete temporary files in ``folder`` (and the given subfolders); returns how many.
    Call it only while holding the folder's :class:`FolderLock`: then no live writer
    owns any of them (they were left by killed processes)."""
    n = 0
    for sub in subfolders:
        d = os.path.join(os.fspath(folder), sub)
        try:
            names = os.listdir(d)
        except (FileNotFoundError, NotADirectoryError):
            continue
        for name in names:
            p = os.path.join(d, name)
            if is_temp_name(name) and os.path.isfile(p) and not os.path.islink(p):
                with contextlib.suppress(FileNotFoundError):
                    os.remove(p)
                    n += 1
    return n


# --- outputs versus inputs -------------------------------------------------------------

def _real(path) -> str:
    return os.path.realpath(os.path.abspath(os.fspath(path)))


def _is_dataset(folder: str) -> bool:
    return os.path.isfile(os.path.join(folder, "manifest.jsonl")) or \
        os.path.isfile(os.path.join(folder, "dataset.json"))


def _same(a: str, b: str) -> bool:
    if _real(a) == _real(b):
        return True
    try:
        return os.path.samefile(a, b)   # hard links
    except OSError:
        return False


def _inside(path: str, folder: str) -> bool:
    path, folder = _real(path), _real(folder)
    try:
        return os.path.commonpath([path, folder]) == folder
    except ValueError:
        return False


def check_outputs(outputs, inputs=(), replaces_folder: bool = False) -> None:
    """Refuse outputs that would destroy an input (raises :class:`OutputError`).

    The one rule every command applies to every output (file or folder) and every input
    (data folders, ``--init`` / ``--model`` weights, scene, prediction and image files),
    links followed:

    * an output that resolves to an input is refused;
    * an output that lies in a part of an input dataset folder that the dataset owns
      (its manifest, card, images/, exr/, scenes/) is refused;
    * an output folder that holds an input is refused: a command writes its folder's
      files by name (``train``'s ``best.safetensors``, ``evaluate``'s reports, a
      dataset's images), so an input kept there could be replaced (``train --out RUN
      --init RUN/best.safetensors`` would lose the init model).

    ``replaces_folder`` is accepted for older callers; the third rule now holds for every
    output.
    """
    del replaces_folder
    inputs = [os.fspath(i) for i in inputs if i is not None]
    for out in outputs:
        if out is None:
            continue
        out = os.fspath(out)
        for inp in inputs:
            if _same(out, inp):
                raise OutputError(f"output {out} is also an input ({inp}); refusing to overwrite it")
            if os.path.isdir(inp) and _is_dataset(inp) and _inside(out, inp):
                rel = os.path.relpath(_real(out), _real(inp))
                if rel.split(os.sep)[0] in DATASET_OWNED:
                    raise OutputError(f"output {out} is part of the input dataset {inp}; "
                                      "choose a path outside it")
            if _inside(inp, out):
                raise OutputError(f"output folder {out} holds the input {inp}, which the command could "
                                  "overwrite; choose another output or move the input out of it")


def check_file_target(path: str | os.PathLike) -> None:
    """Refuse a file output that is an existing folder (before any work is done)."""
    path = os.fspath(path)
    if os.path.isdir(path):
        raise OutputError(f"output {path} is a folder; give a file name")
    parent = os.path.dirname(os.path.abspath(path))
    probe = parent
    while not os.path.exists(probe):
        probe = os.path.dirname(probe)
    if not os.path.isdir(probe):
        raise OutputError(f"cannot write {path}: {probe} is not a folder")


def check_folder_target(path: str | os.PathLike) -> None:
    """Refuse a folder output that is an existing file."""
    path = os.fspath(path)
    if os.path.lexists(path) and not os.path.isdir(path):
        raise OutputError(f"output {path} exists and is not a folder")
    check_file_target(os.path.join(path, "x"))


def _makedirs(folder: str) -> list[str]:
    """Create ``folder`` and missing parents; returns the folders created (deepest last)."""
    made = []
    folder = os.path.abspath(folder)
    while folder and not os.path.exists(folder):
        made.append(folder)
        folder = os.path.dirname(folder)
    for d in reversed(made):
        with contextlib.suppress(FileExistsError):
            os.mkdir(d)
    return list(reversed(made))


def _remove_empty(folders: list[str]) -> None:
    for d in reversed(folders):
        with contextlib.suppress(OSError):
            os.rmdir(d)


def _rename_error(exc: OSError, tmp: str, path: str) -> OutputError:
    return OutputError(f"cannot write {path}: {exc.strerror or exc}")


# --- writing ---------------------------------------------------------------------------

def atomic_write(path: str | os.PathLike, writer, inputs=()) -> None:
    """Write ``path`` atomically: ``writer(tmp_path)`` writes a temporary file beside it,
    which then replaces ``path``. Refuses (:class:`OutputError`) an output that is one of
    ``inputs`` or a folder; on any failure the temporary file is removed and ``path``
    (and the folders) are as before."""
    path = os.fspath(path)
    check_outputs([path], inputs)
    check_file_target(path)
    made = _makedirs(os.path.dirname(os.path.abspath(path)))
    tmp = temp_path(path)
    try:
        writer(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        _discard(tmp)
        _remove_empty(made)
        if exc.filename in (tmp, path) or getattr(exc, "filename2", None) in (tmp, path):
            raise _rename_error(exc, tmp, path) from None
        raise
    except BaseException:
        _discard(tmp)
        _remove_empty(made)
        raise


def atomic_folder(path: str | os.PathLike, writer) -> None:
    """Write the folder ``path`` atomically: ``writer(tmp_dir)`` fills a temporary folder
    beside it, which then takes the place of ``path`` (an older folder there is swapped
    out, then deleted). On any failure the temporary folder is removed and ``path`` is
    as before. The caller checks first that ``path`` may be replaced."""
    path = os.path.abspath(os.fspath(path))
    parent = os.path.dirname(path)
    made = _makedirs(parent)
    tmp = temp_path(path)
    os.mkdir(tmp)
    try:
        writer(tmp)
        if os.path.lexists(path):
            old = temp_path(path)
            os.replace(path, old)
            os.replace(tmp, path)
            _discard(old)
        else:
            os.replace(tmp, path)
    except BaseException:
        _discard(tmp)
        _remove_empty(made)
        raise


def _discard(tmp: str) -> None:
    with contextlib.suppress(OSError):
        if os.path.isdir(tmp) and not os.path.islink(tmp):
            shutil.rmtree(tmp)
        else:
            os.remove(tmp)


def write_text(path, text: str, inputs=()) -> None:
    """Atomically write ``text`` (UTF-8) to ``path``."""
    def w(tmp):
        with open(tmp, "w", encoding="utf-8", newline="") as f:
            f.write(text)
    atomic_write(path, w, inputs)


def write_bytes(path, data: bytes, inputs=()) -> None:
    """Atomically write ``data`` to ``path``."""
    def w(tmp):
        with open(tmp, "wb") as f:
            f.write(data)
    atomic_write(path, w, inputs)


def write_json(path, data, inputs=(), **kw) -> None:
    """Atomically write ``data`` as JSON (indent 1 unless given)."""
    import json
    kw.setdefault("indent", 1)
    write_text(path, json.dumps(data, **kw), inputs)


class Transaction:
    """Several files written all or nothing.

    ``stage(path, writer)`` writes each file to a temporary name; leaving the ``with``
    block normally renames them all over their targets (older files are kept aside and
    put back should a rename fail), an exception removes the temporaries and any folder
    the transaction created, so the targets are exactly as before::

        with Transaction(inputs=[data_dir]) as t:
            t.makedirs(out_dir)
            t.stage(os.path.join(out_dir, "a.json"), lambda tmp: ...)
    """

    def __init__(self, inputs=()):
        self.inputs = list(inputs)
        self.staged: list[tuple[str, str]] = []
        self.made: list[str] = []

    def check(self, *paths) -> None:
        """Refuse outputs before any work (inputs, folders)."""
        check_outputs(paths, self.inputs)
        for p in paths:
            check_file_target(p)

    def makedirs(self, folder) -> None:
        self.made += _makedirs(os.fspath(folder))

    def stage(self, path, writer) -> None:
        path = os.fspath(path)
        self.check(path)
        self.makedirs(os.path.dirname(os.path.abspath(path)))
        tmp = temp_path(path)
        self.staged.append((tmp, path))
        try:
            writer(tmp)
        except OSError as exc:
            if exc.filename == tmp:
                raise _rename_error(exc, tmp, path) from None
            raise

    def stage_text(self, path, text: str) -> None:
        def w(tmp):
            with open(tmp, "w", encoding="utf-8", newline="") as f:
                f.write(text)
        self.stage(path, w)

    def commit(self) -> None:
        done: list[tuple[str | None, str]] = []   # (backup or None, target)
        try:
            for tmp, path in self.staged:
                backup = None
                if os.path.lexists(path):
                    backup = temp_path(path)
                    os.replace(path, backup)
                done.append((backup, path))
                os.replace(tmp, path)
        except BaseException:
            for backup, path in reversed(done):
                with contextlib.suppress(OSError):
                    if backup:
                        os.replace(backup, path)
                    else:
                        os.remove(path)
            self.rollback()
            raise
        for backup, _ in done:
            if backup:
                _discard(backup)
        self.staged = []

    def rollback(self) -> None:
        for tmp, _ in self.staged:
            _discard(tmp)
        self.staged = []
        _remove_empty(self.made)
        self.made = []

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.commit()
        else:
            self.rollback()
        return False


# --- one writer per folder ---------------------------------------------------------------

class FolderLock:
    """An exclusive OS lock (``flock``) on ``FOLDER/.relight.lock``, held while a job
    writes the folder and released when the process ends, however it ends.

    Raises :class:`OutputError` when another process holds it."""

    @classmethod
    def take(cls, folder: str | os.PathLike, what: str = "folder") -> tuple["FolderLock", bool]:
        """Make ``folder`` if needed and lock it; returns ``(lock, existed)``. Refuses
        (:class:`OutputError`) a path that is not a folder; a folder made here is removed
        again when the lock cannot be taken."""
        folder = os.fspath(folder)
        if os.path.lexists(folder) and not os.path.isdir(folder):
            raise OutputError(f"{folder} exists and is not a folder")
        existed = os.path.isdir(folder)
        os.makedirs(folder, exist_ok=True)
        try:
            return cls(folder, what).acquire(), existed
        except BaseException:
            if not existed:
                shutil.rmtree(folder, ignore_errors=True)
            raise

    def __init__(self, folder: str | os.PathLike, what: str = "folder"):
        self.folder = os.fspath(folder)
        self.what = what
        self.fd: int | None = None

    def acquire(self) -> "FolderLock":
        import fcntl
        path = os.path.join(self.folder, LOCK_NAME)
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                os.close(fd)
                raise
            try:
                holder = os.pread(fd, 32, 0).decode(errors="replace").strip()
            except OSError:
                holder = ""
            os.close(fd)
            who = f" (pid {holder})" if holder.isdigit() else ""
            raise OutputError(f"{self.folder}: another relight process{who} is writing this {self.what}; "
                              "wait for it to finish or use another --out") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        self.fd = fd
        return self

    def release(self) -> None:
        if self.fd is not None:
            os.close(self.fd)   # closing the descriptor drops the flock
            self.fd = None

    def __enter__(self):
        return self.acquire()

    def __exit__(self, *exc):
        self.release()
        return False


# --- quiet libraries ---------------------------------------------------------------------

@contextlib.contextmanager
def quiet_library_output():
    """Silence stdout and stderr (file descriptors 1 and 2 and the Python streams) for the
    duration of the block: C++ libraries such as OpenEXR print warnings there directly.
    Python exceptions are unaffected."""
    saved = []
    try:
        sys.stdout.flush()
        sys.stderr.flush()
        devnull = os.open(os.devnull, os.O_WRONLY)
    except (OSError, ValueError):
        yield
        return
    streams = sys.stdout, sys.stderr
    try:
        for fd in (1, 2):
            try:
                saved.append((fd, os.dup(fd)))
                os.dup2(devnull, fd)
            except OSError:
                pass
        sys.stdout = sys.stderr = io.StringIO()   # bindings may print through Python too
        yield
    finally:
        sys.stdout, sys.stderr = streams
        try:   # C and C++ streams buffer: flush them while they still go nowhere
            import ctypes
            ctypes.CDLL(None).fflush(None)
        except (OSError, AttributeError):
            pass
        for fd, copy in saved:
            os.dup2(copy, fd)
            os.close(copy)
        os.close(devnull)

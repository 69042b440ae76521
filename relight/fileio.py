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

A write the file system refuses (full disk, quota, read-only: :func:`disk_error`) or any
OS error on an output is one :class:`OutputError` naming the output as the user gave it
(:func:`name_outputs`, :func:`describe_output`), never the temporary file.
"""
from __future__ import annotations

__all__ = [
    "TEMP_MARK", "LOCK_NAME", "DATASET_OWNED", "temp_path", "is_temp_name", "remove_temps", "check_outputs",
    "check_file_target", "check_folder_target", "atomic_write", "atomic_folder", "write_text", "write_bytes",
    "write_json", "Transaction", "FolderLock", "quiet_library_output",
    "name_outputs", "describe_output", "human_size", "disk_error", "write_error", "append_line",
]

import contextlib
import errno
import io
import os
import re
import secrets
import shutil
import sys
from relight.errors import DiskFullError, OutputError, RelightError

TEMP_MARK = ".relight-tmp-"
LOCK_NAME = ".relight.lock"
# Files and folders a relight dataset owns (nothing else may write them).
DATASET_OWNED = ("manifest.jsonl", "dataset.json", "images", "exr", "scenes", "masks", LOCK_NAME)
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
      (its manifest, card, images/, exr/, scenes/, masks/) is refused;
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
    done = []
    try:
        for d in reversed(made):
            with contextlib.suppress(FileExistsError):
                os.mkdir(d)
                done.append(d)
    except BaseException:
        _remove_empty(done)   # a folder could not be made (full disk...): none is left
        raise
    return list(reversed(made))


def _remove_empty(folders: list[str]) -> None:
    for d in reversed(folders):
        with contextlib.suppress(OSError):
            os.rmdir(d)


# --- naming an output, and the file system refusing bytes -------------------------------

_OUTPUT_OPTIONS: dict[str, tuple[str, str]] = {}   # real path -> (option, path as given)
_OUTPUT_ENV = "RELIGHT_OUTPUT_OPTIONS"


def name_outputs(options: dict) -> None:
    """Record which command-line option gave each output path (``{"--out": path}``, or a
    list of paths for a repeatable option), so
    that an error while writing one names the option the user typed, never an internal
    temporary (the command line calls this once with its parsed arguments)."""
    import json
    _OUTPUT_OPTIONS.clear()
    for option, given in options.items():
        for one in (given if isinstance(given, (list, tuple)) else [given]):   # a repeatable option: each
            if isinstance(one, (str, os.PathLike)) and os.fspath(one):
                _OUTPUT_OPTIONS[_real(one)] = (option, os.fspath(one))
    os.environ[_OUTPUT_ENV] = json.dumps(_OUTPUT_OPTIONS)   # worker processes name them alike


def _output_options() -> dict[str, tuple[str, str]]:
    if not _OUTPUT_OPTIONS and os.environ.get(_OUTPUT_ENV):
        import json
        try:
            _OUTPUT_OPTIONS.update({k: tuple(v) for k, v in json.loads(os.environ[_OUTPUT_ENV]).items()})
        except (ValueError, TypeError, AttributeError):
            pass
    return _OUTPUT_OPTIONS


def describe_output(path) -> str:
    """``path`` as the user knows it: ``--out DIR (images/000003.png)`` when it is (in) the
    output an option named, else the path itself. A temporary name means its target."""
    path = os.fspath(path)
    folder, name = os.path.split(path)
    m = _TEMP_RE.search(name)
    if m and m.group(1) is not None and name.startswith("."):
        name = name[1:m.start()] + name[m.end():]   # .NAME.relight-tmp-PID-TOKEN.EXT -> NAME.EXT
        path = os.path.join(folder, name)
    parts = []   # temporary folders (atomic_folder) along the way name their targets too
    for piece in _real(path).split(os.sep):
        m = _TEMP_RE.search(piece)
        if m and m.group(1) is not None and piece.startswith("."):
            piece = piece[1:m.start()] + piece[m.end():]
        parts.append(piece)
    real = os.sep.join(parts) or os.sep
    best = None
    for out_real, (option, given) in _output_options().items():
        if real == out_real or _inside(real, out_real):
            if best is None or len(out_real) > len(best[0]):
                best = (out_real, option, given)
    if best is None:
        return path
    out_real, option, given = best
    return f"{option} {given}" + ("" if real == out_real else f" ({os.path.relpath(real, out_real)})")


DISK_ERRNOS = {errno.ENOSPC: "no space left on the device", errno.EDQUOT: "disk quota exceeded",
               errno.EROFS: "read-only file system", errno.EFBIG: "file too large for the file system"}
# What libraries that drop the errno say instead (safetensors, OpenEXR, numpy).
_DISK_WORDS = (("no space left", errno.ENOSPC), ("storagefull", errno.ENOSPC),
               ("disk quota", errno.EDQUOT), ("quotaexceeded", errno.EDQUOT),
               ("read-only file system", errno.EROFS), ("readonlyfilesystem", errno.EROFS))
FULL_MARGIN = 1 << 20   # a write failing with less free than this is taken as a full disk


def _free_space(path: str) -> tuple[int | None, bool]:
    """(bytes free to this user, read-only) of the file system holding ``path`` (or its
    nearest existing parent); (None, False) when unknown."""
    probe = os.path.abspath(path)
    while probe and not os.path.exists(probe):
        parent = os.path.dirname(probe)
        if parent == probe:
            break
        probe = parent
    try:
        st = os.statvfs(probe)
    except OSError:
        return None, False
    return st.f_bavail * st.f_frsize, bool(st.f_flag & os.ST_RDONLY)


def human_size(n: float) -> str:
    """Bytes for a person: ``512 B``, ``28.0 KB``, ``1.2 MB``."""
    for unit in ("B", "KB", "MB", "GB", "TB"):
        if n < 1024 or unit == "TB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n} B"


def _disk_errno(exc: BaseException, path: str) -> int | None:
    """The errno when ``exc`` means the file system refused the bytes (full, over quota,
    read-only), looking through chained exceptions and the words of libraries that drop
    the errno; a library that says only that writing failed (torch) is believed when
    the file system is in fact full or read-only."""
    seen, e = set(), exc
    while e is not None and id(e) not in seen:
        seen.add(id(e))
        if isinstance(e, OSError) and e.errno in DISK_ERRNOS:
            return e.errno
        text = str(e).lower().replace(" ", "") if not isinstance(e, OSError) or e.errno is None else ""
        for words, code in _DISK_WORDS:
            if words.replace(" ", "") in text:
                return code
        e = e.__cause__ or e.__context__
    # I/O errors of the writing libraries (torch, OpenEXR, Pillow, safetensors), not
    # programming errors (ValueError, TypeError...), which stay bugs whatever the disk
    if isinstance(exc, OSError) and exc.errno is not None:
        return None   # the OS said what it was (no permission, no such file...)
    if isinstance(exc, (OSError, RuntimeError)) or "Safetensor" in type(exc).__name__:
        free, read_only = _free_space(path)
        if read_only:
            return errno.EROFS
        if free is not None and free < FULL_MARGIN:
            return errno.ENOSPC
    return None


def disk_error(exc: BaseException, path, size: int | None = None, partial: int | None = None
               ) -> DiskFullError | None:
    """The one-line :class:`~relight.errors.DiskFullError` (an :class:`OutputError`) for a write of ``path`` that the file system
    refused (``ENOSPC``, ``EDQUOT``, ``EROFS``, ``EFBIG``), naming the output and the
    free space: ``size``, the bytes the file needs, where known, else ``partial``, the
    bytes it had reached when the disk filled (it needs more); None otherwise."""
    path = os.fspath(path)
    code = _disk_errno(exc, path)
    if code is None:
        return None
    what = DISK_ERRNOS[code]
    if code in (errno.ENOSPC, errno.EDQUOT):
        free, _ = _free_space(path)
        need = (f"; it needs {human_size(size)}" if size else
                f"; it needs more than the {human_size(partial)} written" if partial else "")
        room = f" ({human_size(free)} free{need})" if free is not None else ""
        hint = "; free some space (or choose another --out) and re-run the same command"
    else:
        room, hint = "", "; choose another --out"
    return DiskFullError(f"cannot write {describe_output(path)}: {what}{room}{hint}")


def write_error(exc: BaseException, path, tmp: str | None = None, size: int | None = None,
                partial: int | None = None) -> OutputError | None:
    """The one-line error for a failed write of ``path`` (through ``tmp``): the file
    system refused the bytes (:func:`disk_error`), or an OS error on the file itself
    (no permission, ...), named as the user knows it; None for anything else (a bug)."""
    full = disk_error(exc, path, size, partial)
    if full is not None:
        return full
    if isinstance(exc, OSError):
        names = {os.fspath(n) for n in (exc.filename, getattr(exc, "filename2", None)) if n is not None}
        ours = {os.fspath(path)} | ({tmp} if tmp else set())
        # the file, its temporary (or a file in a temporary folder), or a folder on its way
        if names & ours or any((tmp and _inside(n, tmp)) or _inside(path, n) for n in names):
            return OutputError(f"cannot write {describe_output(path)}: {exc.strerror or exc}")
    return None


# --- writing ---------------------------------------------------------------------------

def _size(path: str) -> int | None:
    try:
        if os.path.isdir(path):
            return sum(os.path.getsize(os.path.join(d, f)) for d, _, fs in os.walk(path) for f in fs)
        return os.path.getsize(path)
    except OSError:
        return None


@contextlib.contextmanager
def _writing(path: str, tmp: str | None = None, made=(), size: int | None = None):
    """Around a write of ``path`` (through ``tmp``): on any failure the temporary and the
    folders made for it are removed, and a refusal of the file system (full disk, quota,
    read-only) or an OS error on the file becomes one :class:`OutputError` naming the
    output as the user gave it (:func:`write_error`); anything else is raised as is."""
    try:
        yield
    except BaseException as exc:
        err = None
        if not isinstance(exc, (RelightError, KeyboardInterrupt, SystemExit, GeneratorExit)):
            # classified before the temporary is removed: the disk is still full now
            err = write_error(exc, path, tmp, size, None if size or not tmp else _size(tmp))
        if tmp:
            _discard(tmp)
        _remove_empty(list(made))
        if err is not None:
            raise err from None
        raise


def atomic_write(path: str | os.PathLike, writer, inputs=(), size: int | None = None) -> None:
    """Write ``path`` atomically: ``writer(tmp_path)`` writes a temporary file beside it,
    which then replaces ``path``. Refuses (:class:`OutputError`) an output that is one of
    ``inputs`` or a folder; on any failure the temporary file is removed and ``path``
    (and the folders) are as before. A full disk, a quota or a read-only file system is
    one :class:`OutputError` naming the output and the free space (``size``: the bytes
    the file needs, where the caller knows them)."""
    path = os.fspath(path)
    check_outputs([path], inputs)
    check_file_target(path)
    with _writing(path, size=size):
        made = _makedirs(os.path.dirname(os.path.abspath(path)))
    tmp = temp_path(path)
    with _writing(path, tmp, made, size):
        writer(tmp)
        os.replace(tmp, path)


def atomic_folder(path: str | os.PathLike, writer) -> None:
    """Write the folder ``path`` atomically: ``writer(tmp_dir)`` fills a temporary folder
    beside it, which then takes the place of ``path`` (an older folder there is swapped
    out, then deleted). On any failure the temporary folder is removed and ``path`` is
    as before (a full disk: one :class:`OutputError`, as :func:`atomic_write`). The
    caller checks first that ``path`` may be replaced."""
    path = os.path.abspath(os.fspath(path))
    parent = os.path.dirname(path)
    with _writing(path):
        made = _makedirs(parent)
    tmp = temp_path(path)
    with _writing(path, tmp, made):
        os.mkdir(tmp)
        writer(tmp)
        if os.path.lexists(path):
            old = temp_path(path)
            os.replace(path, old)
            os.replace(tmp, path)
            _discard(old)
        else:
            os.replace(tmp, path)


def append_line(f, line: bytes, path) -> None:
    """Append one whole ``line`` to the open binary file ``f`` (a manifest) and sync it.
    On failure (a full disk...) the file is cut back to its length before, so no record
    is ever half-written, and the error is one :class:`OutputError` (as :func:`atomic_write`)."""
    start = f.tell()
    with _writing(os.fspath(path), size=len(line)):
        try:
            f.write(line)
            f.flush()
            os.fsync(f.fileno())
        except BaseException:
            with contextlib.suppress(OSError, ValueError):
                f.seek(start)
                f.truncate(start)
                f.flush()
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
    atomic_write(path, w, inputs, size=len(text.encode("utf-8", "surrogatepass")))


def write_bytes(path, data: bytes, inputs=()) -> None:
    """Atomically write ``data`` to ``path``."""
    def w(tmp):
        with open(tmp, "wb") as f:
            f.write(data)
    atomic_write(path, w, inputs, size=len(data))


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
        with _writing(path):
            self.makedirs(os.path.dirname(os.path.abspath(path)))
        tmp = temp_path(path)
        self.staged.append((tmp, path))
        with _writing(path, tmp):   # the rollback removes the rest
            writer(tmp)

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
        except BaseException as exc:
            err = None if isinstance(exc, RelightError) else write_error(exc, path, tmp)
            for backup, path in reversed(done):
                with contextlib.suppress(OSError):
                    if backup:
                        os.replace(backup, path)
                    else:
                        os.remove(path)
            self.rollback()
            if err is not None:
                raise err from None
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
        with _writing(folder):
            made = _makedirs(folder)
        lock = cls(folder, what)
        lock.made = made
        try:
            with _writing(os.path.join(folder, LOCK_NAME)):
                return lock.acquire(), existed
        except BaseException:
            lock.remove_made()
            raise

    def remove_made(self) -> None:
        """Remove the folder (with its contents) and the empty parents :meth:`take` made
        (nothing when the folder existed before)."""
        if self.made:
            shutil.rmtree(self.made[-1], ignore_errors=True)
            _remove_empty(self.made[:-1])

    def __init__(self, folder: str | os.PathLike, what: str = "folder"):
        self.folder = os.fspath(folder)
        self.what = what
        self.made: list[str] = []   # folders take() created, outermost first
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

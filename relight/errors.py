"""The error family of relight: every failure a user can cause and fix.

Each class derives from :class:`RelightError`; the command line prints such an error
as one line on stderr and exits 2, and the library leaves every file as it was when
it raises one. A bug is anything else (a traceback). The family follows the pipeline
(generate -> scene file -> render -> train/predict -> compare/invert), one class per
kind of input, so a caller can catch exactly what it can handle::

    >>> from relight.errors import RelightError, SceneFileError
    >>> issubclass(SceneFileError, RelightError), issubclass(SceneFileError, ValueError)
    (True, True)
"""
from __future__ import annotations

__all__ = [
    "RelightError", "ConfigError", "SceneFileError", "DatasetError", "ImageError", "OutputError",
    "PredictionsError", "ModelFileError", "TrainingError", "ProbeError", "InverseError", "BackendError",
    "EngineError", "BlenderError",
    "DiskFullError", "brief", "user_errors",
]


class RelightError(Exception):
    """Base of every user-fixable error (one-line message)."""


# -- bad values or files (also ValueError, what Python code expects of bad input) -------
class ConfigError(RelightError, ValueError):
    """A generator setting or an option value is out of range or unknown."""


class SceneFileError(RelightError, ValueError):
    """A scene file is unreadable, of an unknown version or inconsistent."""


class DatasetError(RelightError, ValueError):
    """A dataset folder is missing, inconsistent or was made with other settings."""


class ImageError(RelightError, ValueError):
    """An image file cannot be read or written."""


class OutputError(RelightError, ValueError):
    """An output cannot be written: it is one of the inputs, a folder where a file is
    expected, or a folder another relight process is writing."""


class DiskFullError(OutputError):
    """The file system refused an output's bytes: full, over quota or read-only."""


class PredictionsError(RelightError, ValueError):
    """A predictions file or entry is malformed (the message names the entry)."""


class ModelFileError(RelightError, ValueError):
    """A model file is missing, unreadable or not a relight model."""


class TrainingError(RelightError, ValueError):
    """A training setting is out of range, or a run folder belongs to another run."""


class ProbeError(RelightError, ValueError):
    """A probe image, circle or mask cannot be used."""


class InverseError(RelightError, ValueError):
    """Inverse rendering cannot run on these inputs."""


# -- the machine or a service cannot do it ------------------------------------------------
class BackendError(RelightError, RuntimeError):
    """The rendering backend cannot be used on this machine."""


class EngineError(RelightError, RuntimeError):
    """The distributed engine cannot start or lost its scheduler."""


class BlenderError(RelightError, RuntimeError):
    """bpy is missing or a scene cannot be expressed in Cycles."""


# -- one line from a library's message ------------------------------------------------------
import re as _re

_ESCAPES = _re.compile(r"\x1b\[[0-?]*[ -/]*[@-~]|\x1b[@-_]")   # terminal colour / cursor codes


def brief(exc: BaseException | str, limit: int = 120) -> str:
    """A library's error message as a short clause for a one-line error: its first line
    without terminal escape codes or control characters, its first sentence, and cut at a word (never mid-word, marked ``...``) when still over ``limit``.

    >>> brief(RuntimeError("Weights only load failed. In PyTorch 2.6, we changed ..."))
    'Weights only load failed'
    >>> brief("\\x1b[1mbad\\x1b[0m header\\nsecond line")
    'bad header'
    >>> brief("one two three four", limit=12)
    'one two...'
    """
    text = str(exc) if not isinstance(exc, str) else exc
    if not text.strip():
        return type(exc).__name__ if not isinstance(exc, str) else ""
    text = _ESCAPES.sub("", text)
    line = next((ln for ln in text.splitlines() if ln.strip()), "")
    line = " ".join("".join(ch if ch.isprintable() else " " for ch in line).split())
    if ". " in line:   # the first sentence says what happened; the rest is advice for other readers
        line = line.split(". ", 1)[0]
    line = line.rstrip(". ")
    if len(line) > limit:
        cut = line[:limit + 1].rsplit(" ", 1)[0] if " " in line[:limit + 1] else line[:limit]
        line = cut.rstrip(" ,;:(") + "..."
    return line


def user_errors() -> tuple[type, ...]:
    """Exception types that mean 'bad input' (one line, exit 2) rather than a bug: the
    :class:`RelightError` family and the OS's file errors."""
    return (RelightError, FileNotFoundError, PermissionError, IsADirectoryError, NotADirectoryError)

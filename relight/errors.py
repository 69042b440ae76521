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

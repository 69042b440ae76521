"""relight: light direction and colour from one image (Sial et al.), verified with Mitsuba 3.

Start with ``relight --help``; the conventions live in :mod:`relight.frames`.

The library's public face, in pipeline order (each name is loaded on first use, so
``import relight`` stays cheap and imports neither Mitsuba nor PyTorch):

* make a dataset: :func:`generate` with a :class:`GeneratorConfig`; read one back:
  :func:`read_manifest`;
* scene files: :func:`load_scene`, and :func:`render_spec` for the image of one;
* the network: :func:`load_model`, then :func:`predict_arrays` (linear images) or
  :func:`predict_files` (image files);
* verify estimates: :func:`compare_predictions` (re-render each scene under its predicted
  light) and :func:`invert` (inverse rendering with the scene known);
* predictions files: :func:`read_predictions`, :func:`write_predictions`;
* the conventions: :mod:`relight.frames` (angles and frames), :mod:`relight.metrics`
  (errors and the paper's tables), :mod:`relight.colour` (light colour, sRGB);
  :class:`RelightError` is the base of every error a user can fix.

>>> import relight
>>> (relight.frames.direction(90.0, 0.0).round(12) + 0.0).tolist()   # pan 90: the camera's right
[0.0, 1.0, 0.0]
>>> relight.generate.__module__
'relight.generator.run'
"""
from __future__ import annotations

import importlib

__version__ = "0.1.0"

# public name -> the module that defines it (modules themselves map to None)
_API = {
    "generate": "relight.generator.run",
    "GeneratorConfig": "relight.generator.sampling",
    "read_manifest": "relight.dataset.format",
    "load_scene": "relight.scene.spec",
    "render_spec": "relight.scene.build",
    "load_model": "relight.net.predict",
    "predict_arrays": "relight.net.predict",
    "predict_files": "relight.net.predict",
    "compare_predictions": "relight.verify.compare",
    "invert": "relight.inverse.optimize",
    "read_predictions": "relight.predictions",
    "write_predictions": "relight.predictions",
    "RelightError": "relight.errors",
    "frames": None,
    "metrics": None,
    "colour": None,
}

__all__ = list(_API) + ["__version__"]


def __getattr__(name: str):
    """Load a public name on first use (PEP 562)."""
    if name not in _API:
        raise AttributeError(f"module 'relight' has no attribute {name!r}")
    module = _API[name]
    value = importlib.import_module(f"relight.{name}") if module is None \
        else getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))

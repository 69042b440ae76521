"""The ``relight`` subcommands, one module per group, on top of the library: each
parses its arguments, checks its outputs against its inputs, and calls one library
function (:mod:`relight.cli` dispatches to them).

* :mod:`~relight.commands.data`: ``generate``, ``render``
* :mod:`~relight.commands.net`: ``train``, ``evaluate``, ``predict``
* :mod:`~relight.commands.verify`: ``compare``, ``figure spheres|pole``
* :mod:`~relight.commands.inverse`: ``invert``, ``baseline``
* :mod:`~relight.commands.probe`: ``probe``
* :mod:`~relight.commands.blender`: ``export-blender``
* :mod:`~relight.commands.demo`: ``demo``
* :mod:`~relight.commands.argtypes`: the shared argument types (bounded numbers, ...)
"""

__all__ = [
    "argtypes", "blender", "data", "demo", "inverse", "net", "probe", "verify",
]

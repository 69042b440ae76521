"""Baselines that know more or less than the network.

* :mod:`relight.inverse.optimize`: inverse rendering. The scene geometry is known;
  the light direction and colour are fitted by rendering it with Mitsuba 3
  (finite-difference Levenberg-Marquardt on pan/tilt, closed-form colour).
* :mod:`relight.inverse.colour_baselines`: classical colour constancy (Gray World,
  White Patch, Shades of Gray, Gray Edge) from the pixels alone, colour only.
* :mod:`relight.inverse.ad`: automatic-differentiation Jacobians with shadow-edge terms.
* :mod:`relight.inverse.jobs`: batches of images to invert (dataset split or one
  scene), their starting directions, and the trace file.
"""

__all__ = [
    "ad", "colour_baselines", "jobs", "objective", "optimize",
]

"""The MID-like experiment (the paper's Experiment 2 on synthetic rooms whose light is known).

* :mod:`relight.experiments.mid.scene`: the rooms, the flash, the two probe spheres,
  rendering and the *physical* ground truth;
* :mod:`relight.experiments.mid.dataset`: the dataset (``relight generate --preset mid``),
  the sphere procedure's ground truth with the reference-image correction, and the
  paper's Tables 4-5.
"""
__all__ = ["dataset", "scene"]

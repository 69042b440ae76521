"""Experiments built on the pipeline: each a dataset preset, its scenes and its tables.

* :mod:`relight.experiments.mid`: the paper's Experiment 2 on MID-like synthetic rooms
  (``relight generate --preset mid``; Tables 4-5).
"""
__all__ = ["mid"]

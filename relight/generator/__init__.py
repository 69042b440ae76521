"""The generator: random scene files rendered into a dataset (stage 1 of the pipeline).

* :mod:`relight.generator.sampling`: :class:`~relight.generator.sampling.GeneratorConfig`
  and :func:`~relight.generator.sampling.sample_scene`, image ``i`` of a dataset as a
  scene file drawn from the priors;
* :mod:`relight.generator.run`: :func:`~relight.generator.run.generate`, which renders
  them into a dataset folder (resumable, crash-safe, on one process or a Dask cluster).

The format of what it writes (manifest, card, splits, readers) is :mod:`relight.dataset`;
the stages read datasets through that and never import the generator.
"""
__all__ = ["run", "sampling"]

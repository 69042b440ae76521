"""Light from probe spheres in a photograph (the paper's Experiment 2 ground truth):
a chrome sphere's highlight gives the direction, a gray sphere's shading the colour.

* :mod:`relight.probe.ortho`: the paper's procedure for a near-orthographic view and a
  given mask (circle fit, highlight direction, diffuse shading and colour).
* :mod:`relight.probe.geometry`: the same for real cameras: the sphere's 3-D centre
  from its outline, each pixel's own view ray reflected about the sphere normal,
  highlight localisation.
* :mod:`relight.probe.footprint`: a clipped light's position from which pixels it
  clipped (an 8-bit render's box or Blackman-Harris filter, nothing of it beside them).
* :mod:`relight.probe.detect`: finding the spheres (circle detection, outline
  refinement, chrome or diffuse).
* :mod:`relight.probe.locator`: a small learned network, trained on generated probe
  scenes, that says where a chrome sphere's centre likely is: a proposal and a prior on
  the detector's choice.
* :mod:`relight.probe.outline_check`: a second small network that, shown one candidate
  circle, says where the chrome sphere's circle lies relative to it: a second start for
  the detector's edge fit (a sphere's contact shadow draws a larger circle beside it).
* :mod:`relight.probe.run`: ``relight probe`` as one library call, with the QA overlay.
* :mod:`relight.probe.batch`: a folder of photographs with each image's circles from a CSV.

The study of the procedure on harder images (small spheres, clutter, two renderers, real
photographs) is docs/probe.md.
"""

__all__ = [
    "detect", "footprint", "geometry", "locator", "ortho", "outline_check", "run",
]

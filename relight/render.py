"""The one render path: every image relight renders with Mitsuba goes through here.

* :func:`sensor`: the camera, film and sampler of a scene dictionary (one definition
  for generated scenes, probe scenes and verification figures);
* :func:`render_scene`: the one ``mi.render`` call (exact sample count for the
  sampler, a given seed, ``(H, W, C)`` float32 linear RGB out);
* above it, :mod:`relight.scene.build`: :class:`~relight.scene.build.SceneTemplate`
  (a loaded scene; ``render`` and ``render_under`` another point light, for compare
  and inverse rendering) and :func:`~relight.scene.build.render_spec` (a scene file's
  image, with a process-wide builder that reuses loaded scenes).

The inverse renderer's automatic-differentiation paths (:mod:`relight.inverse`) call
``mi.render`` with gradient seeds themselves; everything else renders here.
"""
from __future__ import annotations

__all__ = [
    "sensor", "render_scene", "exact_spp",
]

import numpy as np

from relight import backend
from relight.timing import NO_TIMER


def sensor(res: int, fov_deg: float, sampler: str = "independent", to_world=None,
           pixel_format: str = "rgb", height: int | None = None, rfilter: str = "box") -> dict:
    """A Mitsuba ``perspective`` sensor dictionary: ``fov_deg`` across the image width,
    an ``hdrfilm`` of ``res`` x ``height`` (default square) pixels with a ``rfilter``
    reconstruction filter (box: each sample counts in its own pixel only), and
    the ``sampler`` plugin (its sample count is set per render by :func:`render_scene`)."""
    d = {"type": "perspective", "fov": float(fov_deg), "fov_axis": "x",
         "film": {"type": "hdrfilm", "width": int(res), "height": int(height or res),
                  "rfilter": {"type": rfilter}, "pixel_format": pixel_format},
         "sampler": {"type": sampler, "sample_count": 1}}
    if to_world is not None:
        d["to_world"] = to_world
    return d


def render_scene(scene, spp: int, seed: int, sampler: str = "independent", integrator=None,
                 sensor: int = 0, timer=NO_TIMER) -> np.ndarray:
    """Render a loaded Mitsuba scene: ``(H, W, C)`` float32, linear. ``spp`` is rounded as
    ``sampler`` needs (:func:`exact_spp`: a product of two close integers for multijitter);
    ``integrator`` (a loaded one) replaces the scene's, ``sensor`` picks one of its sensors.
    ``timer`` (:class:`~relight.timing.StageTimer`) times tracing (``mi.render``
    traces the kernel and queues it), the kernel's run and the readback apart."""
    mi = backend.mitsuba()
    spp = exact_spp(sampler, int(spp))
    with timer.stage("render: tracing + launch"):
        image = mi.render(scene, integrator=integrator, sensor=int(sensor), spp=spp, seed=int(seed))
    with timer.stage("render: kernel", sync=True):
        pass   # with a timer: wait here for the queued kernel (else the readback waits)
    with timer.stage("render: readback"):
        return np.array(image, dtype=np.float32)


def exact_spp(sampler: str, spp: int) -> int:
    """The sample count Mitsuba actually takes for ``spp`` (``multijitter`` rounds up to
    a product of two close integers, e.g. 32 -> 35); passing it avoids Mitsuba's
    rounding warning and changes nothing in the image."""
    if sampler == "multijitter":
        rows = max(1, int(np.sqrt(spp)))
        return rows * ((spp + rows - 1) // rows)
    return int(spp)

"""The objective of inverse rendering, shared by the optimiser
(:mod:`relight.inverse.optimize`) and the automatic-differentiation Jacobian
(:mod:`relight.inverse.ad`): the known scene rendered under a candidate light
(:class:`LightRenderer`), the closed-form colour (:func:`colour_fit`), the
variable-projection residual (:func:`residual`) and its finite-difference Jacobian
in the optimiser's step variables (:func:`moved`: arc degrees along pan and tilt,
relative radius). See :mod:`relight.inverse.optimize` for the method.
"""
from __future__ import annotations

__all__ = [
    "downsample", "colour_fit", "LightRenderer", "moved", "residual", "jacobian", "loss_gradient",
]

import dataclasses
import math

import numpy as np

from relight import frames
from relight.errors import InverseError
from relight.scene.spec import SceneSpec


# --- pure helpers ------------------------------------------------------------------

def downsample(image: np.ndarray, res: int) -> np.ndarray:
    """Box-average a square ``(H, H, 3)`` image to ``(res, res, 3)`` (H a multiple of
    res). With Mitsuba's box pixel filter this is the expected image at ``res``."""
    image = np.asarray(image, dtype=np.float64)
    if image.ndim != 3 or image.shape[2] != 3 or image.shape[0] != image.shape[1]:
        raise InverseError(f"expected a square (H, H, 3) image, got shape {image.shape}")
    h = image.shape[0]
    if h % res:
        raise InverseError(f"image size {h} px is not a multiple of the render size {res} px")
    f = h // res
    return image.reshape(res, f, res, f, 3).mean(axis=(1, 3))


def colour_fit(target: np.ndarray, render: np.ndarray) -> tuple[np.ndarray, float]:
    """Best per-channel scale of ``render`` toward ``target`` (least squares).

    Returns ``(k (3,), loss)`` with ``k_c = <I_c, R_c> / <R_c, R_c>`` and
    ``loss = |I - k R|^2 / |I|^2`` (0 = perfect, 1 = as bad as a black image).
    """
    i = np.asarray(target, dtype=np.float64).reshape(-1, 3)
    r = np.asarray(render, dtype=np.float64).reshape(-1, 3)
    rr = np.einsum("nc,nc->c", r, r)
    ir = np.einsum("nc,nc->c", i, r)
    k = np.where(rr > 0, ir / np.where(rr > 0, rr, 1.0), 0.0)
    k = np.maximum(k, 0.0)
    ii = float(np.sum(i * i))
    loss = float(np.sum((i - k * r) ** 2)) / ii if ii > 0 else float("inf")
    return k, loss


# --- rendering ----------------------------------------------------------------------

class LightRenderer:
    """Renders the known scene under a candidate light at several sizes, counting renders.

    One :class:`SceneTemplate` per resolution, loaded once per image; each render only
    writes the light position and a white intensity ``r^2`` W/sr per channel (so the
    irradiance at the scene centre does not depend on the distance).
    """

    def __init__(self, spec: SceneSpec, builder=None):
        from relight import backend
        backend.init()
        if builder is None:
            from relight.scene.build import SceneBuilder
            builder = SceneBuilder()
        self.spec, self.builder = spec, builder
        self._templates: dict[int, object] = {}
        self.renders = 0
        self._last = None  # (arguments, image) of the last render: the AD Jacobian reuses it

    def template(self, res: int):
        tpl = self._templates.get(res)
        if tpl is None:
            spec = dataclasses.replace(self.spec, render=dataclasses.replace(self.spec.render, res=res))
            tpl = self._templates[res] = self.builder.template_for(spec)
        return tpl

    def image(self, pan_rel_deg: float, tilt_deg: float, r_m: float, res: int, spp: int,
               seed: int) -> np.ndarray:
        """``(res, res, 3)`` float64 linear render under a white light at (r, pan_rel, tilt)."""
        key = (pan_rel_deg, tilt_deg, r_m, res, spp, seed)
        if self._last is not None and self._last[0] == key:
            return self._last[1].copy()
        tpl = self.template(res)
        pan_deg = frames.pan_from_rel(pan_rel_deg, self.spec.camera.pan_deg)
        self.renders += 1
        image = tpl.render_under(frames.spherical_to_cartesian(r_m, pan_deg, tilt_deg), (r_m * r_m,) * 3,
                                 spp, seed).astype(np.float64)
        self._last = (key, image)
        return image.copy()


# --- the objective and its finite-difference derivatives ----------------------------

def moved(pan_deg: float, tilt_deg: float, r_m: float, delta) -> tuple[float, float, float]:
    """Apply an optimiser step ``delta = (du_deg, dv_deg[, dr_rel])``: arc steps along pan
    and tilt (:func:`tangent_move`) and a relative change of the radius."""
    pan, tilt = frames.tangent_move(pan_deg, tilt_deg, float(delta[0]), float(delta[1]))
    r = r_m * (1.0 + float(delta[2])) if len(delta) > 2 else r_m
    return pan, tilt, max(r, 1e-3)


def residual(renderer: LightRenderer, target: np.ndarray, pan_rel_deg: float, tilt_deg: float,
             r_m: float, spp: int, seed: int) -> tuple[np.ndarray, float, np.ndarray]:
    """Variable-projection residual ``(I - k R) / |I|`` (flat), its loss ``|.|^2`` and the
    colour scale ``k`` (3,), rendering at the target's size."""
    render = renderer.image(pan_rel_deg, tilt_deg, r_m, target.shape[0], spp, seed)
    k, loss = colour_fit(target, render)
    norm = math.sqrt(float(np.sum(target * target))) or 1.0
    return ((target - k * render) / norm).ravel(), loss, k


def jacobian(renderer: LightRenderer, target: np.ndarray, pan_rel_deg: float, tilt_deg: float,
             r_m: float, spp: int, seed: int, steps) -> np.ndarray:
    """Central-difference Jacobian ``(n_residuals, len(steps))`` of :func:`residual`
    w.r.t. the step variables of :func:`moved` (per arc degree; per unit relative
    radius), with common random numbers: every render uses ``seed``."""
    steps = np.asarray(steps, dtype=np.float64)
    cols = []
    for j, h in enumerate(steps):
        e = np.zeros(len(steps))
        e[j] = h
        plus, _, _ = residual(renderer, target, *moved(pan_rel_deg, tilt_deg, r_m, e), spp, seed)
        minus, _, _ = residual(renderer, target, *moved(pan_rel_deg, tilt_deg, r_m, -e), spp, seed)
        cols.append((plus - minus) / (2.0 * h))
    return np.stack(cols, axis=1)


def loss_gradient(renderer: LightRenderer, target: np.ndarray, pan_rel_deg: float, tilt_deg: float,
                  r_m: float, spp: int, seed: int, fd_step_deg: float) -> tuple[float, np.ndarray]:
    """The optimiser's gradient of the loss, ``2 J^T r``, per arc degree along
    (pan, tilt): what each LM step is built from. Returns ``(loss, grad (2,))``."""
    vec, loss, _ = residual(renderer, target, pan_rel_deg, tilt_deg, r_m, spp, seed)
    jac = jacobian(renderer, target, pan_rel_deg, tilt_deg, r_m, spp, seed, [fd_step_deg] * 2)
    return loss, 2.0 * jac.T @ vec

"""Gradients of the inverse-rendering loss (relight.inverse.optimize).

The optimiser's direction gradient IS a central finite difference with common random
numbers (see the module docstring for why), so it is checked for (a) consistency with
a much finer difference at many more samples and (b) being a descent direction of the
accurately evaluated loss. Colour is exactly linear: Mitsuba's automatic gradient with
respect to the light intensity is checked against the closed form, the closed form
against a central difference of the loss of renders at shifted intensities, and the
closed-form colour fit recovers a known colour from a render.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from relight.metrics import colour_error_deg

# Production estimator (first level): 32 px, 8 spp, h = 2 deg. Reference: 512 spp,
# h = 0.25 deg. Measured spread of the production estimate on such scenes: 10-35 %
# in magnitude, up to ~25 deg in direction (pixel noise at 8 spp); LM only needs a
# descent direction, so these bounds are what the optimiser relies on.
GRAD_ANGLE_TOL_DEG = 35.0
GRAD_RATIO_RANGE = (0.6, 1.6)
REF_SPP, REF_STEP_DEG = 512, 0.25
FD_SPP, FD_STEP_DEG = 8, 2.0
DESCENT_STEP_DEG = 1.5
COLOUR_EXACT_DEG = 1e-3      # same seed: the render is exactly linear in the RGB intensity
AD_REL_TOL = 1e-3            # float32 sums over 32x32 pixels, relative to sum |terms|


@pytest.fixture(scope="module")
def scene(mi):
    from relight.frames import tangent_move
    from relight.inverse.objective import LightRenderer
    from relight.scene.build import SceneBuilder
    from relight.generator.sampling import GeneratorConfig, sample_scene
    # a generated room with two objects; light at pan_rel 60, tilt 45 (cast shadows on
    # the floor move with the light, which the finite difference includes)
    spec = sample_scene(GeneratorConfig(res=32, spp=64), 11, 3).with_light(60.0, 45.0)
    builder = SceneBuilder()
    target = builder.render(spec).astype(np.float64)
    renderer = LightRenderer(spec, builder)
    pan, tilt = tangent_move(spec.pan_rel_deg, spec.light.tilt_deg, 6.0, -5.0)  # off the optimum
    return spec, target, renderer, pan, tilt


def _angle_deg(a, b):
    from relight.metrics import angle_deg
    return float(angle_deg(a, b))

def test_fd_gradient_matches_fine_reference(scene):
    from relight.inverse.objective import loss_gradient
    spec, target, renderer, pan, tilt = scene
    r = spec.light.r_m
    _, g = loss_gradient(renderer, target, pan, tilt, r, FD_SPP, 1, FD_STEP_DEG)
    _, g_ref = loss_gradient(renderer, target, pan, tilt, r, REF_SPP, 5, REF_STEP_DEG)
    assert np.linalg.norm(g_ref) > 0
    assert _angle_deg(g, g_ref) < GRAD_ANGLE_TOL_DEG
    ratio = np.linalg.norm(g) / np.linalg.norm(g_ref)
    assert GRAD_RATIO_RANGE[0] < ratio < GRAD_RATIO_RANGE[1]
    # the gradient points away from the true light: we moved +6 deg along pan, -5 along tilt
    assert g_ref[0] > 0 and g_ref[1] < 0


def test_loss_decreases_along_fd_gradient(scene):
    from relight.frames import tangent_move
    from relight.inverse.objective import loss_gradient, residual
    spec, target, renderer, pan, tilt = scene
    r = spec.light.r_m
    _, g = loss_gradient(renderer, target, pan, tilt, r, FD_SPP, 1, FD_STEP_DEG)
    step = -DESCENT_STEP_DEG * g / np.linalg.norm(g)
    pan2, tilt2 = tangent_move(pan, tilt, step[0], step[1])
    # judged with many samples and an unrelated seed
    _, before, _ = residual(renderer, target, pan, tilt, r, REF_SPP, 9)
    _, after, _ = residual(renderer, target, pan2, tilt2, r, REF_SPP, 9)
    assert after < before


def test_colour_fit_recovers_known_colour(scene):
    from relight.inverse.objective import colour_fit
    spec, _, renderer, _, _ = scene
    rgb = np.array([0.8, 0.55, 0.3])
    coloured = spec.with_light(rgb=rgb)
    target = renderer.builder.render(coloured).astype(np.float64)  # seed = spec.render.seed
    white = renderer.image(spec.pan_rel_deg, spec.light.tilt_deg, spec.light.r_m, 32,
                            spec.render.spp, spec.render.seed)
    k, loss = colour_fit(target, white)
    assert colour_error_deg(k, rgb) < COLOUR_EXACT_DEG
    # intensity = strength r^2 sqrt(3) rgb_unit versus the white r^2: k = strength sqrt(3) rgb_unit
    np.testing.assert_allclose(k, spec.light.strength * math.sqrt(3) * rgb / np.linalg.norm(rgb), rtol=1e-4)
    assert loss < 1e-8


def test_ad_colour_gradient_matches_closed_form_and_fd(scene, mi):
    from relight import backend
    dr = backend.drjit()
    spec, target, renderer, _, _ = scene
    tpl = renderer.template(32)
    spp, seed, c0 = 8, 3, np.array([300.0, 250.0, 200.0])
    white = renderer.image(spec.pan_rel_deg, spec.light.tilt_deg, spec.light.r_m, 32, spp, seed)
    unit = white / spec.light.r_m ** 2             # image per unit intensity, per channel
    unit_grad = renderer.image(spec.pan_rel_deg, spec.light.tilt_deg, spec.light.r_m, 32, spp,
                                seed + 1000) / spec.light.r_m ** 2

    def loss_rendered(c):   # the loss of a real render at intensity c (same seed)
        tpl.params["light.intensity.value"] = mi.Color3f(*[float(v) for v in c])
        tpl.params.update()
        image = np.array(mi.render(tpl.scene, tpl.params, spp=spp, seed=seed), dtype=np.float64)
        return float(np.sum((target - image) ** 2))

    tpl.params["light.intensity.value"] = mi.Color3f(*[float(v) for v in c0])
    intensity = tpl.params["light.intensity.value"]
    dr.enable_grad(intensity)
    tpl.params.update()
    # Mitsuba differentiates with other samples (seed_grad) than the primal pass
    image = mi.render(tpl.scene, tpl.params, spp=spp, seed=seed, seed_grad=seed + 1000)
    loss = dr.sum(dr.square(mi.TensorXf(target.astype(np.float32)) - image), axis=None)
    dr.backward(loss)
    g_ad = np.array(dr.grad(intensity), dtype=np.float64).ravel()
    dr.disable_grad(intensity)
    g_closed = -2.0 * np.einsum("ijc,ijc->c", target - c0 * unit, unit)
    g_closed_ad = -2.0 * np.einsum("ijc,ijc->c", target - c0 * unit, unit_grad)
    h = 5.0
    g_fd = np.array([(loss_rendered(c0 + h * e) - loss_rendered(c0 - h * e)) / (2 * h)
                     for e in np.eye(3)])
    # the sum cancels (signed residuals): judge errors against the sum of magnitudes
    scale = 2.0 * np.einsum("ijc,ijc->c", np.abs(target - c0 * unit), unit)
    assert np.all(np.abs(g_ad - g_closed_ad) < AD_REL_TOL * scale)
    assert np.all(np.abs(g_fd - g_closed) < AD_REL_TOL * scale)


def test_tangent_move_is_an_arc_step():
    from relight import frames
    from relight.frames import tangent_move
    for pan, tilt in [(10.0, 30.0), (200.0, 89.0), (0.0, 90.0)]:
        for du, dv in [(1.0, 0.0), (0.0, -2.0), (3.0, 4.0)]:
            p2, t2 = tangent_move(pan, tilt, du, dv)
            a = frames.direction(pan, tilt)
            b = frames.direction(p2, t2)
            assert math.degrees(math.acos(np.clip(a @ b, -1, 1))) == pytest.approx(math.hypot(du, dv), abs=1e-6)
    # moving along tilt from 45 deg raises the tilt by the arc; along pan near the horizon ~ pan
    assert tangent_move(30.0, 45.0, 0.0, 2.0) == pytest.approx((30.0, 47.0), abs=1e-9)
    assert tangent_move(30.0, 0.0, 2.0, 0.0) == pytest.approx((32.0, 0.0), abs=1e-9)


def test_downsample_and_colour_fit_closed_forms():
    from relight.errors import InverseError
    from relight.inverse.objective import colour_fit, downsample
    img = np.arange(4 * 4 * 3, dtype=np.float64).reshape(4, 4, 3)
    np.testing.assert_allclose(downsample(img, 2)[0, 0], img[:2, :2].reshape(-1, 3).mean(0))
    with pytest.raises(InverseError, match="multiple"):
        downsample(img, 3)
    r = np.random.default_rng(0).uniform(0.1, 1, (5, 5, 3))
    k, loss = colour_fit(r * [2.0, 3.0, 0.5], r)
    np.testing.assert_allclose(k, [2.0, 3.0, 0.5], rtol=1e-12)
    assert loss == pytest.approx(0.0, abs=1e-20)

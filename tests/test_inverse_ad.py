"""AD light gradients (relight.inverse.ad) against central finite differences, and
``relight invert --gradient ad`` end to end.

The reference is the optimiser's own central difference with common random numbers at
many samples (it includes the shadow-edge terms by construction). The sphere scene's
cast shadow moves about a pixel per degree of light motion, so there the shading-only
AD gradient is clearly short (magnitude ~0.7 of the reference, measured) and only the
edge-sampling term brings it back: the with-shadow test fails without it.
"""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from conftest import NO_TIME_BUDGET, sphere_scene

REF_SPP, REF_STEP_DEG, REF_SEED = 1024, 0.25, 5
AD_SPP, AD_SEED = 128, 2
OFFSET_DEG = (4.0, -3.0)        # evaluation point: the true light moved by these arc steps
# Measured at these settings: with shadow angle 0.09 deg, ratio 0.99 (shading only: 0.69);
# empty room angle 0.04 deg, ratio 1.00. The bounds leave room for other seeds and platforms.
GRAD_ANGLE_TOL_DEG = 4.0
GRAD_RATIO_RANGE = (0.9, 1.1)
SHADING_ONLY_MAX_RATIO = 0.85   # without the edge term the sphere scene's gradient is short
DIRECTION_TOL_DEG = 1.0         # end to end on a 32 px image
COLOUR_TOL_DEG = 0.5
PROJECTION_TOL_PX = 1e-4
VP_JACOBIAN_TOL = 1e-7          # float64 central difference, h = 1e-6


def _angle_deg(a, b):
    from relight.metrics import angle_deg
    return float(angle_deg(a, b))

def _setup(spec):
    from relight.frames import tangent_move
    from relight.inverse.objective import LightRenderer
    from relight.scene.build import SceneBuilder
    builder = SceneBuilder(max_templates=2)
    target = builder.render(spec).astype(np.float64)
    renderer = LightRenderer(spec, builder)
    pan, tilt = tangent_move(spec.pan_rel_deg, spec.light.tilt_deg, *OFFSET_DEG)
    return renderer, target, pan, tilt


def _compare(spec, visibility=True):
    from relight.inverse.ad import ADJacobian, ADSettings, ad_loss_gradient
    from relight.inverse.objective import loss_gradient
    renderer, target, pan, tilt = _setup(spec)
    r = spec.light.r_m
    _, g_ref = loss_gradient(renderer, target, pan, tilt, r, REF_SPP, REF_SEED, REF_STEP_DEG)
    est = ADJacobian(renderer, ADSettings(visibility=visibility))
    _, g_ad = ad_loss_gradient(renderer, target, pan, tilt, r, AD_SPP, AD_SEED, estimator=est)
    return g_ad, g_ref, est


def test_ad_gradient_with_moving_cast_shadow(mi):
    # light from the camera's right at tilt 35: the sphere's shadow falls to the left on
    # the floor, in view, and moves with the light
    spec = sphere_scene(pan_rel_deg=90.0, tilt_deg=35.0, camera_tilt_deg=30.0, res=32, spp=256)
    g_ad, g_ref, est = _compare(spec)
    assert est.last_stats["used"] > 100          # edge samples landed on the visible shadow edge
    assert _angle_deg(g_ad, g_ref) < GRAD_ANGLE_TOL_DEG
    ratio = np.linalg.norm(g_ad) / np.linalg.norm(g_ref)
    assert GRAD_RATIO_RANGE[0] < ratio < GRAD_RATIO_RANGE[1]
    g_shading, _, _ = _compare(spec, visibility=False)
    assert np.linalg.norm(g_shading) / np.linalg.norm(g_ref) < SHADING_ONLY_MAX_RATIO


def test_ad_gradient_without_shadows(mi):
    # an empty room: no occluder, so no edge term; shading alone must match
    spec = dataclasses.replace(sphere_scene(pan_rel_deg=120.0, tilt_deg=50.0, res=32, spp=256), objects=())
    g_ad, g_ref, est = _compare(spec)
    assert est.last_stats["edges"] == 0
    assert _angle_deg(g_ad, g_ref) < GRAD_ANGLE_TOL_DEG
    ratio = np.linalg.norm(g_ad) / np.linalg.norm(g_ref)
    assert GRAD_RATIO_RANGE[0] < ratio < GRAD_RATIO_RANGE[1]


def test_pinhole_matches_mitsuba_sensor(mi):
    from relight.inverse.ad import Pinhole
    from relight.inverse.objective import LightRenderer
    from relight.scene.build import SceneBuilder
    spec = sphere_scene(res=16, spp=4)
    sensor = LightRenderer(spec, SceneBuilder(max_templates=1)).template(16).scene.sensors()[0]
    u = np.array([[0.5, 0.5], [3.25, 12.0], [15.9, 8.0]])
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f((u / 16).T.astype(np.float32)), mi.Point2f(0.5, 0.5))
    o = np.array([np.array(ray.o[i]) for i in range(3)]).T
    d = np.array([np.array(ray.d[i]) for i in range(3)]).T
    cam = Pinhole(spec.camera, 16)
    back, depth = cam.project(o + 7.0 * d)
    assert np.all(depth > 0)
    np.testing.assert_allclose(back, u, atol=PROJECTION_TOL_PX * 16 * 10)


def test_silhouette_of_a_closed_mesh(mi):
    # a closed convex mesh seen from a far point: the silhouette is one closed loop,
    # every silhouette vertex joins exactly two silhouette edges
    from relight.inverse.ad import Occluders
    spec = sphere_scene()
    occ = Occluders(spec)
    assert not occ.boundary.any()             # seams welded: no open edges
    mask, side = occ.silhouette(np.array([0.0, 30.0, 20.0]))
    assert mask.sum() > 10 and np.all(side[mask] != 0)
    ends = np.concatenate([occ.a[mask], occ.b[mask]])
    _, counts = np.unique(np.round(ends, 6), axis=0, return_counts=True)
    assert np.all(counts == 2)


def test_bad_gradient_name():
    from relight.inverse.optimize import InverseError, InvertConfig
    with pytest.raises(InverseError, match="gradient"):
        InvertConfig(gradient="magic")


def test_invert_gradient_ad_end_to_end(mi, tmp_path):
    from relight.cli import main
    from relight.metrics import light_errors
    from relight.imageio import write_exr
    from relight.scene.build import SceneBuilder
    spec = sphere_scene(pan_rel_deg=70.0, tilt_deg=40.0, camera_tilt_deg=30.0, res=32, spp=64,
                        rgb=(1.0, 0.8, 0.6))
    scene_path, image_path, out = tmp_path / "s.json", tmp_path / "s.exr", tmp_path / "p.json"
    spec.save(scene_path)
    write_exr(str(image_path), SceneBuilder(max_templates=1).render(spec))
    assert main(["invert", "--scene", str(scene_path), "--image", str(image_path), "--out", str(out),
                 "--gradient", "ad", "--init", "grid", "--quiet", *NO_TIME_BUDGET]) == 0
    doc = json.loads(out.read_text())
    assert doc["settings"]["gradient"] == "ad"
    p = doc["predictions"][0]
    e = light_errors(p["pan_deg"], p["tilt_deg"], p["rgb"], spec.pan_rel_deg, spec.light.tilt_deg,
                     spec.light.rgb)
    assert e["direction"] < DIRECTION_TOL_DEG and e["colour"] < COLOUR_TOL_DEG, e
    assert (tmp_path / "p.trace.csv").read_text().startswith("id,iteration,stage")


def test_vp_jacobian_matches_central_difference_of_the_residual():
    # pure numpy: a render that moves linearly with two parameters; the closed-form
    # colour scale k is re-fitted at every point, as the finite-difference Jacobian does
    from relight.inverse.ad import vp_jacobian
    from relight.inverse.objective import colour_fit
    rng = np.random.default_rng(3)
    target = rng.uniform(0.1, 1.0, (6, 6, 3))
    r0 = target * [1.5, 0.8, 1.1] + rng.normal(0, 0.05, target.shape)
    d = rng.normal(0, 0.1, (6, 6, 3, 2))

    def res(theta):
        render = r0 + d @ theta
        k, _ = colour_fit(target, render)
        return ((target - k * render) / np.linalg.norm(target)).ravel()

    h = 1e-6
    fd = np.stack([(res(h * e) - res(-h * e)) / (2 * h) for e in np.eye(2)], axis=1)
    jac = vp_jacobian(target, r0, d, colour_fit(target, r0)[0])
    np.testing.assert_allclose(jac, fd, atol=VP_JACOBIAN_TOL)

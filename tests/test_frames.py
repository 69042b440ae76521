"""Conventions module: closed forms, round trips, wrap-around, camera and Mitsuba frames."""
import math

import numpy as np
import pytest

from relight import frames

TOL = 1e-12


def test_spherical_closed_forms():
    # pan 0 / tilt 0 is +X; pan 90 is +Y (counter-clockwise from above); tilt 90 is +Z.
    assert np.allclose(frames.spherical_to_cartesian(2.0, 0, 0), [2, 0, 0], atol=TOL)
    assert np.allclose(frames.spherical_to_cartesian(2.0, 90, 0), [0, 2, 0], atol=TOL)
    assert np.allclose(frames.spherical_to_cartesian(2.0, 123, 90), [0, 0, 2], atol=TOL)
    s = math.sqrt(0.5)
    assert np.allclose(frames.direction(45, 45), [0.5, 0.5, s], atol=TOL)


def test_spherical_round_trip():
    rng = np.random.default_rng(0)
    r, pan, tilt = rng.uniform(1, 50, 100), rng.uniform(0, 360, 100), rng.uniform(-89, 89, 100)
    r2, pan2, tilt2 = frames.cartesian_to_spherical(frames.spherical_to_cartesian(r, pan, tilt))
    assert np.allclose(r2, r) and np.allclose(tilt2, tilt)
    assert np.allclose(frames.wrap180(pan2 - pan), 0, atol=1e-9)


def test_wrap():
    assert frames.wrap360(-1) == 359 and frames.wrap360(360) == 0 and frames.wrap360(725) == 5
    assert frames.wrap180(181) == -179 and frames.wrap180(-180) == -180 and frames.wrap180(359 - 1) == -2
    assert 0 <= frames.wrap360(-1e-20) < 360
    # pan 359 vs 1 is 2 degrees apart
    assert abs(frames.wrap180(359 - 1)) == pytest.approx(2.0)


def test_pan_rel():
    assert frames.pan_rel_deg(90, 0) == 90
    assert frames.pan_rel_deg(10, 30) == 340


def test_encode_decode_round_trip():
    rng = np.random.default_rng(1)
    pan, tilt = rng.uniform(0, 360, 50), rng.choice(np.arange(30, 91, 5), 50).astype(float)
    tilt_c = rng.uniform(10, 70, 50)
    rgb = rng.uniform(0.1, 1, (50, 3))
    y = frames.encode_y(pan, tilt, rgb, tilt_c)
    assert y.shape == (50, 7)
    pan2, tilt2, rgb2 = frames.decode_y(y, tilt_c)
    assert np.allclose(frames.wrap180(pan2 - pan), 0, atol=1e-9)
    assert np.allclose(tilt2, tilt) and np.allclose(rgb2, rgb)
    # decoding does not need unit sin/cos pairs (a network's raw output)
    pan3, tilt3, _ = frames.decode_y(y * np.array([3, 3, 0.5, 0.5, 1, 1, 1]), tilt_c)
    assert np.allclose(frames.wrap180(pan3 - pan), 0, atol=1e-9) and np.allclose(tilt3, tilt)


def test_encode_closed_form():
    # pan_c = 0, pan_l = 90: sin(-90) = -1, cos(-90) = 0; tilt_c 40, tilt_l 70: sin(-30) = -0.5
    y = frames.encode_y(90.0, 70.0, [1, 0, 0], 40.0)
    assert np.allclose(y, [-1, 0, -0.5, math.cos(math.radians(30)), 1, 0, 0], atol=TOL)
    with pytest.raises(ValueError):
        frames.decode_y([1, 2, 3], 40.0)


def test_camera_basis_pan0_right_is_plus_y():
    right, up, forward = frames.camera_basis(30.0)
    assert np.allclose(right, [0, 1, 0], atol=TOL)        # conventions: right-hand side is +Y
    assert np.allclose(forward, -frames.direction(0, 30), atol=TOL)
    assert up[2] > 0 and abs(np.dot(up, forward)) < TOL
    with pytest.raises(ValueError):
        frames.camera_basis(90.0)


def test_world_camera_round_trip():
    v = np.random.default_rng(2).normal(size=(20, 3))
    c = frames.world_to_camera(v, 25.0, 10.0)
    assert np.allclose(frames.camera_to_world_vector(c, 25.0, 10.0), v)
    # the camera position maps to +z (toward the camera), +Y to the image right for pan_c = 0
    assert np.allclose(frames.world_to_camera(frames.direction(0, 25.0), 25.0), [0, 0, 1], atol=TOL)
    assert np.allclose(frames.world_to_camera([0, 1, 0], 25.0), [1, 0, 0], atol=TOL)


def test_mitsuba_sensor_matches_look_at(mi):
    origin = frames.camera_position(35.0, 20.0)
    ref = np.array(mi.ScalarTransform4f().look_at(origin=origin.tolist(), target=[0, 0, 0], up=[0, 0, 1]).matrix)
    assert np.allclose(frames.mitsuba_sensor_to_world(35.0, 20.0), ref, atol=1e-5)


def test_travel_direction_flips_sign():
    assert np.allclose(frames.travel_direction([0, 0, 1]), [0, 0, -1])


def test_tangent_basis_is_the_derivative_of_direction():
    # d(direction)/d(tilt) = e_tilt and d(direction)/d(pan) = cos(tilt) e_pan (central
    # differences, 1e-4 deg); both orthogonal to the direction; e_tilt up at the horizon.
    h = 1e-4
    for pan, tilt in [(0.0, 0.0), (123.0, 35.0), (300.0, 80.0)]:
        e_pan, e_tilt = frames.tangent_basis(pan, tilt)
        d_pan = (frames.direction(pan + h, tilt) - frames.direction(pan - h, tilt)) / np.radians(2 * h)
        d_tilt = (frames.direction(pan, tilt + h) - frames.direction(pan, tilt - h)) / np.radians(2 * h)
        assert np.allclose(d_pan, np.cos(np.radians(tilt)) * e_pan, atol=1e-7)
        assert np.allclose(d_tilt, e_tilt, atol=1e-7)
        assert abs(e_pan @ frames.direction(pan, tilt)) < TOL and abs(e_tilt @ e_pan) < TOL
    assert np.allclose(frames.tangent_basis(0.0, 0.0)[1], [0, 0, 1])


@pytest.mark.parametrize("pan,tilt,want_pan,want_tilt", [
    (10.0, 108.8, 190.0, 71.2), (200.0, 90.0, 200.0, 90.0), (0.0, 180.0, 180.0, 0.0),
    (350.0, -100.0, 170.0, -80.0), (45.0, 30.0, 45.0, 30.0), (90.0, 270.0, 90.0, -90.0)])
def test_fold_over_zenith_keeps_the_direction(pan, tilt, want_pan, want_tilt):
    p, t = frames.fold_over_zenith(pan, tilt)
    assert (p, t) == pytest.approx((want_pan, want_tilt), abs=1e-9)
    assert -90.0 <= t <= 90.0
    assert np.allclose(frames.direction(p, t), frames.direction(pan, tilt), atol=1e-12)


def test_decode_y_folds_tilt_over_the_zenith():
    """A light 20 deg past the zenith on the camera side decodes as tilt 70 from behind."""
    y = frames.encode_y(0.0, 110.0, np.array([1.0, 1.0, 1.0]), 45.0)
    pan, tilt, _ = frames.decode_y(y, 45.0)
    assert float(tilt) == pytest.approx(70.0) and float(pan) == pytest.approx(180.0)
    ys = np.stack([frames.encode_y(p, t, np.ones(3), 30.0) for p, t in [(10, 100), (200, 60), (300, -95)]])
    pans, tilts, _ = frames.decode_y(ys, 30.0)
    assert np.all(np.abs(tilts) <= 90.0)
    for (p, t), pd, td in zip([(10, 100), (200, 60), (300, -95)], pans, tilts):
        assert np.allclose(frames.direction(pd, td), frames.direction(p, t), atol=1e-9)


def test_perpendicular_pair_completes_a_right_handed_frame():
    rng = np.random.default_rng(7)
    for a in list(rng.normal(size=(200, 3))) + [np.array([0.0, 1.0, 0.0]), np.array([0.0, -1.0, 0.0])]:
        a = a / np.linalg.norm(a)
        e1, e2 = frames.perpendicular_pair(a)
        m = np.stack([e1, e2, a], axis=1)
        assert np.allclose(m.T @ m, np.eye(3), atol=1e-12)
        assert np.isclose(np.linalg.det(m), 1.0, atol=1e-12)


@pytest.mark.parametrize("tilt,pan", [(0.0, 0.0), (35.0, 20.0), (70.0, 250.0), (-20.0, 90.0)])
def test_sensor_frame_is_the_cameras_mitsuba_frame(tilt, pan):
    # a camera looking at the origin with up +Z: the same rotation as mitsuba_sensor_to_world
    forward = frames.camera_basis(tilt, pan)[2]
    m = frames.sensor_frame(forward, [0.0, 0.0, 1.0])
    assert np.allclose(m, frames.mitsuba_sensor_to_world(tilt, 20.0, pan)[:3, :3], atol=1e-12)

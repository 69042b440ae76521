"""Probe renders: spheres and the pole's cast shadow follow the light convention.

Convention (shared/conventions.md): the camera sits at pan 0 on the +X side looking at
the origin, its right-hand side is +Y; pan_rel 90 puts the light at +Y, i.e. on the
camera's right, so lit sides face image right and shadows fall toward image left.
"""
import numpy as np
import pytest

from relight.verify import spheres

RES, SPP = 48, 16
CAMERA_TILT_DEG = 45.0
SHADOW_DROP = 0.05          # luminance drop (linear) that counts as shadow
MIN_OFFSET_PX = 4           # shadow centroid at least this far from the pole base
CENTRE_REL_TOL = 0.05       # Monte Carlo noise of a 3x3 mean at 16 spp
LIT_RATIO = 3.0             # lit half of the diffuse sphere vs the dark half


def _lum(img):
    return img[..., :3] @ np.array([0.2126, 0.7152, 0.0722])


def _shadow_centroid(pan_rel_deg, tilt_deg=30.0):
    ground = spheres.render_probe("ground", pan_rel_deg, tilt_deg, [1, 1, 1], CAMERA_TILT_DEG, RES, SPP)
    pole = spheres.render_probe("pole", pan_rel_deg, tilt_deg, [1, 1, 1], CAMERA_TILT_DEG, RES, SPP)
    mask = (_lum(ground) - _lum(pole)) > SHADOW_DROP
    assert mask.sum() >= 3, "no shadow found"
    ys, xs = np.nonzero(mask)
    return xs.mean(), ys.mean()


def test_shadow_points_away_from_light(mi):
    centre = (RES - 1) / 2.0  # the pole stands at the origin, imaged at the centre
    x_right_light, _ = _shadow_centroid(90.0)     # light on camera's right -> shadow left
    x_left_light, _ = _shadow_centroid(270.0)     # light on camera's left -> shadow right
    _, y_back_light = _shadow_centroid(180.0)     # light behind the scene -> shadow toward camera (down)
    assert x_right_light < centre - MIN_OFFSET_PX
    assert x_left_light > centre + MIN_OFFSET_PX
    assert y_back_light > centre + MIN_OFFSET_PX / 2


def test_diffuse_sphere_lit_from_the_right(mi):
    diffuse, specular = spheres.sphere_pair(90.0, 20.0, [1, 1, 1], CAMERA_TILT_DEG, RES, SPP)
    lum = _lum(diffuse)
    assert lum[:, RES // 2:].mean() > LIT_RATIO * lum[:, :RES // 2].mean()
    y, x = np.unravel_index(np.argmax(_lum(specular)), (RES, RES))
    assert x > RES // 2  # the highlight is on the lit side


def test_light_colour_and_alpha(mi):
    # Light straight from the camera's direction: the sphere's centre pixel faces it.
    # Lambert: radiance = albedo / pi * E with E = SUN_IRRADIANCE * 1 (unit rgb (1, 0, 0)),
    # plus the grey sky reflected: albedo * SKY_RADIANCE (whole hemisphere visible).
    img = spheres.render_probe("diffuse", 0.0, CAMERA_TILT_DEG, [2, 0, 0], CAMERA_TILT_DEG, RES, SPP)
    assert img.shape == (RES, RES, 4)
    c = RES // 2
    centre = img[c - 1:c + 2, c - 1:c + 2, :3].mean(axis=(0, 1))
    sky = spheres.DIFFUSE_ALBEDO * spheres.SKY_RADIANCE
    expected_red = spheres.DIFFUSE_ALBEDO / np.pi * spheres.SUN_IRRADIANCE + sky
    assert centre[0] == pytest.approx(expected_red, rel=CENTRE_REL_TOL)
    assert centre[1] == pytest.approx(sky, rel=0.5) and centre[2] == pytest.approx(sky, rel=0.5)
    assert img[0, 0, 3] == 0.0 and img[RES // 2, RES // 2, 3] == 1.0   # background / sphere


def test_overlay_pole_top_left():
    image = np.full((40, 60, 3), 0.2, np.float32)
    inset = np.zeros((10, 10, 4), np.float32)
    inset[..., :3], inset[..., 3] = 1.0, 1.0
    out = spheres.overlay_pole(image, inset, margin_px=2)
    assert out[2:12, 2:12].min() == 1.0 and out[20:, 20:].max() == pytest.approx(0.2)
    assert image.max() == pytest.approx(0.2)   # input untouched


def test_bad_arguments(mi):
    with pytest.raises(ValueError):
        spheres.render_probe("cube", 0, 45, [1, 1, 1], 30)
    with pytest.raises(ValueError):
        spheres.render_probe("diffuse", 0, 45, [0, 0, 0], 30)

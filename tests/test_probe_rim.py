"""The learned rim reader (relight.probe.rim): a chrome outline read across its rim."""
from __future__ import annotations

import math

import numpy as np
import pytest

from relight.probe import detect, rim
from relight.probe import geometry as pg

W, H, FOV_DEG = 160, 120, 40.0


def _sphere_at(camera, x, y, angular_radius_deg, distance=5.0):
    _, d = camera.rays(np.array(x), np.array(y))
    return pg.Sphere(tuple((d * distance).tolist()), distance * math.sin(math.radians(angular_radius_deg)))


def test_radial_samples_lie_on_lines_through_the_outline():
    # a linear image (a cubic spline reproduces it exactly, pixel centres at +0.5): each
    # sample is the image's value where the line crosses the outline, plus its offset
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 70.3, 58.6, 8.0)
    ys, xs = np.mgrid[0:H, 0:W] + 0.5
    image = np.stack([xs, ys, xs + 2 * ys], -1)
    samples, cx, cy, theta, r_theta = detect.radial_samples(image, cam, sphere, rim.OFFSETS, rim.LINES)
    assert samples.shape == (rim.LINES, len(rim.OFFSETS), 3)
    ox, oy, _ = pg.outline_circle(cam, sphere)
    assert (cx, cy) == pytest.approx((ox, oy))
    s = r_theta[:, None] + rim.OFFSETS[None, :]
    # (to a hundredth of a pixel: the spline's border a few pixels off bends it a little)
    assert np.allclose(samples[..., 0], cx + s * np.cos(theta)[:, None], atol=0.01)
    assert np.allclose(samples[..., 1], cy + s * np.sin(theta)[:, None], atol=0.01)
    # the outline's own points, at offset 0, lie on the outline
    x0, y0 = samples[:, rim.OFFSETS.tolist().index(0.0), 0], samples[:, rim.OFFSETS.tolist().index(0.0), 1]
    assert np.abs(detect._outline_distance(cam, sphere, x0, y0)).max() < 0.01


def test_features_read_a_dark_rim_as_a_bright_one():
    rng = np.random.default_rng(1)
    p = rng.uniform(0.2, 1.0, (5, len(rim.OFFSETS), 3))
    a, b = rim.features(p), rim.features(0.5 * p)
    # the profile's shape is the same (to the 1% the floor on its spread leaves); its
    # spread and level say it is twice as dark
    assert np.allclose(a[:, :-2], b[:, :-2], atol=0.03)
    assert np.allclose(a[:, -2] - b[:, -2], math.log(2.0), atol=0.02)
    assert np.allclose(a[:, -1] - b[:, -1], math.log(2.0), atol=0.02)
    # and a shifted edge is another profile
    assert not np.allclose(a[:, :-2], rim.features(np.roll(p, 2, axis=1))[:, :-2], atol=1e-2)


def _circle_points(cam, sphere, grow_px):
    """Points on ``sphere``'s outline moved out by ``grow_px`` (the network's reading, faked)."""
    cx, cy, _ = pg.outline_circle(cam, sphere)
    x, y = pg.outline_polygon(cam, sphere, rim.LINES)
    d = np.hypot(x - cx, y - cy)
    return np.stack([x + grow_px * (x - cx) / d, y + grow_px * (y - cy) / d], 1)


@pytest.mark.parametrize("grow_px, trusted", [(0.3, True), (rim.GUARD_PX + 0.3, False)])
def test_a_reading_far_from_the_shifted_fit_is_not_trusted(monkeypatch, grow_px, trusted):
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    fit = _sphere_at(cam, 80.0, 60.0, 6.0)
    shifted = detect.outline_from_rim(cam, fit, 0.1)
    monkeypatch.setattr(rim, "line_offsets", lambda smoothed, camera, sphere, path=rim.WEIGHTS:
                        _circle_points(camera, sphere, grow_px))
    sphere, read = rim.read_outline(np.zeros((H, W, 3)), cam, fit, shifted)
    assert read is trusted
    want = detect.outline_from_rim(cam, fit, grow_px) if trusted else shifted
    assert np.allclose(pg.outline_circle(cam, sphere), pg.outline_circle(cam, want), atol=0.01)


def test_missing_or_foreign_weights_are_one_line_errors(tmp_path):
    from relight.errors import ProbeError
    with pytest.raises(ProbeError, match="no rim reader weights"):
        rim.load_rim(str(tmp_path / "none.safetensors"))
    bad = tmp_path / "bad.safetensors"
    bad.write_bytes(b"not a safetensors file")
    with pytest.raises(ProbeError, match="not the rim reader"):
        rim.load_rim(str(bad))


def test_shipped_reader_reads_fresh_renders_nearer_the_truth_than_one_shift():
    # rooms of the probe set's default draw (a gray ball, clutter, lit floor and walls) with
    # seeds no training or judging set uses, rendered here by Mitsuba at 128 px and written
    # as 8-bit; the rim fit started at the true outline, as in training. Where the fit
    # found the rim's edges (it did on 6 of 8; on the others it returns the start, and the
    # one shift then lands on the truth by construction), the outline read is nearer the
    # truth than the fit moved out by the one shift, summed over the scenes (centre offset
    # plus radius error: 1.01 against 1.14 px when measured; read nearer on 5 of 6)
    from relight import backend
    from relight.colour import srgb_decode
    from relight.imageio import to_srgb8
    from relight.verify import probe_scenes as ps
    backend.init()
    errors = {"shift": 0.0, "read": 0.0}
    fitted = 0
    for seed in range(7100, 7108):
        d = ps.sample_room_scene(seed, res=128)
        linear = ps.render_room_mitsuba(d, spp=16)
        image = srgb_decode(to_srgb8(linear, detect.camera_exposure(linear, 0.02)).astype(np.float64) / 255.0)
        truth = d["truth"]["chrome_circle"]
        cam = pg.Camera.from_fov(image.shape[1], image.shape[0], d["truth"]["fov_deg"])
        start = detect.outline_from_rim(cam, pg.sphere_from_circle(cam, *truth), -detect.chrome_rim_shift_px(image))
        smoothed = detect.edge_image(image, 1.0)
        fit = detect.outer_rim_fit(smoothed, cam, start)
        if fit is start:
            continue
        fitted += 1
        shifted = detect.outline_from_rim(cam, fit, detect.chrome_rim_shift_px(image))
        read, trusted = rim.read_outline(smoothed, cam, fit, shifted)
        assert trusted
        for name, sphere in (("shift", shifted), ("read", read)):
            cx, cy, r = pg.outline_circle(cam, sphere)
            errors[name] += math.hypot(cx - truth[0], cy - truth[1]) + abs(r - truth[2])
    assert fitted >= 5
    assert errors["read"] < errors["shift"]

"""The learned outline check (relight.probe.outline_check) and the detector's second start from it."""
from __future__ import annotations

import dataclasses
import math
import os

import numpy as np
import pytest

from relight.probe import detect
from relight.probe import outline_check as oc


def _disc(h, w, cx, cy, r, ss=8):
    """A white disc (pixel centres at +0.5) on black, area-sampled."""
    ys, xs = np.mgrid[0:h * ss, 0:w * ss] + 0.5
    inside = (xs / ss - cx) ** 2 + (ys / ss - cy) ** 2 <= r * r
    return np.repeat(inside.reshape(h, ss, w, ss).mean((1, 3))[..., None], 3, -1).astype(np.float32)


@pytest.mark.parametrize("r", [6.0, 16.0, 40.0])     # enlarged, one to one, shrunk (with its filter)
def test_the_crop_shows_the_circle_window_radii_across_centred(r):
    cx, cy = 100.3, 90.7
    img = _disc(200, 220, cx, cy, r)
    x = oc.crop(img, (cx, cy, r))[..., 0]
    assert x.shape == (oc.SIZE, oc.SIZE)
    k = oc.SIZE / oc.WINDOW                      # the circle's radius in the crop
    assert x.sum() == pytest.approx(math.pi * k * k, rel=0.02)
    ys, xs = np.mgrid[0:oc.SIZE, 0:oc.SIZE] + 0.5
    assert (xs * x).sum() / x.sum() == pytest.approx(oc.SIZE / 2, abs=0.05)
    assert (ys * x).sum() / x.sum() == pytest.approx(oc.SIZE / 2, abs=0.05)
    # seen from a circle 0.3 radii to the left and 1.25 times as large, the disc lies right of
    # the crop's centre by 0.3 / 1.25 of the candidate's radius, its radius 1 / 1.25 of it
    x = oc.crop(img, (cx - 0.3 * r, cy, 1.25 * r))[..., 0]
    assert x.sum() == pytest.approx(math.pi * (k / 1.25) ** 2, rel=0.03)
    assert (xs * x).sum() / x.sum() == pytest.approx(oc.SIZE / 2 + 0.3 / 1.25 * k, abs=0.1)


def test_training_candidates_and_targets_agree():
    rng = np.random.default_rng(3)
    truth = (120.0, 80.0, 15.0)
    cands, t = oc.sample_candidates(truth, 500, rng)
    off = np.hypot(cands[:, 0] - truth[0], cands[:, 1] - truth[1]) / truth[2]
    assert off.max() <= oc.TRAIN_MAX_OFFSET and off.max() > 0.9 * oc.TRAIN_MAX_OFFSET
    ratio = cands[:, 2] / truth[2]
    assert ratio.min() >= oc.TRAIN_RADIUS_RANGE[0] and ratio.max() <= oc.TRAIN_RADIUS_RANGE[1]
    # the targets put each candidate back on the truth
    back = np.stack([cands[:, 0] + t[:, 0] * cands[:, 2], cands[:, 1] + t[:, 1] * cands[:, 2],
                     cands[:, 2] * np.exp(t[:, 2])], 1)
    assert np.allclose(back, truth, atol=1e-3)


def _scene():
    from relight.probe import geometry as pg
    from test_probe_hard import FOV_DEG, H, W, _quantise, _render, _sphere_at
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 62.0, 5.0)
    image = _quantise(_render(cam, sphere, np.array([0.3, 0.4, 0.87])))
    return cam, sphere, image


def _candidate(cam, image, circle):
    sphere = detect.sphere_from_circle(cam, *circle)
    return {"sphere": sphere, "circle": detect.outline_circle(cam, sphere), "edge_support": 0.4, "chrome": True,
            **detect.sphere_features(image, cam, sphere, 1.0)}


def test_a_wrong_outline_is_fitted_again_where_the_check_puts_the_sphere():
    cam, sphere, image = _scene()
    truth = detect.outline_circle(cam, sphere)
    smoothed = detect._edge_image(image)
    wrong = _candidate(cam, image, (truth[0] + 3.0, truth[1] + 2.0, 1.25 * truth[2]))
    # a check that knows where the sphere is (slightly off, as a network would be): the
    # outline is fitted there, on the sphere's edges
    sure = lambda circles: np.array([(truth[0] + 0.4, truth[1] - 0.3, truth[2] * 1.04)] * len(circles))
    got = detect._checked_outline(image, cam, wrong, smoothed, 1.0, sure)
    assert got["checked_from"] == wrong["circle"]
    assert math.dist(got["circle"][:2], truth[:2]) < 0.3 and abs(got["circle"][2] - truth[2]) < 0.3
    # a check that agrees with the candidate leaves it as it is
    agree = lambda circles: np.asarray(circles, float)
    assert detect._checked_outline(image, cam, wrong, smoothed, 1.0, agree) is wrong
    # ... and so does one pointing where no outline is (the edge fit finds nothing there, or
    # something the check, asked again, likes no better)
    nowhere = lambda circles: np.array([(20.0, 20.0, 8.0)] * len(circles))
    assert detect._checked_outline(image, cam, wrong, smoothed, 1.0, nowhere) is wrong


def test_find_spheres_asks_the_check_about_chrome_outlines_and_keeps_those_it_agrees_with():
    cam, sphere, image = _scene()
    asked = []

    def agree(circles):
        asked.extend(map(tuple, np.asarray(circles)))
        return np.asarray(circles, float)
    plain = detect.find_spheres(image, cam, 1.0)
    checked = detect.find_spheres(image, cam, 1.0, outline_check=agree)
    chrome = [c["circle"] for c in plain if c["chrome"]]
    assert chrome and sorted(asked) == sorted(chrome)
    assert [c["circle"] for c in checked] == [c["circle"] for c in plain]


def test_of_two_nested_chrome_circles_the_one_the_check_prefers_stays():
    # a sphere's circle (r 17) and its cast shadow's (r 19, lower; as well supported): the
    # rules keep the outer one; when the check, seen from each, puts the sphere clearly
    # nearer the inner one, the outer one goes instead
    def cand(circle, support, gap):
        return {"circle": circle, "edge_support": support, "chrome": True, "check_gap": gap}
    sphere, shadow = (100.0, 100.0, 17.0), (100.5, 101.8, 19.0)
    keep = lambda a, b: [c["circle"] for c in detect._drop_inner_circles([cand(sphere, *a), cand(shadow, *b)])]
    assert keep((0.54, None), (0.55, None)) == [shadow]
    assert keep((0.54, 0.05), (0.55, 0.22)) == [sphere]
    assert keep((0.54, 0.05), (0.55, 0.05 + detect.CHECK_PREFER - 0.01)) == [shadow]     # within the margin
    assert keep((0.54, 0.05), (0.55, None)) == [shadow]                                   # no opinion on one
    assert keep((0.54, 0.22), (0.55, 0.05)) == [shadow]
    # an outer circle clearly less supported never hid the inner one: both stay, whatever the check
    assert len(keep((0.70, 0.22), (0.55, 0.05))) == 2 and len(keep((0.70, 0.05), (0.55, 0.22))) == 2
    # the check's preference concerns chrome circles only
    got = detect._drop_inner_circles([{**cand(sphere, 0.54, 0.05), "chrome": False}, cand(shadow, 0.55, 0.22)])
    assert [c["circle"] for c in got] == [shadow]


def _mirror_with_a_shadow(scale: float):
    """The test sphere on a lit floor (0.35) with its cast shadow (0.05) beside its lower
    half: a disc ``scale`` times its radius whose top nearly touches the sphere's, as an
    8-bit image; returns ``(image, cam, true circle, shadow circle)``."""
    from test_probe_hard import _mirror_over

    def shadow_of(circle):
        cx, cy, r = circle
        return (cx + 0.3 * (scale - 1.0) * r, cy + 0.95 * (scale - 1.0) * r, scale * r)

    def floor(xs, ys, circle):
        sx, sy, sr = shadow_of(circle)
        return np.where((np.hypot(xs - sx, ys - sy) < sr) & (ys > circle[1]), 0.05, 0.35)
    image, cam, circle = _mirror_over(floor)
    return image, cam, circle, shadow_of(circle)


def test_a_cast_shadows_circle_gives_way_to_the_sphere_the_check_finds():
    image, cam, truth, shadow = _mirror_with_a_shadow(1.2)
    near = lambda c, ref, tol: math.dist(c[:2], ref[:2]) < tol and abs(c[2] - ref[2]) < tol
    # the premise: with no preference from the check (it agrees with every circle) the
    # detector settles on the shadow's circle
    agree = lambda circles: np.asarray(circles, float)
    picked = detect.pick_sphere(detect.find_spheres(image, cam, 1.0, outline_check=agree), "chrome")["circle"]
    assert near(picked, shadow, 0.5) and not near(picked, truth, 2.0)
    # a check that knows where the sphere is (slightly off, as a network would be): the
    # sphere's own circle is fitted there and the shadow's gives way to it
    sure = lambda circles: np.array([(truth[0] + 0.2, truth[1] - 0.1, truth[2] * 1.02)] * len(circles))
    picked = detect.pick_sphere(detect.find_spheres(image, cam, 1.0, outline_check=sure), "chrome")["circle"]
    assert near(picked, truth, 0.3)


def test_the_check_judges_circles_up_to_the_largest_it_was_trained_on():
    # candidates up to 1.5 times a sphere of at most 15% of the side: 22.5% of it, beyond
    # the locator's own range (16.5%)
    from relight.probe import locator
    side = 400
    top = oc.TRAIN_RADIUS_RANGE[1] * locator.TRAINED_RADIUS_FRACTION * side
    assert top == pytest.approx(0.225 * side)
    assert oc.judges(0.2 * side, side, 300) and not locator.judges(0.2 * side, side, 300)
    assert oc.judges(top - 0.01, 300, side) and not oc.judges(top + 0.01, 300, side)


@pytest.mark.skipif(not os.path.exists(oc.WEIGHTS), reason="no shipped outline check weights")
def test_the_detectors_check_speaks_only_for_circles_it_can_judge():
    # on a 100 px image: a 10 px circle gets the network's answer, a 30 px one (over 22.5 px)
    # comes back as it is
    codes = np.random.default_rng(1).random((100, 100, 3))
    circles = np.array([(50.0, 50.0, 10.0), (50.0, 50.0, 30.0)])
    got = oc.check_circles(codes, circles)
    assert np.allclose(got[0], oc.predict(codes, circles[:1])[0], rtol=1e-9, atol=1e-9)
    assert np.array_equal(got[1], circles[1])


def test_missing_or_foreign_weights_are_one_line_errors(tmp_path):
    from relight.errors import ProbeError
    with pytest.raises(ProbeError, match="no outline check weights"):
        oc.load_check(str(tmp_path / "none.safetensors"))
    bad = tmp_path / "bad.safetensors"
    bad.write_bytes(b"not a safetensors file")
    with pytest.raises(ProbeError, match="not the outline check"):
        oc.load_check(str(bad))


@pytest.mark.skipif(not os.path.exists(oc.WEIGHTS), reason="no shipped outline check weights")
def test_shipped_check_brings_candidates_back_onto_the_sphere_in_fresh_renders():
    # rooms of the harder probe set with seeds no training or judging set uses, rendered here
    # by Mitsuba at 128 px and written as 8-bit; candidates a quarter of the radius off and a
    # quarter too large (a contact shadow's circle): the check's circle is within a tenth of
    # the radius of the truth (the edge fit's basin) on at least 5 of 6
    from relight import backend
    from relight.colour import srgb_decode
    from relight.imageio import to_srgb8
    from relight.probe import locator
    from relight.verify import probe_scenes as ps
    backend.init()
    hits = 0
    for seed in range(7000, 7006):
        d = ps.sample_room_scene(seed, res=128)
        linear = ps.render_room_mitsuba(d, spp=16)
        codes = to_srgb8(linear, detect.camera_exposure(linear, 0.02))
        seen = locator.codes(srgb_decode(codes.astype(np.float64) / 255.0), 1.0)
        tx, ty, tr = d["truth"]["chrome_circle"]
        angles = np.radians([30.0, 150.0, 270.0])
        cands = np.stack([tx + 0.25 * tr * np.cos(angles), ty + 0.25 * tr * np.sin(angles),
                          np.full(3, 1.25 * tr)], 1)
        got = oc.predict(seen, cands)
        hits += bool(np.all(np.hypot(got[:, 0] - tx, got[:, 1] - ty) <= 0.1 * tr)
                     and np.all(np.abs(np.log(got[:, 2] / tr)) <= 0.1))
    assert hits >= 5


def test_a_disputed_outline_states_half_the_two_outlines_distance():
    from relight.probe import geometry as pg
    cam = pg.Camera.from_fov(160, 120, 40.0)
    sphere = dataclasses.replace(detect.sphere_from_circle(cam, 80.0, 60.0, 15.0), outline_sigma_px=0.2)
    circle = detect.outline_circle(cam, sphere)
    seen = (circle[0] + 1.2, circle[1] - 1.6, circle[2] + 0.5)      # centres 2.0 px apart, radii 0.5
    cand = {"circle": circle, "check_gap": detect.CHECK_DISPUTE + 0.01, "check_circle": seen}
    got, apart = detect.disputed_outline(sphere, cand)
    assert apart == pytest.approx(2.5, abs=1e-9)
    assert got.outline_sigma_px == pytest.approx(math.hypot(0.2, 1.25), abs=1e-9)
    assert got.centre == sphere.centre and got.radius == sphere.radius
    # within the margin, with no opinion, or not asked: the outline as it was
    for c in ({**cand, "check_gap": detect.CHECK_DISPUTE}, {**cand, "check_gap": None}, {"circle": circle}):
        assert detect.disputed_outline(sphere, c) == (sphere, None)
    # an outline that stated no error of its own gets half the distance
    bare = dataclasses.replace(sphere, outline_sigma_px=None)
    assert detect.disputed_outline(bare, cand)[0].outline_sigma_px == pytest.approx(1.25, abs=1e-9)


def test_a_found_outline_the_check_disputes_widens_the_stated_uncertainty_not_the_direction(monkeypatch, tmp_path):
    from relight.imageio import write_png
    from relight.probe.run import ProbeConfig, qa_caption, run_probe
    from test_probe_hard import FOV_DEG
    cam, sphere, image = _scene()
    path = tmp_path / "mirror.png"
    write_png(path, image)
    truth = detect.outline_circle(cam, sphere)
    runs = {}
    for name, move in (("agrees", 0.0), ("disputes", 3.0)):
        # the check puts the sphere where the candidate is, or 3 px to the right of it
        monkeypatch.setattr(oc, "check_circles", lambda seen, circles, move=move: np.asarray(circles, float) + [move, 0, 0])
        runs[name] = run_probe(ProbeConfig(chrome=str(path), fov_deg=FOV_DEG)).entry
    agrees, disputes = runs["agrees"], runs["disputes"]
    assert math.dist(agrees["chrome_circle"][:2], truth[:2]) < 0.5          # the premise: the sphere is found
    assert "outline_disputed_px" not in agrees
    assert disputes["outline_disputed_px"] == pytest.approx(3.0, abs=0.01)
    # (the check's second start fits the outline again from its circle and lands where it was)
    assert math.degrees(math.acos(min(1.0, float(np.dot(disputes["to_light_camera"], agrees["to_light_camera"]))))) < 0.01
    assert disputes["quality"]["outline_sigma_px"] == pytest.approx(
        math.hypot(agrees["quality"]["outline_sigma_px"], 1.5), abs=2e-4)
    assert disputes["quality_deg"] > 2.0 * agrees["quality_deg"]
    assert any("disputed" in line for line in qa_caption(disputes))
    assert not any("disputed" in line for line in qa_caption(agrees))

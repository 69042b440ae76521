"""The sphere procedure on harder spheres: a given circle is respected (refined only
within its stated uncertainty, never to a worse fit), the highlight chosen among equally
bright blobs by what a small light predicts (ambiguity reported when two remain),
sub-pixel highlight localisation under an image shift, and the batch command (a folder
of photographs with circles from a CSV) with its one-line errors."""
import dataclasses
import json
import math
import os

import numpy as np
import pytest
from scipy import ndimage

from relight.cli import main
from relight.probe import detect, geometry as pg

from conftest import load_script

W, H, FOV_DEG = 160, 120, 40.0
SHIFT_PX = 0.5
SHIFT_TOL_PX = 0.1            # the issue: the estimate moves by at most 0.1 px more or less than the image
TOLERANCE_PX = 0.5            # the default stated uncertainty of a given circle
DIR_TOL_DEG = 1.5             # a 20 px sphere: one pixel of highlight error is ~6 deg at the rim


def _angle(a, b):
    from relight.metrics import angle_deg
    return float(angle_deg(a, b))


def _sphere_at(camera, x, y, angular_radius_deg, distance=5.0):
    _, d = camera.rays(np.array(x), np.array(y))
    return pg.Sphere(tuple((d * distance).tolist()), distance * math.sin(math.radians(angular_radius_deg)))


def _render(camera, sphere, to_light, shift=(0.0, 0.0), light_radius_deg=3.0, radiance=30.0, ss=4,
            extra=None, background=0.3, clip=True, blur_px=0.6):
    """A mirror sphere reflecting a disc light on a dim sky, supersampled, blurred by a
    lens (``blur_px``, a Gaussian's sigma), clipped at 1 (unless not ``clip``: linear HDR), with all content moved by ``shift`` pixels. ``extra(s)``
    adds radiance to reflected directions (other bright things)."""
    img = np.zeros((camera.height, camera.width))
    to_light = np.asarray(to_light, float) / np.linalg.norm(to_light)
    for i in range(ss):
        for j in range(ss):
            ys, xs = np.mgrid[0:camera.height, 0:camera.width] + (np.array([i, j])[:, None, None] + 0.5) / ss
            s = pg.surface(camera, sphere, xs - shift[0], ys - shift[1])
            lit = np.degrees(np.arccos(np.clip(s["reflect"] @ to_light, -1, 1))) < light_radius_deg
            value = np.where(lit, radiance, 0.08 + 0.04 * s["reflect"][..., 1])
            if extra is not None:
                value = value + extra(s)
            img += np.where(s["hit"], value, background)
    img = ndimage.gaussian_filter(img / ss ** 2, blur_px)
    return np.repeat((np.clip(img, 0.0, 1.0) if clip else img)[..., None], 3, -1)


def _quantise(img):
    """As an 8-bit sRGB file would hold it, decoded back to linear."""
    from relight.colour import srgb_decode, srgb_encode
    return srgb_decode(np.round(srgb_encode(img) * 255) / 255)


# ------------------------------------------------------------------ a given circle is respected
def test_exact_circle_stays_within_its_tolerance():
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 70.3, 62.6, 6.0)
    image = _quantise(_render(cam, sphere, [0.3, 0.4, 0.87]))
    circle = detect.outline_circle(cam, sphere)
    refined, report = detect.constrained_refinement(image, cam, circle, TOLERANCE_PX)
    moved = detect.outline_circle(cam, refined)
    assert math.dist(moved[:2], circle[:2]) <= TOLERANCE_PX + 1e-9
    assert abs(moved[2] - circle[2]) <= TOLERANCE_PX + 1e-9
    if report["accepted"]:
        assert report["fit_refined_px"] < report["fit_given_px"]


def test_wrong_circle_moves_at_most_its_tolerance_and_only_to_a_better_fit():
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 7.0)
    image = _quantise(_render(cam, sphere, [0.3, 0.4, 0.87]))
    cx, cy, r = detect.outline_circle(cam, sphere)
    given = (cx + 1.0, cy, r)                       # 1 px off: the edges pull it back by 0.5 px only
    refined, report = detect.constrained_refinement(image, cam, given, TOLERANCE_PX)
    out = detect.outline_circle(cam, refined)
    assert report["accepted"] and report["fit_refined_px"] < report["fit_given_px"]
    assert math.dist(out[:2], given[:2]) == pytest.approx(TOLERANCE_PX, abs=0.02)
    assert out[0] < given[0]                        # toward the truth
    # stated as 1 px uncertain, it goes all the way back (within a tenth of a pixel)
    refined, report = detect.constrained_refinement(image, cam, given, 1.0)
    assert report["accepted"] and math.dist(detect.outline_circle(cam, refined)[:2], (cx, cy)) < 0.1
    # tolerance 0: the circle exactly as given, through the library call
    from relight.probe.run import locate_sphere
    sphere0, _, how, rep = locate_sphere(image, cam, "chrome", given, tolerance_px=0.0)
    assert how == "circle" and detect.outline_circle(cam, sphere0) == pytest.approx(given, abs=1e-3)


def test_refinement_that_fits_worse_is_refused():
    # the outline fit is pulled by a bright disc touching the sphere; the given circle is exact
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 7.0)
    image = _render(cam, sphere, [0.3, 0.4, 0.87])
    cx, cy, r = detect.outline_circle(cam, sphere)
    ys, xs = np.mgrid[0:H, 0:W] + 0.5
    touching = (np.hypot(xs - (cx + r + 6), ys - cy) < 7) & ~pg.surface(cam, sphere, xs, ys)["hit"]
    image[touching] = 1.0
    image = _quantise(image)
    refined, report = detect.constrained_refinement(image, cam, (cx, cy, r), TOLERANCE_PX)
    out = detect.outline_circle(cam, refined)
    assert math.dist(out[:2], (cx, cy)) <= TOLERANCE_PX + 1e-9
    if report["accepted"]:
        assert report["fit_refined_px"] < report["fit_given_px"]


# ------------------------------------------------------------------ the right highlight
def _rim_glare(sphere_axis_deg=-90.0, width_deg=35.0):
    """A bright grazing reflection (a lit floor seen near the rim): reflected directions
    within ``width_deg`` of the image-plane direction ``sphere_axis_deg``, nearly
    perpendicular to the view (|z| < 0.25)."""
    a = math.radians(sphere_axis_deg)
    axis = np.array([math.cos(a), math.sin(a), 0.0])

    def extra(s):
        r = s["reflect"]
        ang = np.degrees(np.arccos(np.clip((r * [1, 1, 0]) @ axis / np.maximum(np.hypot(r[..., 0], r[..., 1]), 1e-9),
                                           -1, 1)))
        return np.where((ang < width_deg) & (np.abs(r[..., 2]) < 0.45) & (r[..., 2] < 0.0), 5.0, 0.0)
    return extra


def test_compact_highlight_wins_over_a_larger_clipped_rim_reflection():
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 8.0)
    to_light = np.array([0.35, 0.45, 0.82])
    image = _quantise(_render(cam, sphere, to_light, light_radius_deg=2.0, extra=_rim_glare()))
    found = pg.locate_highlight(image, cam, sphere, clip_level=1.0)
    assert found.quality["candidates"] >= 2              # the rim glare clips too
    assert _angle(found.to_light, to_light) < DIR_TOL_DEG


def test_two_equal_lights_are_reported_as_ambiguous_and_the_diffuse_sphere_decides():
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 8.0)
    a = np.array([0.4, 0.4, 0.82]) / np.linalg.norm([0.4, 0.4, 0.82])
    b = np.array([-0.4, 0.35, 0.85]) / np.linalg.norm([-0.4, 0.35, 0.85])

    def second_light(s):
        return np.where(np.degrees(np.arccos(np.clip(s["reflect"] @ b, -1, 1))) < 3.0, 30.0, 0.0)
    image = _quantise(_render(cam, sphere, a, extra=second_light))
    single = pg.locate_highlight(_quantise(_render(cam, sphere, a)), cam, sphere, clip_level=1.0)
    found = pg.locate_highlight(image, cam, sphere, clip_level=1.0)
    assert found.quality["ambiguity"] > 0.5
    assert found.quality["alternative_separation_deg"] == pytest.approx(_angle(a, b), abs=3.0)
    assert found.quality["uncertainty_deg"] > single.quality["uncertainty_deg"] + 0.3 * _angle(a, b)
    # a diffuse sphere's shading direction (a few degrees off) picks the one it agrees with
    for truth, other in ((a, b), (b, a)):
        hint = truth + 0.1 * other
        chosen = pg.locate_highlight(image, cam, sphere, clip_level=1.0, expect_to_light=hint / np.linalg.norm(hint))
        assert _angle(chosen.to_light, truth) < DIR_TOL_DEG


def test_linear_hdr_picks_the_brighter_blob():
    # in EXR the light outshines a lit wall's reflection; in 8-bit both clip
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 8.0)
    a = np.array([0.4, 0.4, 0.82]) / np.linalg.norm([0.4, 0.4, 0.82])
    b = np.array([-0.4, 0.35, 0.85]) / np.linalg.norm([-0.4, 0.35, 0.85])

    def wall(s):   # a bright patch as large as the light, 20x dimmer
        return np.where(np.degrees(np.arccos(np.clip(s["reflect"] @ b, -1, 1))) < 4.0, 1.5, 0.0)
    img = np.zeros((H, W))
    ss = 4
    for i in range(ss):
        for j in range(ss):
            ys, xs = np.mgrid[0:H, 0:W] + (np.array([i, j])[:, None, None] + 0.5) / ss
            s = pg.surface(cam, sphere, xs, ys)
            lit = np.degrees(np.arccos(np.clip(s["reflect"] @ a, -1, 1))) < 2.0
            img += np.where(s["hit"], np.where(lit, 30.0, 0.05) + wall(s), 0.2)
    hdr = np.repeat(ndimage.gaussian_filter(img / ss ** 2, 0.6)[..., None], 3, -1)
    found = pg.locate_highlight(hdr, cam, sphere)
    assert _angle(found.to_light, a) < DIR_TOL_DEG and found.quality["ambiguity"] == 0.0



def _lit_wall(centre, core_deg=3.5, core=30.0, halo_deg=12.0, halo=0.6):
    """A lit wall seen in the mirror: its brightest patch (``core_deg`` around ``centre``,
    clipping in 8-bit) inside a bright surround (``halo_deg``) that does not clip."""
    c = np.asarray(centre, float) / np.linalg.norm(centre)

    def extra(s):
        ang = np.degrees(np.arccos(np.clip(s["reflect"] @ c, -1, 1)))
        return np.where(ang < core_deg, core, np.where(ang < halo_deg, halo, 0.0))
    return extra


def test_a_clipped_patch_of_a_lit_wall_loses_to_the_light_standing_alone():
    # both clip and both are compact, round and away from the rim; the wall's patch is
    # even the larger, but it is the brightest part of a surface that continues around it
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 8.0)
    light = np.array([0.35, 0.45, 0.82]) / np.linalg.norm([0.35, 0.45, 0.82])
    wall = np.array([-0.4, 0.35, 0.85]) / np.linalg.norm([-0.4, 0.35, 0.85])
    image = _quantise(_render(cam, sphere, light, light_radius_deg=2.5, extra=_lit_wall(wall)))
    found = pg.locate_highlight(image, cam, sphere, clip_level=1.0)
    assert found.quality["candidates"] >= 2
    assert _angle(found.to_light, light) < DIR_TOL_DEG
    # the share of bright surroundings is what decides: the wall's patch alone is no rival
    alone = _quantise(_render(cam, sphere, light, light_radius_deg=2.5,
                              extra=_lit_wall(wall, halo=0.0)))
    tie = pg.locate_highlight(alone, cam, sphere, clip_level=1.0)
    assert tie.quality["ambiguity"] > found.quality["ambiguity"]


def _lit_object(centre, core_deg=2.5, halo_deg=6.0, halo=0.95):
    """A small lit object seen in the mirror (a lit ball): a patch that clips in 8-bit
    (``core_deg`` around ``centre``, 3 times the clip level), shading down over the pixels
    around it (``halo`` out to ``halo_deg``), dark beyond."""
    return _lit_wall(centre, core_deg=core_deg, core=3.0, halo_deg=halo_deg, halo=halo)


def test_a_lit_objects_clipped_patch_shading_down_loses_to_the_light_that_falls_off_at_once():
    # a sharp image (a pixel filter, no lens): both blobs clip, both are compact, round and
    # stand alone 2-3 px out; the object's patch shades down over the pixels touching it,
    # the light, far above the clip level, drops to the sky at once
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 8.0)
    light = np.array([0.35, 0.45, 0.82]) / np.linalg.norm([0.35, 0.45, 0.82])
    ball = np.array([-0.4, 0.35, 0.85]) / np.linalg.norm([-0.4, 0.35, 0.85])
    image = _quantise(_render(cam, sphere, light, light_radius_deg=2.0, extra=_lit_object(ball), blur_px=0.3))
    found = pg.locate_highlight(image, cam, sphere, clip_level=1.0)
    assert found.quality["candidates"] >= 2
    assert _angle(found.to_light, light) < DIR_TOL_DEG
    # the shading around the patch is what decides: the patch alone (nothing around it) is a tie
    bare = _quantise(_render(cam, sphere, light, light_radius_deg=2.0, extra=_lit_object(ball, halo=0.0),
                             blur_px=0.3))
    tie = pg.locate_highlight(bare, cam, sphere, clip_level=1.0)
    assert tie.quality["ambiguity"] > 0.9 and found.quality["ambiguity"] < tie.quality["ambiguity"] - 0.2


def test_a_patch_shading_down_less_than_the_level_loses_when_the_light_drops_at_once(monkeypatch):
    # team scene 22340 (130 deg off): the light sits on a lit wall's faint glow, which costs
    # it as not standing alone; a lit object's clipped patch shades down to about 0.6 of its
    # peak, under the level a lens's blur asks for (0.6: a blurred light stands at 0.7), so
    # nothing marked it. In a sharp image the light itself shows what the blur leaves
    # beside a clipped light (it drops at once): the patch stands well above that
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 8.0)
    light = np.array([0.35, 0.45, 0.82]) / np.linalg.norm([0.35, 0.45, 0.82])
    ball = np.array([-0.4, 0.35, 0.85]) / np.linalg.norm([-0.4, 0.35, 0.85])

    def extra(s):
        return _lit_object(ball, halo=0.8)(s) + _lit_wall(light, core_deg=0.0, halo_deg=14.0, halo=0.2)(s)
    image = _quantise(_render(cam, sphere, light, light_radius_deg=2.0, extra=extra, blur_px=0.3))
    found = pg.locate_highlight(image, cam, sphere, clip_level=1.0)
    assert found.quality["candidates"] >= 2
    assert _angle(found.to_light, light) < DIR_TOL_DEG
    monkeypatch.setattr(pg, "SHADING_DOWN_GAP", math.inf)     # the level alone: the patch wins
    assert _angle(pg.locate_highlight(image, cam, sphere, clip_level=1.0).to_light, light) > 30.0


def test_a_light_touching_a_lit_patch_at_a_corner_is_a_candidate_of_its_own(monkeypatch):
    # team28 scene 22906 (11 deg): the light's clipped pixels touched a lit wall's clipped
    # reflection at one corner; joined into one core by 8-connectivity, the two were
    # measured together and the light's centre moved onto the patch. 4-connected, the
    # light is a candidate of its own, and it drops at once where the patch shades down
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 10.0)
    light = np.array([0.3, 0.4, 0.87]) / np.linalg.norm([0.3, 0.4, 0.87])
    spot, _ = pg.predict_highlight(cam, sphere, light)
    image = _quantise(_render(cam, sphere, light, light_radius_deg=0.01))   # the sphere, no highlight
    sx, sy = int(spot[0]), int(spot[1])
    for dx, dy in ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)):               # the light: a clipped plus
        image[sy + dy, sx + dx] = 1.0
    yy, xx = np.mgrid[0:H, 0:W]
    patch = (xx >= sx + 1) & (xx <= sx + 5) & (yy >= sy + 2) & (yy <= sy + 4)   # its corner at the plus's arm
    around = (xx >= sx) & (xx <= sx + 6) & (yy >= sy + 2) & (yy <= sy + 6) & ~patch & ~((xx <= sx) & (yy <= sy + 2))
    image[around] = 0.75                                                        # shading down around the patch
    image[patch] = 1.0
    found = pg.locate_highlight(image, cam, sphere, clip_level=1.0)
    assert found.quality["candidates"] == 2
    assert math.dist(found.pixel, (sx + 0.5, sy + 0.5)) < 0.5
    monkeypatch.setattr(pg, "CORE_STRUCTURE", np.ones((3, 3), bool))          # 8-connected: one core, pulled
    assert math.dist(pg.locate_highlight(image, cam, sphere, clip_level=1.0).pixel, (sx + 0.5, sy + 0.5)) > 1.0


def test_a_light_beside_a_lit_objects_clipped_patch_is_not_scored_for_the_patch():
    # a lit object's clipped patch 12 deg from the light (2-3 px in the image): the patch is in
    # the light's surroundings, but it is a candidate of its own, judged on its own
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 8.0)
    light = np.array([0.35, 0.45, 0.82]) / np.linalg.norm([0.35, 0.45, 0.82])
    side = np.cross(light, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    patch = light * math.cos(math.radians(12.0)) + side * math.sin(math.radians(12.0))
    image = _quantise(_render(cam, sphere, light, light_radius_deg=2.0,
                              extra=_lit_object(patch, core_deg=2.0, halo_deg=5.0), blur_px=0.3))
    found = pg.locate_highlight(image, cam, sphere, clip_level=1.0)
    assert found.quality["candidates"] >= 2
    assert _angle(found.to_light, light) < DIR_TOL_DEG


def _bright_light_by_the_rim(rho, toward_deg, wall=False):
    """A light 100 times the clip level, ``rho`` of the radius from the centre toward
    ``toward_deg`` in the image, under a 1 px lens blur, in 8-bit; with ``wall``, what lies
    right behind the sphere on that side clips too. Returns the camera, sphere, image, the
    truth's pixel and the outward unit vector."""
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 8.0)
    cx, cy, r = detect.outline_circle(cam, sphere)
    out = np.array([math.cos(math.radians(toward_deg)), math.sin(math.radians(toward_deg))])
    to_light = pg.reflected_direction(cam, sphere, cx + rho * r * out[0], cy + rho * r * out[1])
    image = _render(cam, sphere, to_light, light_radius_deg=1.0, radiance=3000.0, blur_px=1.0)
    if wall:
        ys, xs = np.mgrid[0:H, 0:W] + 0.5
        image[~pg.surface(cam, sphere, xs, ys)["hit"] & ((xs - cx) * out[0] + (ys - cy) * out[1] > 0.5 * r)] = 1.0
    return cam, sphere, _quantise(image), pg.predict_highlight(cam, sphere, to_light)[0], out


@pytest.mark.parametrize("rho", [0.9, 0.95])
@pytest.mark.parametrize("toward_deg", [-90.0, 30.0])
def test_a_bright_blurred_light_by_the_rim_is_centred_on_its_whole_clipped_disc(rho, toward_deg):
    # the light clips over a disc of about 3 px radius, which crosses the outline near the
    # rim: the part past it is the light's too (the blur spreads it there as much as
    # inward); cut there, the centre moved inward by 0.6-1.2 px (5-12 deg)
    cam, sphere, image, truth_px, _ = _bright_light_by_the_rim(rho, toward_deg)
    found = pg.locate_highlight(image, cam, sphere, clip_level=1.0)
    assert found.quality["clipped"] and found.quality["highlight_pixels"] > 12
    assert math.dist(found.pixel, truth_px) < 0.5


@pytest.mark.parametrize("rho", [0.9, 0.95])
@pytest.mark.parametrize("toward_deg", [-90.0, 30.0])
def test_a_clipped_wall_behind_the_rim_does_not_pull_a_highlight_by_the_rim(rho, toward_deg):
    # as above, but what lies right behind the sphere on that side clips too (a lit wall):
    # the light's clipped disc runs into it past the outline, and those pixels are not the
    # light; taken as its own, they pulled it 1.3-9.7 px outward. The disc's inner part
    # alone leaves the inward bias above (at most a pixel), never an outward pull
    cam, sphere, image, truth_px, out = _bright_light_by_the_rim(rho, toward_deg, wall=True)
    found = pg.locate_highlight(image, cam, sphere, clip_level=1.0)
    outward = float((np.asarray(found.pixel) - truth_px) @ out)
    assert outward < 0.25 and math.dist(found.pixel, truth_px) < 1.0


def test_a_bright_surface_touching_a_small_highlight_does_not_pull_it():
    # a lit floor's reflection runs just below the light's clipped highlight, one darker
    # row between them (one of its pixels clips too): the highlight's position comes from
    # the light's own pixels
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 6.0)
    light = np.array([0.3, 0.35, 0.88]) / np.linalg.norm([0.3, 0.35, 0.88])
    spot, _ = pg.predict_highlight(cam, sphere, light)
    clean = _quantise(_render(cam, sphere, light, light_radius_deg=2.0))
    image = clean.copy()
    x, y = int(spot[0]), int(spot[1])
    image[y + 3, x - 3:x + 4] = 0.85          # the floor's reflection: a bright streak 3 px below
    image[y + 3, x + 3] = 1.0                 # clipping at one end
    ref = pg.locate_highlight(clean, cam, sphere, clip_level=1.0)
    found = pg.locate_highlight(image, cam, sphere, clip_level=1.0)
    assert math.dist(found.pixel, ref.pixel) < 0.15
    assert _angle(found.to_light, light) < DIR_TOL_DEG


def _streak(x, y, offset_px, width_px=0.8, peak=0.94):
    """A lit edge's reflection: a bright line running diagonally (down and to the right)
    past pixel ``(x, y)``, its crest ``offset_px`` up and to the right of it."""
    yy, xx = np.mgrid[0:H, 0:W] + 0.5
    d = (xx - x) * 0.7071 - (yy - y) * 0.7071 - offset_px
    along = np.abs((xx - x) * 0.7071 + (yy - y) * 0.7071)
    return np.where(along < 6.0, peak * np.exp(-0.5 * (d / width_px) ** 2), 0.0)


def _streak_scene():
    """A ~30 px mirror sphere and its light: camera, sphere, direction, highlight pixel."""
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 9.0)
    light = np.array([0.3, 0.35, 0.88]) / np.linalg.norm([0.3, 0.35, 0.88])
    return cam, sphere, light, pg.predict_highlight(cam, sphere, light)[0]


@pytest.mark.parametrize("offset_px", [2.0, 2.6])
def test_a_bright_streak_touching_a_box_filtered_clipped_highlight_does_not_pull_it(offset_px):
    # a render's box filter, a light far above the clip level: the light's pixels are those
    # its image touches, all clipped, and nothing around them is blurred. A lit edge's
    # reflection runs diagonally past them, its crest touching them (2.0) or its flank only
    # (2.6); a descent from the clipped core ran onto it (a Cycles scene: 4.0 deg, against 0.9
    # for the clipped pixels' centroid; here 0.5 and 0.3 px)
    cam, sphere, light, spot = _streak_scene()
    alone = _render(cam, sphere, light, light_radius_deg=0.01)[..., 0]     # the sphere alone
    x, y = int(spot[0]), int(spot[1])

    def located(image):
        image = image.copy()
        image[y, x:x + 2] = 1.0               # the light's three clipped pixels, an L
        image[y + 1, x + 1] = 1.0
        return pg.locate_highlight(_quantise(np.repeat(image[..., None], 3, -1)), cam, sphere, clip_level=1.0)

    found = located(np.maximum(alone, _streak(x + 0.5, y + 0.5, offset_px)))
    ref = located(alone)
    assert found.quality["clipped"]
    assert math.dist(found.pixel, ref.pixel) < 0.05
    # and the light is where its pixels put it: within the L's box, nearer the L's
    # corner pixel than the missing fourth one
    assert x + 0.5 < found.pixel[0] < x + 1.5 and y + 0.5 < found.pixel[1] < y + 1.5
    assert found.pixel[0] - (x + 1.0) > found.pixel[1] - (y + 1.0)


@pytest.mark.parametrize("offset_px", [2.0, 2.8])
def test_a_bright_streak_touching_a_lens_blurred_clipped_highlight_does_not_pull_it(offset_px):
    # a photograph: the lens blurs the clipped highlight into a halo on every side, which
    # still counts; a streak beside it has no counterpart on the far side of the light
    # and does not (0.4-0.6 px before, crest touching; 0.16 px, flank only)
    cam, sphere, light, spot = _streak_scene()
    clean = _quantise(_render(cam, sphere, light, light_radius_deg=0.8, radiance=200.0))
    streak = _streak(*spot, offset_px + 0.8, width_px=0.6, peak=0.93)
    image = np.maximum(clean, np.repeat(streak[..., None], 3, -1))
    ref = pg.locate_highlight(clean, cam, sphere, clip_level=1.0)
    found = pg.locate_highlight(image, cam, sphere, clip_level=1.0)
    assert found.quality["clipped"]
    assert math.dist(found.pixel, ref.pixel) < 0.05
    assert _angle(found.to_light, light) < DIR_TOL_DEG


def _behind_the_sphere(inside_px):
    """An 18 px sphere and a light behind it whose highlight lies ``inside_px`` inside the
    outline along (0.3, -1) from the centre. Returns the camera, sphere, the highlight's
    pixel, the sphere's render without the light (linear, one channel) and the outline's
    distance from the centre along that line."""
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 5.0)
    cx, cy = cam.project(sphere.c)
    rim = next(d for d in np.arange(0.0, 30.0, 0.01)
               if not pg.surface(cam, sphere, np.array([cx + 0.3 * d]), np.array([cy - d]))["hit"][0])
    d = rim - inside_px
    light = pg.surface(cam, sphere, np.array([cx + 0.3 * d]), np.array([cy - d]))["reflect"][0]
    spot, _ = pg.predict_highlight(cam, sphere, light)
    return cam, sphere, spot, _render(cam, sphere, light, radiance=0.0, clip=False)[..., 0], rim


@pytest.mark.parametrize("inside_px, clip", [(1.4, True), (1.0, False), (1.4, False)])
def test_a_highlight_by_the_rim_keeps_its_pixels_in_the_rim_band(inside_px, clip):
    # a light behind the sphere: its highlight 1-1.4 px inside the outline, where the search
    # leaves out the rim band (pixels within 1 px of the outline mix with what lies beyond);
    # the light's core continues there, and without those pixels the highlight moved inward
    # by 0.3-0.56 px (5-10 degrees on this 18 px sphere)
    cam, sphere, spot, img, _ = _behind_the_sphere(inside_px)
    img = img + _blob(*spot, 0.5, (8.0 if clip else 2.0) * 2 * math.pi * 0.25)   # clipped: 8x the clip level
    img = np.repeat(img[..., None], 3, -1)
    found = pg.locate_highlight(_quantise(np.clip(img, 0, 1)) if clip else img, cam, sphere,
                                clip_level=1.0 if clip else None)
    assert math.dist(found.pixel, spot) < 0.25


def _light_in_the_rim_band(inside_px, clip, bleed=False):
    """A light behind an 18 px sphere whose highlight lies ``inside_px`` inside the
    outline, all of it in the rim band the search leaves out (as when the outline is found
    a pixel small), and a dim reflection in the interior (a third of the clip level). With
    ``bleed`` what lies right behind the sphere on that side is as bright as the light (a
    lit wall). Returns the camera, sphere, image, the light's pixel and the dim blob's."""
    cam, sphere, spot, img, rim = _behind_the_sphere(inside_px)
    cx, cy = cam.project(sphere.c)
    peak = 8.0 if clip else 50.0                 # clipped: 8x the clip level; linear: far above the scene
    img = img + _blob(*spot, 0.25, peak * 2 * math.pi * 0.0625)
    dim = np.floor([cx - 3.0, cy + 2.0]) + 0.5
    img = img + _blob(*dim, 0.4, 0.5 * 2 * math.pi * 0.16)
    if bleed:
        yy, xx = np.mgrid[0:H, 0:W] + 0.5
        beyond = ~pg.surface(cam, sphere, xx, yy)["hit"]
        img[beyond & ((xx - cx) * 0.29 - (yy - cy) * 0.96 > 0.5 * rim)] = peak
    img = np.repeat(img[..., None], 3, -1)
    return cam, sphere, _quantise(np.clip(img, 0, 1)) if clip else img, spot, dim


@pytest.mark.parametrize("inside_px", [0.3, 0.5])
@pytest.mark.parametrize("clip", [True, False])
def test_a_light_wholly_in_the_rim_band_is_found_there(inside_px, clip):
    # held-out scenes 22835 and 23007: a light behind the sphere, its clipped highlight a
    # pixel or two inside the true outline, and the outline found 0.6-0.7 px small at the
    # top; the whole highlight then lay in the rim band, and a dim reflection inside won
    # (107 and 48 deg off)
    # (the dim reflection lies 22 px away; by the rim, where only the band's part of the
    # light is seen, its centre may lie inward by up to 0.6 px)
    cam, sphere, image, spot, _ = _light_in_the_rim_band(inside_px, clip)
    found = pg.locate_highlight(image, cam, sphere, clip_level=1.0 if clip else None)
    assert math.dist(found.pixel, spot) < 0.75


@pytest.mark.parametrize("clip", [True, False])
def test_a_bright_thing_beyond_the_outline_bleeding_into_the_rim_band_is_not_the_light(clip):
    # the same rim-band blob continuing past the outline at its own brightness: it may be
    # the light or a wall seen right behind the sphere, not a highlight on it; the search
    # stays inside the rim band and finds the dim reflection there
    cam, sphere, image, spot, dim = _light_in_the_rim_band(0.3, clip, bleed=True)
    found = pg.locate_highlight(image, cam, sphere, clip_level=1.0 if clip else None)
    assert math.dist(found.pixel, dim) < 0.5


def test_a_light_beside_clipped_surroundings_is_still_located():
    # the light's small clipped core sits beside a clipped arc (a lamp's shade, a bright
    # window frame) joined to it by bright pixels: the level around the core is the clip
    # level itself, so nothing stands above it; the core's own pixels place the light
    # (this raised "no highlight on the chrome sphere" before)
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 10.0)
    light = np.array([0.3, 0.4, 0.87]) / np.linalg.norm([0.3, 0.4, 0.87])
    spot, _ = pg.predict_highlight(cam, sphere, light)
    image = _quantise(_render(cam, sphere, light, light_radius_deg=0.01))   # the sphere, no highlight
    yy, xx = np.mgrid[0:H, 0:W] + 0.5
    dist = np.hypot(xx - spot[0], yy - spot[1])
    image[dist < 4.5] = 0.6                                  # bright surroundings joining the two
    image[(dist >= 4.5) & (dist < 6.5) & (xx > spot[0])] = 1.0   # the clipped arc, on one side
    image[dist < 1.1] = 1.0                                  # the light's core: the pixels at the spot
    found = pg.locate_highlight(image, cam, sphere, clip_level=1.0)
    assert math.dist(found.pixel, spot) < 0.5
    assert _angle(found.to_light, light) < 3.0


def _light_on_a_lit_wall_and_a_spot(spot_value):
    """The light clipping on a lit wall's bright reflection (which costs it as "not
    standing alone") and a lone spot of ``spot_value`` elsewhere on the sphere, with dim
    neighbours, which wins on looks alone. Returns ``(camera, sphere, light, spot's
    direction, image)``."""
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 10.0)
    light = np.array([0.3, 0.4, 0.87]) / np.linalg.norm([0.3, 0.4, 0.87])
    image = _quantise(_render(cam, sphere, light, light_radius_deg=2.5,
                              extra=_lit_wall(light, core_deg=0.0, halo_deg=14.0, halo=0.9)))
    other = np.array([-0.35, -0.3, 0.89]) / np.linalg.norm([-0.35, -0.3, 0.89])
    spot, _ = pg.predict_highlight(cam, sphere, other)
    image[int(spot[1]), int(spot[0])] = spot_value
    return cam, sphere, light, other, image


def test_in_an_image_that_clips_a_blob_that_does_not_is_not_the_light():
    # the light clips (a small light is hundreds of times brighter than what it lights); a
    # lone spot at 98.5% of the clip level ties with it by brightness (TIE_FRACTION) and
    # would win on looks alone. It is known to be dimmer than the clipped light: in an
    # image that clips it takes a strike, and the light wins; read as linear (no clip
    # level) the same pixels choose the spot (the strike is what decides)
    cam, sphere, light, other, image = _light_on_a_lit_wall_and_a_spot(0.985)
    clipped = pg.locate_highlight(image, cam, sphere, clip_level=1.0)
    assert clipped.quality["candidates"] >= 2
    assert _angle(clipped.to_light, light) < DIR_TOL_DEG
    linear = pg.locate_highlight(image, cam, sphere)
    assert _angle(linear.to_light, other) < 5.0


@pytest.mark.parametrize("fireflies", [0, 1, 2, 6])
def test_a_lone_clipped_pixel_loses_to_the_light_where_the_image_shows_fireflies(fireflies):
    # lone clipped pixels on the background (dim all round, well away from the sphere)
    # show that the image carries fireflies or hot pixels: from FIREFLY_MIN of them on, the
    # sphere's lone clipped pixel takes a strike and the light's larger clipped core wins;
    # with fewer (a Cycles render, a photo) the image says nothing of the kind and the
    # same pixels choose the lone one as before (a lone clipped pixel can be a small
    # light's whole highlight)
    # (the spot clipped: a path tracer's firefly)
    cam, sphere, light, other, image = _light_on_a_lit_wall_and_a_spot(1.0)
    x0, y0, x1, y1 = pg.bounding_box(cam, sphere)
    spots = [(6, 8), (150, 10), (12, 110), (140, 100), (30, 60), (130, 64)][:fireflies]
    for x, y in spots:
        assert not (x0 - 3 <= x <= x1 + 3 and y0 - 3 <= y <= y1 + 3)
        image[y, x] = 1.0
    lum = pg._luminance(image)
    assert pg.lone_clipped_pixels(lum, pg.CLIPS_AT, (x0 - 2, y0 - 2, x1 + 2, y1 + 2)) == fireflies
    found = pg.locate_highlight(image, cam, sphere, clip_level=1.0)
    assert found.quality["candidates"] >= 2
    assert found.quality["lone_clipped_pixels"] == fireflies
    if fireflies >= pg.FIREFLY_MIN:
        assert _angle(found.to_light, light) < DIR_TOL_DEG
    else:
        assert _angle(found.to_light, other) < 5.0


def test_lone_clipped_pixels_are_counted_by_size_and_surroundings():
    lum = np.full((40, 60), 0.2)
    lum[5, 5] = 1.0                          # lone
    lum[10, 20:22] = 1.0                     # two pixels: lone
    lum[30, 40:43] = 1.0                     # three: a clipped patch, not lone
    lum[20, 50] = 1.0                        # clipped, but in a bright surround
    lum[19:22, 49:52][lum[19:22, 49:52] < 1.0] = 0.8
    lum[35, 5] = 0.99                        # below the clip level
    assert pg.lone_clipped_pixels(lum, pg.CLIPS_AT) == 2
    assert pg.lone_clipped_pixels(lum, pg.CLIPS_AT, (0, 0, 10, 10)) == 1   # the box is left out


@pytest.mark.parametrize("normal_deg", [15.0, 45.0, 70.0])
def test_the_error_budgets_circle_term_is_what_moving_the_circle_does(normal_deg):
    # the budget's circle term against finite differences: the highlight's pixel fixed and
    # the circle moved by a small distance in every direction, the rms change of the light
    # direction. Near the rim a move across the outline's radius tilts the normal by
    # 1 / cos(theta) times one along it; the budget once stretched every move by
    # 1 / cos(theta / 2) and stated a third of the error at 70 deg
    cam = pg.Camera.from_fov(W, H, 5.0)
    sphere = _sphere_at(cam, 80.0, 60.0, 0.5)
    cx, cy, r = detect.outline_circle(cam, sphere)
    out = np.array([0.6, -0.8])
    px, py = np.array([cx, cy]) + out * r * math.sin(math.radians(normal_deg))
    s0 = pg.surface(cam, sphere, np.array([px]), np.array([py]))
    view_deg = math.degrees(math.acos(float(s0["cos_view"][0])))
    step = 0.02
    moved = [_angle(pg.reflected_direction(cam, sphere, px - step * math.cos(a), py - step * math.sin(a)),
                    s0["reflect"][0]) for a in np.linspace(0.0, 2 * math.pi, 16, endpoint=False)]
    rms = math.sqrt(np.mean(np.square(moved)))
    q = {"highlight_pixels": 1, "view_angle_deg": view_deg, "highlight_spread_deg": 0.0}
    budget = pg.error_budget(cam, sphere, q, circle_px=step)
    assert budget["circle_deg"] == pytest.approx(rms, rel=0.1)


def _arc_biased_fits(cam, circle, phi, rms, draws, rng):
    """Centre errors (px) of circles fitted to outline points at angles ``phi`` around
    ``circle``, each moved radially by noise of ``rms`` and a bias shared along arcs (a
    Gaussian process: RIM_BIAS_PX, correlated over RIM_BIAS_ARC_DEG), ``draws`` times."""
    cx, cy, r = circle
    gap = np.angle(np.exp(1j * (phi[:, None] - phi[None, :])))
    k = detect.RIM_BIAS_PX ** 2 * np.exp(-0.5 * (gap / math.radians(detect.RIM_BIAS_ARC_DEG)) ** 2)
    w, v = np.linalg.eigh(k)
    root = v * np.sqrt(np.clip(w, 0.0, None))
    errors = []
    for _ in range(draws):
        move = root @ rng.standard_normal(phi.size) + rms * rng.standard_normal(phi.size)
        fit = pg.fit_sphere(cam, cx + (r + move) * np.cos(phi), cy + (r + move) * np.sin(phi), robust=False)
        fx, fy, _ = pg.outline_circle(cam, fit)
        errors.append(math.hypot(fx - cx, fy - cy))
    return np.array(errors)


@pytest.mark.parametrize("missing_deg", [0.0, 120.0])
def test_an_outline_centres_stated_error_is_what_arc_biases_do_to_the_fit(missing_deg):
    # outline_centre_sigma_px propagates the points' noise and their arcs' shared biases
    # through the circle fit; against a Monte-Carlo of exactly that model (biases drawn,
    # circles fitted) it must state the rms centre error within 12% (400 draws: the rms's
    # own scatter is about 4%), on a whole outline and on one whose bottom third shows no
    # edge (a mirror's rim at the floor it stands on), where the top arc's bias moves the
    # centre whole and the error must be larger by a quarter at least (it is by a third)
    cam = pg.Camera(128, 128)
    circle = (64.0, 64.0, 20.0)
    rms = 0.1
    sphere = dataclasses.replace(pg.sphere_from_circle(cam, *circle), outline_rms_px=rms)

    def stated(phi):
        return detect.outline_centre_sigma_px(cam, sphere, circle[0] + circle[2] * np.cos(phi),
                                              circle[1] + circle[2] * np.sin(phi))
    whole = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    # (image y points down: the bottom of the outline is at +90 deg)
    phi = whole[np.abs(np.angle(np.exp(1j * (whole - math.pi / 2)))) > math.radians(missing_deg / 2)]
    errors = _arc_biased_fits(cam, circle, phi, rms, 400, np.random.default_rng(7))
    assert stated(phi) == pytest.approx(math.sqrt(np.mean(errors ** 2)), rel=0.12)
    if missing_deg:
        assert stated(phi) > 1.25 * stated(whole)


def test_an_outline_without_the_rim_fits_error_states_it_from_its_edges():
    # detect.with_centre_error: an outline the rim fit left as it was gets its centre's
    # error from the rim's edge points around it. On a sphere whose rim stands out all
    # round it is what the whole outline's points give (within 15%); with the lower half's
    # background as bright as the rim mirrors there (0.1: its edge falls under the weak
    # edges' cut, and the lower half keeps no point) it is larger by half at least (twice
    # as large here; 0.09-0.12 alike); one that already states it keeps it
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = dataclasses.replace(_sphere_at(cam, 80.0, 60.0, 5.0), outline_rms_px=0.05)
    cx, cy, r = pg.outline_circle(cam, sphere)
    ys = np.mgrid[0:H, 0:W][0] + 0.5
    lit = [0.3, 0.4, 0.87]
    whole = detect.with_centre_error(_quantise(_render(cam, sphere, lit)), cam, sphere).outline_sigma_px
    t = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    assert whole == pytest.approx(detect.outline_centre_sigma_px(cam, sphere, cx + r * np.cos(t), cy + r * np.sin(t)),
                                  rel=0.15)
    image = _render(cam, sphere, lit)
    on = pg.surface(cam, sphere, *np.mgrid[0:H, 0:W][::-1] + 0.5)["hit"]
    dark = np.where(((ys > cy) & ~on)[..., None], 0.1, image)
    half = detect.with_centre_error(_quantise(dark), cam, sphere).outline_sigma_px
    assert half > 1.5 * whole
    stated = dataclasses.replace(sphere, outline_sigma_px=0.7)
    assert detect.with_centre_error(_quantise(image), cam, stated).outline_sigma_px == 0.7


def test_a_found_chrome_outline_states_its_centres_error_in_the_budget():
    # the budget's circle term for an outline found in the image is 0.05 px plus the
    # centre's stated error (outline_sigma_px, kept through the rim's outward shift), and
    # the old rms rule only for an outline without it (a mask's)
    cam = pg.Camera.from_fov(W, H, 5.0)
    sphere = _sphere_at(cam, 80.0, 60.0, 0.5)
    q = {"highlight_pixels": 1, "view_angle_deg": 40.0, "highlight_spread_deg": 0.0}
    plain = dataclasses.replace(sphere, outline_rms_px=0.2, outline_points=320)
    found = dataclasses.replace(plain, outline_sigma_px=0.3)
    step = pg.error_budget(cam, plain, q, circle_px=1.0)["circle_deg"]    # degrees per pixel
    assert pg.error_budget(cam, plain, q)["circle_deg"] == pytest.approx(step * (0.05 + 0.2 / math.sqrt(40.0)))
    assert pg.error_budget(cam, found, q)["circle_deg"] == pytest.approx(step * 0.35)
    assert detect.outline_from_rim(cam, found, 0.2).outline_sigma_px == 0.3


# ------------------------------------------------------------------ sub-pixel localisation
def _blob(x0, y0, sigma, amplitude):
    """A lens-blurred point highlight: a Gaussian of ``sigma`` px at ``(x0, y0)``,
    integrated exactly over each pixel (no aliasing, unlike point sampling a tiny disc)."""
    from scipy.special import erf

    def axis(n, c):
        edges = np.arange(n + 1, dtype=float)
        cdf = 0.5 * (1 + erf((edges - c) / (math.sqrt(2) * sigma)))
        return np.diff(cdf)
    return amplitude * np.outer(axis(H, y0), axis(W, x0))


@pytest.mark.parametrize("phase", [0.0, 0.25, 0.4])
@pytest.mark.parametrize("clip", [False, True])
def test_highlight_moves_with_a_half_pixel_image_shift(phase, clip):
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 6.0)          # a ~20 px sphere
    to_light = np.array([0.3, 0.35, 0.88]) / np.linalg.norm([0.3, 0.35, 0.88])
    spot, _ = pg.predict_highlight(cam, sphere, to_light)
    pixels = []
    for dx in (phase, phase + SHIFT_PX):
        shift = np.array([dx, 0.3 * dx])
        img = _render(cam, sphere, to_light, shift=shift, radiance=0.0, clip=False)[..., 0]
        # a clipped highlight: 8 times the clip level at its peak (a plateau of a few pixels)
        img = img + _blob(*(spot + shift), 0.7, (8.0 if clip else 2.0) * 2 * math.pi * 0.49)
        img = np.repeat(img[..., None], 3, -1)
        img = _quantise(np.clip(img, 0, 1)) if clip else img
        moved = _sphere_at(cam, *(np.asarray(cam.project(sphere.c)) + shift), 6.0)
        found = pg.locate_highlight(img, cam, moved, clip_level=1.0 if clip else None)
        assert found.quality["clipped"] == clip
        pixels.append(np.asarray(found.pixel))
    step = pixels[1] - pixels[0]
    assert abs(step[0] - SHIFT_PX) <= SHIFT_TOL_PX
    assert abs(step[1] - 0.3 * SHIFT_PX) <= SHIFT_TOL_PX


# ------------------------------------------------------------------ a folder with circles from a CSV
def _run(args):
    try:
        return main(args)
    except SystemExit as exc:
        return int(exc.code)


@pytest.fixture
def photo_folder(tmp_path):
    """Three 8-bit photographs of a mirror sphere under known lights, and their circles."""
    from relight.imageio import write_png
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    folder = tmp_path / "photos"
    folder.mkdir()
    lights, rows = {}, ["image,chrome_cx,chrome_cy,chrome_r"]
    for k, (where, light) in enumerate((((70.0, 60.0), (0.3, 0.4, 0.87)), ((90.0, 55.0), (-0.4, 0.2, 0.9)),
                                        ((80.0, 66.0), (0.1, -0.3, 0.95)))):
        sphere = _sphere_at(cam, *where, 9.0)
        light = np.asarray(light) / np.linalg.norm(light)
        write_png(folder / f"img{k}.png", _render(cam, sphere, light))
        lights[f"img{k}"] = light
        rows.append(f"img{k}.png," + ",".join(f"{v:.3f}" for v in detect.outline_circle(cam, sphere)))
    csv_path = tmp_path / "circles.csv"
    csv_path.write_text("\n".join(rows) + "\n")
    return folder, csv_path, lights


def test_batch_measures_every_listed_photo(photo_folder, tmp_path):
    folder, csv_path, lights = photo_folder
    out, qa = tmp_path / "pred.json", tmp_path / "qa"
    assert _run(["probe", "--folder", str(folder), "--circles", str(csv_path), "--fov", str(FOV_DEG),
                 "--out", str(out), "--qa", str(qa)]) == 0
    entries = json.loads(out.read_text())["predictions"]
    assert [e["id"] for e in entries] == ["img0", "img1", "img2"]
    for e in entries:
        assert e["chrome_found_by"].startswith("circle")
        assert _angle(e["to_light_camera"], lights[e["id"]]) < DIR_TOL_DEG
    assert sorted(os.listdir(qa)) == ["img0.png", "img1.png", "img2.png"]


def test_batch_bad_rows_give_one_line_naming_the_row_and_write_nothing(photo_folder, tmp_path, capsys):
    import cv2
    folder, csv_path, _ = photo_folder
    cv2.imwrite(str(folder / "black.png"), np.zeros((H, W, 3), np.uint8))
    good = csv_path.read_text().splitlines()
    cases = {
        "not a number": good + ["img0.png,70,60,abc"],
        "missing image": good + ["nothere.png,70,60,20"],
        "partial circle": good + ["img1.png,70,,20"],
        "unknown column": ["image,chrome_x,chrome_cy,chrome_r"] + good[1:],
        "duplicate id": good + [good[1]],
        "no highlight": good + ["black.png,80,60,20"],       # fails while measuring, after the others
        "extra field": good + ["img0.png,70,60,20,5"],
    }
    out, qa = tmp_path / "pred.json", tmp_path / "qa"
    for name, lines in cases.items():
        bad = tmp_path / "bad.csv"
        bad.write_text("\n".join(lines) + "\n")
        code = _run(["probe", "--folder", str(folder), "--circles", str(bad), "--fov", str(FOV_DEG),
                     "--out", str(out), "--qa", str(qa)])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and err[0].startswith("relight: error:"), (name, err)
        assert f"row {len(lines)}" in err[0] or name == "unknown column", (name, err)
        assert not out.exists() and not qa.exists(), name
    # the QA folder may not replace the photographs' folder; single-image options do not mix in
    for args in (["--qa", str(folder)], ["--chrome", str(folder / "img0.png")]):
        assert _run(["probe", "--folder", str(folder), "--circles", str(csv_path), "--out", str(out), *args]) == 2
        assert len(capsys.readouterr().err.strip().splitlines()) == 1
        assert not out.exists() and sorted(os.listdir(folder)) == ["black.png", "img0.png", "img1.png", "img2.png"]


def test_the_consensus_circle_is_the_median_of_the_largest_agreeing_group():
    from relight.errors import ProbeError
    from relight.probe.batch import AGREE_FRACTION, consensus_circle
    near = [(100.0, 80.0, 40.0), (100.6, 79.8, 40.4), (99.7, 80.3, 39.5), (101.0, 80.0, 40.2)]
    far = [(60.0, 50.0, 12.0), (100.0, 80.0, 40.0 * (1 + 2 * AGREE_FRACTION)), None]
    circle, agree = consensus_circle(near + far, images=7)
    assert agree == 4
    assert circle == pytest.approx((100.3, 80.0, 40.1))     # each coordinate's median over the group
    with pytest.raises(ProbeError) as err:                  # 4 of 8 is not more than half
        consensus_circle(near + far + [None], images=8)
    assert "\n" not in str(err.value) and "4 agree" in str(err.value)


def _wedge_room(s):
    """What a mirror reflects (added to :func:`_render`'s dim sky): a room of five bright
    and five dark wedges around the view axis, whose edges run radially from the sphere's
    centre in its image."""
    rf = s["reflect"]
    return np.where(np.sin(5.0 * np.arctan2(rf[..., 1], rf[..., 0])) > 0, 0.2, 0.0)


@pytest.mark.parametrize("light", [(0.1, -0.3, 0.95), (-0.1, 0.5, 0.86), (0.5, 0.1, 0.86)])
def test_a_mirror_whose_reflections_run_radially_is_proposed(light):
    # OpenCV's classic Hough gives each centre the radius with the most edge pixels per unit
    # of radius; a mirror's wedges put as many at every radius, so over the whole range the
    # sphere's centre went to a small circle (for these three lights no proposal lay near the
    # sphere, and a 9-15 px circle was picked); the classic one over each octave of radii
    # proposes it, and it is found
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 9.0)
    cx, cy, r = detect.outline_circle(cam, sphere)
    image = _quantise(_render(cam, sphere, np.asarray(light) / np.linalg.norm(light), extra=_wedge_room))
    assert any(math.dist(c[:2], (cx, cy)) < 0.05 * r and abs(c[2] - r) < 0.05 * r
               for c in detect.hough_circles(image, 1.0))
    chrome = detect.pick_sphere(detect.find_spheres(image, cam, clip_level=1.0), "chrome")
    assert math.dist(chrome["circle"][:2], (cx, cy)) < 0.5 and abs(chrome["circle"][2] - r) < 0.5


def _fixed_probe_folder(tmp_path):
    """Five 8-bit photographs of one mirror sphere standing still in a room of bright and
    dark wedges (:func:`_wedge_room`), under five lights; in the fifth it mirrors a black
    room on a black background (only its highlight shows: no outline to find). Returns
    ``(folder, csv with no circles, lights, true circle)``."""
    from relight.imageio import write_png
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 9.0)
    folder = tmp_path / "capture"
    folder.mkdir()

    def black(s):
        return -(0.08 + 0.04 * s["reflect"][..., 1])    # (less _render's dim sky)
    lights = {}
    for k, light in enumerate(((0.3, 0.4, 0.87), (-0.4, 0.2, 0.9), (-0.2, -0.3, 0.93), (0.5, 0.1, 0.86),
                               (0.2, 0.3, 0.93))):
        light = np.asarray(light) / np.linalg.norm(light)
        dark = k == 4
        write_png(folder / f"img{k}.png", _render(cam, sphere, light, extra=black if dark else _wedge_room,
                                                 background=0.0 if dark else 0.3))
        lights[f"img{k}"] = light
    csv_path = tmp_path / "capture.csv"
    csv_path.write_text("image\n" + "".join(f"img{k}.png\n" for k in range(5)))
    return folder, csv_path, lights, detect.outline_circle(cam, sphere)


def test_a_fixed_probe_gives_every_image_the_circle_the_detections_agree_on(tmp_path, capsys):
    # found image by image, the fifth image's sphere is not found (the batch stops there,
    # writing nothing); with --fixed-probe the other four agree, and the circle they agree
    # on measures all five
    from relight.probe.run import qa_caption
    folder, csv_path, lights, (cx, cy, r) = _fixed_probe_folder(tmp_path)
    out = tmp_path / "pred.json"
    base = ["probe", "--folder", str(folder), "--circles", str(csv_path), "--fov", str(FOV_DEG), "--out", str(out)]
    assert _run(base) == 2 and "row 6" in capsys.readouterr().err and not out.exists()     # the premise
    assert _run(base + ["--fixed-probe", "--qa", str(tmp_path / "qa")]) == 0
    entries = json.loads(out.read_text())["predictions"]
    assert sorted(p.name for p in (tmp_path / "qa").iterdir()) == [f"img{k}.png" for k in range(5)]
    assert [e["id"] for e in entries] == [f"img{k}" for k in range(5)]
    shared = entries[0]["chrome_circle_shared"]
    assert (shared["agreeing"], shared["found"], shared["images"]) == (4, 4, 5)
    assert math.dist(shared["circle"][:2], (cx, cy)) < 0.5 and abs(shared["circle"][2] - r) < 0.5
    for e in entries:
        assert e["chrome_found_by"].startswith("circle") and e["chrome_circle_shared"] == shared
        assert _angle(e["to_light_camera"], lights[e["id"]]) < DIR_TOL_DEG
        # the overlay's caption says whose circle it is (not just "as given")
        assert "the batch's fixed probe" in qa_caption(e)[-1] and "4 agreeing" in qa_caption(e)[-1]
    assert not any("fixed probe" in line for line in qa_caption({k: v for k, v in entries[0].items()
                                                                  if k != "chrome_circle_shared"}))
    # one image, or too few agreeing: one line, exit 2, nothing written
    out.unlink()
    assert _run(["probe", "--chrome", str(folder / "img0.png"), "--fixed-probe", "--out", str(out)]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    (tmp_path / "two.csv").write_text("image\nimg0.png\nimg4.png\n")
    assert _run(base[:4] + [str(tmp_path / "two.csv")] + base[5:] + ["--fixed-probe"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--fixed-probe" in err[0] and not out.exists()


# ------------------------------------------------------------------ the harder probe set's truth
def test_specular_point_bisects_eye_and_light():
    from relight.verify.probe_scenes import specular_point
    c, eye, light = np.array([0.3, -0.2, 0.1]), np.array([5.0, 1.0, 2.0]), np.array([-1.0, 2.0, 3.0])
    p = specular_point(c, 0.1, eye, light)
    n = (p - c) / 0.1
    to_eye, to_light = (eye - p) / np.linalg.norm(eye - p), (light - p) / np.linalg.norm(light - p)
    assert np.linalg.norm(p - c) == pytest.approx(0.1, rel=1e-12)
    assert np.linalg.norm(n - (to_eye + to_light) / np.linalg.norm(to_eye + to_light)) < 1e-9


def test_probe_scene_render_puts_the_highlight_where_the_truth_says():
    # a 128 px scene of the harder set, rendered by Mitsuba: the highlight's centroid in
    # linear radiance, reflected on the true sphere, points along the stated truth
    from relight import backend
    from relight.verify import probe_scenes as ps
    backend.init()
    d = ps.sample_room_scene(0, res=128)
    t = d["truth"]
    image = ps.render_room_mitsuba(d, spp=16).mean(-1)
    cam = pg.Camera.from_fov(128, 128, t["fov_deg"])
    sphere = ps.room_sphere(d, "chrome")
    spot, _ = pg.predict_highlight(cam, sphere, t["to_light_camera"])
    x, y = int(spot[0]), int(spot[1])
    win = image[y - 3:y + 4, x - 3:x + 4]
    win = np.where(win > 20 * np.median(image), win, 0.0)    # the light's reflection only
    ys, xs = np.mgrid[y - 3:y + 4, x - 3:x + 4] + 0.5
    centre = (float((win * xs).sum() / win.sum()), float((win * ys).sum() / win.sum()))
    assert math.dist(centre, spot) < 0.5
    assert t["chrome_circle"] == pytest.approx(list(detect.outline_circle(cam, sphere)), abs=1e-6)


def test_a_room_scene_can_be_drawn_as_the_teams_cycles_renders():
    # 256 px, FOV 30, chrome radius 15-20 px: every draw has them (the outline circle of
    # an off-axis sphere is up to 1/cos(21 deg) = 7% wider than its on-axis radius), and
    # the radius still varies within the range; without them a seed's scene is unchanged
    from relight.verify import probe_scenes as ps
    radii, fovs = [], []
    for seed in range(6):
        t = ps.sample_room_scene(seed, 256, 30.0, (15.0, 20.0))["truth"]
        assert t["res"] == 256 and t["fov_deg"] == 30.0
        assert 15.0 <= t["chrome_circle"][2] <= 20.0 * 1.07
        radii.append(t["chrome_circle"][2])
        plain = ps.sample_room_scene(seed)
        assert plain == ps.sample_room_scene(seed, None, None, None)
        fovs.append(plain["truth"]["fov_deg"])
    assert max(radii) - min(radii) > 1.0 and max(fovs) - min(fovs) > 5.0
    with pytest.raises(ValueError):
        ps.sample_room_scene(0, 256, 30.0, (20.0, 15.0))
    with pytest.raises(ValueError):    # more than ROOM_MAX_RADIUS_SHARE of a 128 px side
        ps.sample_room_scene(0, 128, 30.0, (15.0, 20.0))


# ------------------------------------------------------------------ small spheres found
def test_chrome_outline_grows_past_a_reflection_circle_inside_it():
    # a mirror sphere on a background about as bright as its rim (a faint outline) shows a
    # bright reflection whose edge is a strong circle at ~0.78 of its radius; a fit started
    # there locks onto it, and the outermost-outline search finds the sphere's own
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 8.0)
    to_light = np.array([0.3, 0.4, 0.87])

    def window(s):    # what is reflected within ~100 deg of the view ray back: bright, in wedges
        r = s["reflect"]
        wedges = np.sin(5.0 * np.arctan2(r[..., 1], r[..., 0])) > -0.3
        return np.where((r[..., 2] > -0.2) & wedges, 0.5, 0.0)
    image = _render(cam, sphere, to_light, extra=window, background=0.3, clip=False)
    cx, cy, r = detect.outline_circle(cam, sphere)
    _assert_grows_to_the_outline(image, cam, (cx, cy, r), start=0.78, locks_below=0.9)


def test_chrome_outline_grows_through_nested_reflection_bands():
    # near its rim a mirror sphere compresses what surrounds it into concentric bands (the
    # image radius goes as the sine of half the reflection angle): here bright / dark / bright
    # / dark bands end at 0.72, 0.81 and 0.90 of the radius, 11-12% apart, the last one dark
    # against a dim background (scene 29 of the issue-29 set: a dark rim). A fit started on
    # the innermost circle must step outward band by band: 20% and 40% steps land between
    # bands (the growth stopped at 0.82 of the radius); the 10% step tried then reaches the outline
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 58.0, 8.0)
    cx, cy, r = detect.outline_circle(cam, sphere)

    def bands(s):
        rf = s["reflect"]
        rho = np.sqrt(np.clip((1.0 - rf[..., 2]) / 2.0, 0.0, 1.0))    # image radius / outline radius
        stripes = np.sin(6.0 * np.arctan2(rf[..., 1], rf[..., 0])) > 0   # (no smooth shading fits it)
        value = np.where(rho < 0.72, np.where(stripes, 0.25, 0.02), 0.02)
        value = np.where((rho > 0.81) & (rho <= 0.9), 0.2, value)
        return value - 0.08 - 0.04 * rf[..., 1]       # in place of _render's dim sky
    image = _quantise(_render(cam, sphere, np.array([0.3, 0.4, 0.87]), extra=bands, background=0.15))
    _assert_grows_to_the_outline(image, cam, (cx, cy, r), start=0.72, locks_below=0.8)


def _assert_grows_to_the_outline(image, cam, circle, start, locks_below):
    """A fit started at ``start`` of the true circle's radius locks onto an inner circle
    (below ``locks_below`` of it); the outline growth from there ends on the true outline
    (within 0.5 px) and still chrome."""
    cx, cy, r = circle
    smoothed = detect._edge_image(image)
    inner, support = detect.refine_sphere(image, cam, pg.sphere_from_circle(cam, cx, cy, start * r), smoothed,
                                          first_band_px=2.0)
    inner_circle = detect.outline_circle(cam, inner)
    assert inner_circle[2] < locks_below * r             # the fit does lock onto the inner circle
    f = detect.sphere_features(image, cam, inner)
    cand = {"sphere": inner, "circle": inner_circle, "edge_support": support, **f, "chrome": True, "diffuse": False}
    grown = detect._outermost_outline(image, cam, cand, smoothed)
    assert abs(grown["circle"][2] - r) < 0.5
    assert math.dist(grown["circle"][:2], (cx, cy)) < 0.5
    assert grown["chrome"]


def _mirror_over(background):
    """The test chrome sphere over a linear ``background(xs, ys, (cx, cy, r))`` (pixel-centre
    grids and the sphere's true circle -> values), blurred like the sphere, as an 8-bit image:
    returns ``(image, cam, (cx, cy, r))``."""
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 62.0, 5.0)
    circle = detect.outline_circle(cam, sphere)
    to_light = np.array([0.3, 0.4, 0.87])
    # linear in the background: the sphere over any background is i0 + background (i1 - i0)
    i0 = _render(cam, sphere, to_light, background=0.0, clip=False)
    i1 = _render(cam, sphere, to_light, background=1.0, clip=False)
    ys, xs = np.mgrid[0:H, 0:W] + 0.5
    back = ndimage.gaussian_filter(background(xs, ys, circle), 0.6)[..., None]
    return _quantise(np.clip(i0 + back * (i1 - i0), 0.0, 1.0)), cam, circle


def _mirror_on_a_plate(plate_scale: float):
    """A chrome sphere (true circle ``(cx, cy, r)``) on a dark plate of broken outline (floor
    dots), ``plate_scale`` times its radius and 3 px higher, as an 8-bit image: returns
    ``(image, cam, (cx, cy, r), plate)``."""
    def plate_of(circle):
        return (circle[0], circle[1] - 3.0, plate_scale * circle[2])

    def background(xs, ys, circle):
        px, py, pr = plate_of(circle)
        dots = np.sin(6.0 * np.arctan2(ys - py, xs - px)) > 0.5
        return np.where((np.hypot(xs - px, ys - py) < pr) & dots, 0.05, 0.35)
    image, cam, circle = _mirror_over(background)
    return image, cam, circle, plate_of(circle)


_RIM_FIT_ON_A_PLATE = """
import json, sys
sys.path.insert(0, sys.argv[1])
import test_probe_hard as T
from relight.probe import detect
image, cam, true, plate = T._mirror_on_a_plate(1.2)
view, _ = detect.detection_view(image, 1.0)
smoothed = detect._edge_image(view)
guess = detect._screen(smoothed, cam, plate[0], plate[1], 0.85 * plate[2])[1]
refined, _ = detect.refine_sphere(view, cam, guess, smoothed, first_band_px=3.0)
print(json.dumps({"fit": detect.outline_circle(cam, detect.outer_rim_fit(smoothed, cam, refined)),
                  "true": list(true)}))
"""


def _cpu_flags() -> set:
    try:
        with open("/proc/cpuinfo") as f:
            return next((set(line.split(":", 1)[1].split()) for line in f if line.startswith("flags")), set())
    except OSError:
        return set()


@pytest.mark.skipif("avx" not in _cpu_flags(), reason="needs an x86-64 CPU with AVX (OpenBLAS's Sandybridge kernel)")
def test_the_outermost_rim_fit_does_not_depend_on_the_blas_kernel():
    # a mirror on a dark dotted plate 1.2 times its radius, 3 px higher (the plate's rim 0.8 px
    # below the sphere's): edge points sit on the search's quarter-pixel steps, and whether one
    # exactly on the outline counted as outside was decided by the last bits of a projection,
    # which numpy's OpenBLAS kernel sets. Two kernels any x86-64 CPU with AVX runs must agree,
    # and keep the sphere (with the Prescott kernel the fit once moved 1.1 px onto the plate)
    import subprocess
    import sys
    here = os.path.dirname(os.path.abspath(__file__))
    fits = []
    for kernel in ("Prescott", "Sandybridge"):
        env = dict(os.environ, OPENBLAS_CORETYPE=kernel,
                   PYTHONPATH=os.pathsep.join(p for p in (os.path.dirname(here), os.environ.get("PYTHONPATH")) if p))
        done = subprocess.run([sys.executable, "-c", _RIM_FIT_ON_A_PLATE, here], env=env, capture_output=True,
                              text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-2000:]
        fits.append(json.loads(done.stdout.strip().splitlines()[-1]))
    (a, b) = fits
    assert np.allclose(a["fit"], b["fit"], atol=1e-4)
    assert math.dist(a["fit"][:2], a["true"][:2]) < 0.5 and abs(a["fit"][2] - a["true"][2]) < 0.5


def test_every_radius_that_passes_the_screen_is_refined(monkeypatch):
    # a chrome sphere on a dark plate of broken outline (floor dots), 1.3 times its radius and
    # 3 px higher: the one proposal is the plate's circle. The screen keeps the proposal's
    # centre, so the sphere's radius (0.85 of it) screens worse than the plate's own; refined,
    # it lands on the sphere, which is better supported than the plate.
    # (the plate's rim 2.75 px below the sphere's: with 1.2 times the radius, 0.8 px below it,
    # the outermost-rim fit's choice is the next test's)
    image, cam, (cx, cy, r), plate = _mirror_on_a_plate(1.3)
    # the premise: at the proposal's centre the plate's radius screens better than the sphere's
    smoothed = detect._edge_image(detect.detection_view(image, 1.0)[0])
    assert detect._screen(smoothed, cam, *plate)[0] > detect._screen(smoothed, cam, plate[0], plate[1],
                                                                     0.85 * plate[2])[0]
    monkeypatch.setattr(detect, "hough_circles", lambda img, *args: [plate])
    chrome = detect.pick_sphere(detect.find_spheres(image, cam, clip_level=1.0), "chrome")   # an 8-bit image
    assert math.dist(chrome["circle"][:2], (cx, cy)) < 0.5
    assert abs(chrome["circle"][2] - r) < 0.5


def _mirror_with_an_arc_by_a_dark_rim(arc_deg):
    """A 79 px chrome sphere whose lower half lies on a background as dark as its rim
    mirrors there (no outline edge), with a bright reflection band at 0.80-0.90 of its
    radius, 25 deg either side of ``arc_deg`` (image angle, y up): psm_spheres' chrome.10
    (the ball beside a dark hill, a window's arc inside its rim). Returns
    ``(8-bit image, cam, true circle)``."""
    cam = pg.Camera.from_fov(200, 200, 40.0)
    sphere = _sphere_at(cam, 100.0, 100.0, 16.0)
    circle = detect.outline_circle(cam, sphere)

    def arc(s):
        rf = s["reflect"]
        rho = np.sqrt(np.clip((1.0 - rf[..., 2]) / 2.0, 0.0, 1.0))    # image radius / outline radius
        off = (np.degrees(np.arctan2(-rf[..., 1], rf[..., 0])) - arc_deg + 180.0) % 360.0 - 180.0
        return np.where((rho > 0.8) & (rho < 0.9) & (np.abs(off) < 25.0), 0.5, 0.0)
    to_light = np.array([0.3, 0.4, 0.87])
    i0 = _render(cam, sphere, to_light, extra=arc, background=0.0, clip=False)
    i1 = _render(cam, sphere, to_light, extra=arc, background=1.0, clip=False)
    ys = np.mgrid[0:200, 0:200][0] + 0.5
    back = ndimage.gaussian_filter(np.where(ys > circle[1], 0.085, 0.35), 0.6)[..., None]
    return _quantise(np.clip(i0 + back * (i1 - i0), 0.0, 1.0)), cam, circle


@pytest.mark.parametrize("arc_deg", [190.0, 200.0])
def test_a_refinement_that_leaves_the_proposal_less_supported_is_tried_again_on_a_narrow_band(monkeypatch, arc_deg):
    # the proposal is the true circle; refined on the wide band (12% of the radius) the fit
    # takes the reflection band's outer edge, 8 px inside, for the dark lower-left rim and
    # ends 3 px off, less supported than the proposal was; refined again from it on a narrow
    # band it stays, and that is the sphere found
    image, cam, (cx, cy, r) = _mirror_with_an_arc_by_a_dark_rim(arc_deg)
    view = detect.detection_view(image, 1.0)[0]
    smoothed = detect._edge_image(view)
    proposal = pg.sphere_from_circle(cam, cx, cy, r)
    wide, support = detect.refine_sphere(view, cam, proposal, smoothed, first_band_px=0.12 * r)
    assert math.dist(detect.outline_circle(cam, wide)[:2], (cx, cy)) > 2.0      # the premise
    assert support < detect.support_at(smoothed, cam, proposal)
    monkeypatch.setattr(detect, "hough_circles", lambda img, *args: [(cx, cy, r)])
    chrome = detect.pick_sphere(detect.find_spheres(image, cam, clip_level=1.0), "chrome")
    assert math.dist(chrome["circle"][:2], (cx, cy)) < 0.5
    assert abs(chrome["circle"][2] - r) < 0.5


def test_a_small_sphere_with_a_highlight_is_proposed_when_the_proposals_overflow(monkeypatch):
    # strong-edged diffuse discs win the Hough votes; a faint small disc with one bright
    # pixel (a chrome sphere's highlight) still gets one of the last places
    ys, xs = np.mgrid[0:H, 0:W] + 0.5
    img = np.full((H, W), 0.2)
    discs = [(30, 30, 14), (75, 30, 14), (120, 30, 14), (30, 85, 14), (120, 85, 14)]
    for cx, cy, r in discs:
        img[np.hypot(xs - cx, ys - cy) < r] = 0.7
    small = (75.5, 85.5, 9.0)
    img[np.hypot(xs - small[0], ys - small[1]) < small[2]] = 0.26
    img[83, 73] = 1.0
    image = np.repeat(ndimage.gaussian_filter(img, 0.5)[..., None], 3, -1)

    def found(spots):
        monkeypatch.setattr(detect, "MAX_CANDIDATES", len(discs))
        monkeypatch.setattr(detect, "SPOT_PROPOSALS", spots)
        return any(math.dist(c[:2], small[:2]) < 3 for c in detect.hough_circles(image))
    assert found(1)
    assert not found(0)      # on votes alone it is crowded out


def test_the_hough_proposers_take_turns(monkeypatch):
    # the classic proposer's many weak circles must not queue the fine one's best behind them
    import cv2
    lists = [[(20.0, 20.0, 10.0)], [(40.0 + 20 * k, 60.0, 9.0) for k in range(5)], [(130.0, 90.0, 8.0)]]
    calls = iter(lists)     # (the classic one over octaves of radii, called after them, finds none)
    monkeypatch.setattr(cv2, "HoughCircles",
                        lambda *a, **k: (lambda c: None if c is None else np.asarray([c], np.float32))(next(calls, None)))
    monkeypatch.setattr(detect, "MAX_CANDIDATES", 3)
    monkeypatch.setattr(detect, "SPOT_PROPOSALS", 0)
    got = detect.hough_circles(np.full((H, W, 3), 0.3))
    assert [c[:2] for c in got] == [(20.5, 20.5), (40.5, 60.5), (130.5, 90.5)]


def _lit_floor(strength=2.0):
    """A broad bright reflection (a lit floor below the sphere, clipping in 8-bit):
    reflected directions pointing down and away from the camera's axis."""
    def extra(s):
        r = s["reflect"]
        return np.where((r[..., 1] < -0.35) & (r[..., 2] < 0.6), strength, 0.0)
    return extra


def test_a_chrome_sphere_mirroring_a_clipped_lit_floor_is_still_chrome():
    # in 8-bit the lit floor's reflection clips as the highlight does and covers far more of
    # the sphere than a highlight would: the chrome test looks at the brightest spot's own region
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 8.0)
    image = _quantise(_render(cam, sphere, np.array([0.3, 0.4, 0.87]), light_radius_deg=2.0, extra=_lit_floor()))
    f = detect.sphere_features(image, cam, sphere)
    clipped = int((image[..., 0] >= 1.0).sum())
    assert f["blob_pixels"] < 0.25 * clipped           # the highlight's own region, not the floor's
    assert f["blob_fraction"] <= detect.CHROME_MAX_BLOB_FRACTION
    assert detect.is_chrome(f)


def test_an_inner_reflection_disc_does_not_hide_the_chrome_sphere_around_it():
    # scene-like figures: a uniform inner disc (diffuse-looking, better supported) and the
    # chrome outline around it at 1.4 times its radius; a second chrome circle there, less
    # supported, goes, while a better supported one replaces the first
    disc = {"circle": (100.0, 100.0, 17.5), "edge_support": 0.48, "chrome": False}
    sphere = {"circle": (103.0, 107.0, 24.3), "edge_support": 0.44, "chrome": True}
    out = detect._merge_candidate(detect._merge_candidate([], disc), sphere)
    assert any(c is sphere for c in out) and any(c is disc for c in out)
    weaker = dict(sphere, edge_support=0.40, circle=(104.0, 107.0, 24.0))
    assert not any(c is weaker for c in detect._merge_candidate(out, weaker))
    stronger = dict(sphere, edge_support=0.5)
    merged = detect._merge_candidate(out, stronger)
    assert any(c is stronger for c in merged) and not any(c is sphere for c in merged)


# ------------------------------------------------------------------ edge smoothing from the image's noise
def _shaded_disc(n=64, noise=0.0, seed=0):
    """A shaded disc (radius 0.3 n) on a linear gradient, exposed space (values 0.1-0.6),
    plus white noise of std ``noise``."""
    ys, xs = np.mgrid[0:n, 0:n] + 0.5
    d = np.hypot(xs - 0.52 * n, ys - 0.47 * n)
    base = np.where(d < 0.3 * n, 0.5 - 0.3 * (d / (0.3 * n)) ** 2, 0.1 + 0.2 * xs / n)
    rgb = np.stack([base, 0.8 * base, 0.6 * base], -1)
    return rgb + noise * np.random.default_rng(seed).standard_normal(rgb.shape)


@pytest.mark.parametrize("noise", [0.002, 0.02])
def test_image_noise_recovers_white_noise_on_shading_and_edges(noise):
    # shading (locally linear or quadratic) and a disc's outline barely register: the
    # estimate is the added noise's standard deviation within 10%
    assert detect.image_noise(_shaded_disc(noise=noise)) == pytest.approx(noise, rel=0.1)
    assert detect.image_noise(_shaded_disc()) < 0.1 * 0.002


def test_edge_smoothing_follows_the_image_noise():
    # a clean image is smoothed by the least (half a pixel), a noisy one by the most, and
    # in between by what leaves EDGE_NOISE_LEFT: s / (2 sqrt(pi) sigma)
    assert detect.edge_sigma_px(_shaded_disc()) == detect.EDGE_SIGMA_PX == 0.5
    assert detect.edge_sigma_px(_shaded_disc(noise=0.02)) == detect.EDGE_SIGMA_MAX_PX
    mid = 0.0021
    want = mid / (2.0 * math.sqrt(math.pi) * detect.EDGE_NOISE_LEFT)
    assert detect.EDGE_SIGMA_PX < want < detect.EDGE_SIGMA_MAX_PX
    assert detect.edge_sigma_px(_shaded_disc(noise=mid)) == pytest.approx(want, rel=0.1)
    # and the edge image of a clean render is smoothed by it (the previous fixed 0.7 px
    # merged a mirror's rim with its inner reflections more than a clean render needs)
    clean = np.clip(_shaded_disc(), 0.0, 1.0)
    lin = np.clip(clean * detect._exposure(clean), 0.0, 1.0)
    np.testing.assert_allclose(detect._edge_image(clean), ndimage.gaussian_filter(lin, (0.5, 0.5, 0)), atol=1e-12)


# ------------------------------------------------------------------ a chrome rim hidden below
def _rim_hidden_below(half_angle_deg, depth_px, n=64, cx=31.6, cy=29.3, r=12.4, ss=8):
    """A dark mirror disc on a brighter background whose lower rim (within
    ``half_angle_deg`` of straight down) mirrors that background: there the rim has no
    edge, and the strongest edge near it is the reflection's inner boundary, ``depth_px``
    inside (a sphere standing on a floor and its contact shadow)."""
    ys, xs = (np.mgrid[0:n * ss, 0:n * ss] + 0.5) / ss
    d = np.hypot(xs - cx, ys - cy)
    down = np.abs(np.degrees(np.arctan2(ys - cy, xs - cx)) - 90.0) < half_angle_deg
    v = np.where(d < r, 0.1, 0.4)
    v = np.where((d < r) & (d > r - depth_px) & down, 0.4, v)
    g = v.reshape(n, ss, n, ss).mean((1, 3))
    return np.stack([g, 0.9 * g, 0.8 * g], -1), (cx, cy, r)


@pytest.mark.parametrize("half_angle_deg, depth_px", [(45.0, 1.5), (45.0, 2.0), (60.0, 1.5), (60.0, 2.0), (0.0, 0.0)])
def test_chrome_outline_follows_the_outermost_edges(half_angle_deg, depth_px):
    # a symmetric robust fit is pulled in and up by the inner edge below (0.2-1.1 px off);
    # the outer-rim fit of a chrome outline leaves the inner points out and recovers the
    # circle within 0.15 px, and on a plain disc (no hidden rim) it stays within 0.05 px
    n = 64
    image, circle = _rim_hidden_below(half_angle_deg, depth_px, n)
    cam = pg.Camera.from_fov(n, n, 30.0)
    true = detect.outline_circle(cam, pg.sphere_from_circle(cam, *circle))
    smoothed = detect._edge_image(image)
    fitted, _ = detect.refine_sphere(image, cam, pg.sphere_from_circle(cam, *circle), smoothed)
    before = detect.outline_circle(cam, fitted)
    outer = detect.outline_circle(cam, detect.outer_rim_fit(smoothed, cam, fitted))
    if depth_px:
        assert math.dist(before[:2], true[:2]) > 0.2           # the problem
        assert math.dist(outer[:2], true[:2]) < 0.15 and abs(outer[2] - true[2]) < 0.15
    else:
        assert math.dist(outer[:2], true[:2]) < 0.05 and abs(outer[2] - true[2]) < 0.05


@pytest.mark.parametrize("half_angle_deg, depth_px", [(45.0, 1.5), (60.0, 1.5), (60.0, 2.0), (0.0, 0.0)])
def test_the_outer_rim_fit_ends_where_it_settles_wherever_it_starts(half_angle_deg, depth_px):
    # one pass ends part of the way from an outline pulled in and up (0.07-0.17 px from
    # where a pass started at the true circle ends); repeated until it settles, both
    # starts end at the same outline
    n = 64
    image, circle = _rim_hidden_below(half_angle_deg, depth_px, n)
    cam = pg.Camera.from_fov(n, n, 30.0)
    smoothed = detect._edge_image(image)
    true = pg.sphere_from_circle(cam, *circle)
    pulled, _ = detect.refine_sphere(image, cam, true, smoothed)
    a, b = (detect.outline_circle(cam, detect.outer_rim_fit(smoothed, cam, s)) for s in (pulled, true))
    assert math.dist(a[:2], b[:2]) < 0.02 and abs(a[2] - b[2]) < 0.02


@pytest.mark.parametrize("half_angle_deg, depth_px", [(45.0, 1.5), (60.0, 2.0)])
@pytest.mark.parametrize("off", [(0.3, -0.3, 0.2), (-0.35, 0.2, -0.25)])
def test_a_given_chrome_circle_is_refined_as_a_found_outline_is(half_angle_deg, depth_px, off):
    # a circle given 0.4-0.5 px off (tolerance 0.5 px) on a mirror whose lower rim shows no
    # edge: refined as the detection fits a chrome outline (outer_rim_fit) it comes back
    # within 0.15 px of the truth; the symmetric robust fit it had been refined by is
    # pulled in and up by the inner edge below, more than 0.2 px off
    n = 64
    image, circle = _rim_hidden_below(half_angle_deg, depth_px, n)
    cam = pg.Camera.from_fov(n, n, 30.0)
    true = detect.outline_circle(cam, pg.sphere_from_circle(cam, *circle))
    given = (true[0] + off[0], true[1] + off[1], true[2] + off[2])
    refined, report = detect.constrained_refinement(image, cam, given, TOLERANCE_PX, rim_shift_px=0.0, chrome=True)
    out = detect.outline_circle(cam, refined)
    assert report["accepted"]
    assert math.dist(out[:2], true[:2]) < 0.15 and abs(out[2] - true[2]) < 0.15
    symmetric, _ = detect.refine_sphere(image, cam, pg.sphere_from_circle(cam, *given), detect._edge_image(image))
    assert math.dist(detect.outline_circle(cam, symmetric)[:2], true[:2]) > 0.2


@pytest.mark.parametrize("cx, cy, r", [(40.37, 33.81, 12.3), (51.2, 40.55, 17.71), (45.5, 38.5, 9.9)])
def test_a_final_outlines_edge_points_lie_on_the_edge_not_on_the_pixel_lattice(cx, cy, r):
    # a disc whose outline is known to the sub-pixel (box-filtered, blurred by half a
    # pixel, 8-bit): a final fit's edge points (peak) scatter about it by 0.06-0.07 px rms,
    # at most 0.2 px. Read where the weighted choice fell in a linear interpolation (the
    # search's points) they sat on the lattice's half steps: 0.10-0.14 px rms, 0.36 px at most
    ss, w, h = 8, 96, 80
    ys, xs = (np.mgrid[0:h * ss, 0:w * ss] + 0.5) / ss
    disc = (np.hypot(xs - cx, ys - cy) < r).reshape(h, ss, w, ss).mean((1, 3))
    image = _quantise(np.repeat(ndimage.gaussian_filter(0.15 + 0.5 * disc, 0.5)[..., None], 3, -1))
    cam = pg.Camera(w, h, None)
    smoothed = detect._edge_image(image)
    spread = {}
    for peak in (False, True):
        x, y, _ = detect.edge_points(smoothed, cam, pg.sphere_from_circle(cam, cx, cy, r), 1.5, peak=peak)
        d = np.hypot(x - cx, y - cy) - r
        assert len(d) == detect.EDGE_ANGLES
        spread[peak] = (math.sqrt(np.mean((d - np.median(d)) ** 2)), np.abs(d).max())
    assert spread[True][0] < 0.085 < spread[False][0]
    assert spread[True][1] < 0.25 < spread[False][1]


def test_a_mirror_rim_shift_follows_the_edge_blur():
    # closed form: CHROME_RIM_SHIFT blur widths, the blur being the edge smoothing and the
    # pixel's own box (1/sqrt(12) px) in quadrature; a clean image gets the least smoothing
    disc, _ = _rim_hidden_below(0.0, 0.0)
    assert detect.edge_blur_px(disc) == pytest.approx(math.hypot(detect.EDGE_SIGMA_PX, math.sqrt(1 / 12)), rel=1e-9)
    assert detect.chrome_rim_shift_px(disc) == pytest.approx(detect.CHROME_RIM_SHIFT * detect.edge_blur_px(disc))
    noisy = np.clip(disc + np.random.default_rng(3).normal(0.0, 0.01, disc.shape), 0.0, 1.0)
    assert detect.chrome_rim_shift_px(noisy) > detect.chrome_rim_shift_px(disc)


@pytest.mark.parametrize("fov", [None, 45.0])
def test_an_outline_from_its_rim_grows_by_the_shift_about_the_same_centre(fov):
    cam = pg.Camera.from_fov(128, 96, fov) if fov else pg.Camera(128, 96, None)
    sphere = pg.sphere_from_circle(cam, 30.4, 70.2, 14.3)
    before = detect.outline_circle(cam, sphere)
    after = detect.outline_circle(cam, detect.outline_from_rim(cam, sphere, 0.25))
    assert after[2] - before[2] == pytest.approx(0.25, abs=0.01)
    assert math.dist(after[:2], before[:2]) < 0.01
    assert detect.outline_from_rim(cam, sphere, 0.0) is sphere


def test_mirror_outlines_fitted_to_their_rims_edges_come_out_the_right_size_in_fresh_renders():
    # twelve rooms of the harder probe set (seeds no tuning or judging set uses) rendered
    # here by Mitsuba at 256 px and written as 8-bit: the chrome sphere's rim mirrors what
    # lies just behind it, so its edges lie inside the outline, and the outermost-rim fit
    # started at the true circle comes out too small (settled: 0.11 px at the median here,
    # 0.15 px on Cycles renders; asserted beyond 0.05 px, a margin for renders on another
    # CPU); moved out by the rim shift it is within 0.1 px at the median (here +0.04)
    from relight import backend
    from relight.colour import srgb_decode
    from relight.imageio import to_srgb8
    from relight.verify import probe_scenes as ps
    backend.init()
    fitted, shifted = [], []
    for seed in range(7000, 7012):
        d = ps.sample_room_scene(seed, res=256)
        linear = ps.render_room_mitsuba(d, spp=16)
        image = srgb_decode(to_srgb8(linear, detect.camera_exposure(linear, 0.02)).astype(np.float64) / 255.0)
        t = d["truth"]
        cam = pg.Camera.from_fov(256, 256, t["fov_deg"])
        smoothed = detect._edge_image(image)
        fit, _ = detect.refine_sphere(image, cam, pg.sphere_from_circle(cam, *t["chrome_circle"]), smoothed)
        fit = detect.outer_rim_fit(smoothed, cam, fit)
        fitted.append(detect.outline_circle(cam, fit)[2] - t["chrome_circle"][2])
        moved = detect.outline_from_rim(cam, fit, detect.chrome_rim_shift_px(image))
        shifted.append(detect.outline_circle(cam, moved)[2] - t["chrome_circle"][2])
    assert np.median(fitted) < -0.05                      # the problem
    assert abs(np.median(shifted)) < 0.1


# ------------------------------------------------------------------ a mirror of a bright room in 8-bit
def _bright_room(s):
    """A bright room around the sphere: reflected directions toward the camera's side lit in
    wedges (0.08 / 0.32), the rest 0.2: the mirror's median is about a third of the clip level."""
    r = s["reflect"]
    wedges = np.sin(5.0 * np.arctan2(r[..., 1], r[..., 0])) > -0.3
    return np.where(r[..., 2] > -0.2, np.where(wedges, 0.32, 0.08), 0.2)


def test_a_mirror_of_a_bright_room_whose_highlight_clips_is_chrome():
    # in 8-bit the highlight clips at 1 and the mirror's median is about a third of that: the
    # contrast reads about 3, below CHROME_MIN_CONTRAST whatever the light's brightness; with
    # the clip level known the clipped highlight's contrast is a lower bound, and it is chrome
    cam = pg.Camera.from_fov(128, 96, FOV_DEG)
    sphere = _sphere_at(cam, 64.0, 48.0, 8.0)
    image = _quantise(_render(cam, sphere, np.array([0.3, 0.4, 0.87]), extra=_bright_room, background=0.5))
    blind = detect.sphere_features(image, cam, sphere)
    assert blind["contrast"] < detect.CHROME_MIN_CONTRAST and not detect.is_chrome(blind)   # the problem
    f = detect.sphere_features(image, cam, sphere, clip_level=1.0)
    assert f["clipped"] and f["clip_contrast"] >= detect.CHROME_MIN_CLIPPED_CONTRAST
    assert detect.is_chrome(f)
    # a diffuse ball, lit to clip on its bright side, stays diffuse: its bright region is its lit side
    ys, xs = np.mgrid[0:96, 0:128] + 0.5
    s = pg.surface(cam, sphere, xs, ys)
    shade = np.clip(s["normal"] @ (np.array([0.7, -0.4, 0.6]) / np.linalg.norm([0.7, -0.4, 0.6])), 0, None)
    ball = _quantise(np.repeat(np.where(s["hit"], np.clip(0.1 + 1.6 * shade, 0, 1), 0.5)[..., None], 3, -1))
    g = detect.sphere_features(ball, cam, sphere, clip_level=1.0)
    assert g["clipped"] and not detect.is_chrome(g)


def test_a_clipped_highlight_proposes_its_circles_when_the_proposals_overflow(monkeypatch):
    # strong-edged discs win the Hough votes and a dark disc with one bright, unclipped pixel
    # wins the one brightest-spot place; a faint bright disc (a mirror of a bright room) holding
    # a small clipped spot reads a contrast of about 2 and gets a place only among those holding
    # a compact clipped spot
    ys, xs = np.mgrid[0:96, 0:128] + 0.5
    img = np.full((96, 128), 0.3)
    discs = [(22, 22, 12), (64, 22, 12), (106, 22, 12), (22, 72, 12)]
    for cx, cy, r in discs:
        img[np.hypot(xs - cx, ys - cy) < r] = 0.8
    dark = (106.5, 72.5, 9.0)
    img[np.hypot(xs - dark[0], ys - dark[1]) < dark[2]] = 0.22
    img[71, 105] = 0.9
    faint = (64.5, 72.5, 9.0)
    img[np.hypot(xs - faint[0], ys - faint[1]) < faint[2]] = 0.4
    img[70:72, 62:64] = 1.0
    image = np.repeat(np.clip(ndimage.gaussian_filter(img, 0.5), 0, 1)[..., None], 3, -1)
    image[70:72, 62:64] = 1.0          # clipped in every channel
    monkeypatch.setattr(detect, "MAX_CANDIDATES", len(discs) + 1)
    monkeypatch.setattr(detect, "SPOT_PROPOSALS", 1)
    monkeypatch.setattr(detect, "CLIPPED_SPOT_PROPOSALS", 1)

    def found(circles, circle):
        return any(math.dist(c[:2], circle[:2]) < 3 for c in circles)
    cam = pg.Camera.from_fov(128, 96, FOV_DEG)
    smoothed = detect._edge_image(image)
    old = detect.hough_circles(image)
    assert found(old, dark) and not found(old, faint)        # the problem
    new = detect.hough_circles(image, 1.0, lambda c: detect._screen(smoothed, cam, *c)[0])
    assert found(new, dark) and found(new, faint)


def test_a_back_lit_small_mirrors_clipped_highlight_by_the_rim_counts_as_clipped():
    # a 10 px mirror sphere lit from 116 deg off the view: its clipped highlight lies 1.4 px
    # inside the outline, among the pixels the highlight is looked for in (all but the
    # outermost RIM_EXCLUDE_PX); the chrome test sees it clip (it once left 1.5 px out, and
    # the sphere, its only bright spot unread, was neither chrome nor found)
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 2.6)
    to_cam = -sphere.c / np.linalg.norm(sphere.c)
    up = np.array([0.0, 1.0, 0.0]) - to_cam[1] * to_cam
    up /= np.linalg.norm(up)
    light = math.cos(math.radians(116.0)) * to_cam + math.sin(math.radians(116.0)) * up
    spot, _ = pg.predict_highlight(cam, sphere, light)
    cx, cy, r = detect.outline_circle(cam, sphere)
    assert 9.5 < r < 10.5 and 1.2 < r - math.dist(spot, (cx, cy)) < 1.5
    f = detect.sphere_features(_quantise(_render(cam, sphere, light, light_radius_deg=2.0)), cam, sphere, 1.0)
    assert f["clipped"] and f["clip_contrast"] > detect.CHROME_MIN_CLIPPED_CONTRAST
    assert f["contrast"] < f["clip_contrast"]


def test_a_circle_chrome_only_by_the_clip_allowance_around_a_sphere_goes():
    # a large circle around a chrome sphere holds its clipped highlight and, on a bright
    # background, passes the chrome test only by the clipped allowance: the better supported
    # sphere inside stays, the circle goes (one with the full contrast, or better supported, stays)
    sphere = {"circle": (50.0, 50.0, 18.0), "edge_support": 0.43, "chrome": True, "contrast": 2.7}
    around = {"circle": (62.0, 60.0, 40.0), "edge_support": 0.27, "chrome": True, "contrast": 3.8}
    out = detect._drop_clipped_surroundings([sphere, around])
    assert any(c is sphere for c in out) and not any(c is around for c in out)
    bright = dict(around, contrast=6.0)
    assert any(c is bright for c in detect._drop_clipped_surroundings([sphere, bright]))
    better = dict(around, edge_support=0.5)
    assert any(c is better for c in detect._drop_clipped_surroundings([sphere, better]))


def test_the_chrome_pick_reads_a_clipped_highlight_contrast_as_a_lower_bound():
    # two candidates alike but for the contrast: the one whose highlight clips reads 2.7 over
    # its median but is at least 3.3 (the clip level over the median), more than the other's 3.0
    base = {"edge_support": 0.4, "chrome": True, "highlight": -1.0, "residual": 0.5}
    clipped = dict(base, circle=(20.0, 20.0, 15.0), contrast=2.7, clip_contrast=3.3)
    plain = dict(base, circle=(80.0, 20.0, 15.0), contrast=3.0)
    assert detect.pick_sphere([plain, clipped], "chrome") is clipped


def test_blackman_harris_pixel_weights_match_the_window():
    """The cell-integrated weights of the refiltered set: symmetric, summing to 1, and each
    the window's integral over its pixel (checked by a fine midpoint sum), the outer pixels
    (beyond +-1.5 px) empty."""
    w = load_script("benchmarks/bench_probe.py").blackman_harris_weights(1.5)
    x = np.linspace(-2.5, 2.5, 500_001)[:-1] + 5.0 / 1_000_000
    span = 3.0
    u = x / span + 0.5
    window = np.where(np.abs(x) <= 1.5, 0.35875 - 0.48829 * np.cos(2 * np.pi * u) + 0.14128 * np.cos(4 * np.pi * u)
                      - 0.01168 * np.cos(6 * np.pi * u), 0.0)
    cells = np.array([window[(x >= k - 0.5) & (x < k + 0.5)].sum() for k in range(-2, 3)])
    np.testing.assert_allclose(w, cells / cells.sum(), atol=1e-6)
    np.testing.assert_allclose(w, w[::-1], atol=1e-12)
    assert w.sum() == pytest.approx(1.0) and w[2] > 0.5 and w[0] == 0.0 and w[1] > 0.1


@pytest.mark.parametrize("blur_px", [None, 1.0])
def test_refiltered_copy_spreads_a_point_as_its_filter_does(tmp_path, blur_px):
    """``bench_probe.py --refilter`` (``--refilter-blur``): a point of light in a scene's
    Cycles EXR comes out with its energy kept, in place, spread with the filter's variance
    in x and y (the 1-D weights' own, or the Gaussian's), and the colour channels apart."""
    from relight.imageio import read_exr, write_exr
    bench = load_script("benchmarks/bench_probe.py")
    src, out = tmp_path / "set", tmp_path / "copy"
    src.mkdir()
    image = np.zeros((21, 25, 3), np.float32)
    image[10, 12] = (4.0, 2.0, 1.0)
    write_exr(str(src / "probe1234.cycles.exr"), image)
    (src / "probe1234.json").write_text(json.dumps({"png_exposure": 1.0}))
    bench.refilter_set(str(src), str(out), blur_px)
    got = read_exr(str(out / "probe1234.cycles.exr")).astype(np.float64)
    assert (out / "probe1234.cycles.png").exists() and json.loads((out / "probe1234.json").read_text()) == {"png_exposure": 1.0}
    np.testing.assert_allclose(got.sum((0, 1)), (4.0, 2.0, 1.0), rtol=1e-5)
    np.testing.assert_allclose(got[..., 1] * 2.0, got[..., 0], atol=1e-6)
    lum = got[..., 0] / got[..., 0].sum()
    ys, xs = np.mgrid[0:21, 0:25]
    assert (lum * xs).sum() == pytest.approx(12.0, abs=1e-6) and (lum * ys).sum() == pytest.approx(10.0, abs=1e-6)
    if blur_px is None:
        w = bench.blackman_harris_weights()
        variance = float((w * np.arange(-2, 3) ** 2).sum())
    else:
        variance = blur_px ** 2
    assert (lum * (xs - 12.0) ** 2).sum() == pytest.approx(variance, rel=0.02)
    assert (lum * (ys - 10.0) ** 2).sum() == pytest.approx(variance, rel=0.02)


def test_a_linear_hdr_image_is_searched_as_a_camera_would_expose_it(monkeypatch):
    # a linear EXR's highlight is hundreds of times its surroundings: detection looks at it
    # as a camera's auto exposure would record it (the brightest 2% clip), so that it is
    # read as the 8-bit files the detector knows are (Cycles EXR automatic misses 4/40 -> 1/40)
    rng = np.random.default_rng(5)
    hdr = np.repeat(rng.uniform(0.0, 1.0, (60, 80, 1)) ** 3 * 500.0, 3, -1)   # grey: mean = every channel
    exposed = detect.exposed_like_a_camera(hdr)
    lum = hdr.mean(-1)
    level = np.percentile(lum, 98.0)
    clipped = (exposed >= 1.0).all(-1)
    assert 0.015 <= clipped.mean() <= 0.025 and exposed.max() == 1.0
    below = np.all(hdr / level < 1.0, axis=-1)
    np.testing.assert_allclose(exposed[below], hdr[below] / level, rtol=1e-12)
    seen = []
    monkeypatch.setattr(detect, "_edge_image", lambda image: seen.append(image) or np.zeros_like(image))
    monkeypatch.setattr(detect, "hough_circles", lambda image, *a, **k: [])
    detect.find_spheres(hdr, pg.Camera.from_fov(80, 60, FOV_DEG))
    np.testing.assert_array_equal(seen[0], exposed)


def test_the_reference_diagnostic_recovers_the_circle_a_reference_was_made_with():
    # lights derived (orthographic mirror) from highlights on a circle 12% larger than the
    # mask's: the diagnostic finds that circle, and the mask's disagrees by degrees
    bench = load_script("benchmarks/bench_probe.py")
    rng = np.random.default_rng(3)
    used = np.array([256.5, 150.8, 134.4])
    highlights = np.column_stack([used[0] + rng.uniform(-60, 60, 12), used[1] + rng.uniform(-60, 60, 12)])
    n = np.column_stack([(highlights[:, 0] - used[0]) / used[2], -(highlights[:, 1] - used[1]) / used[2]])
    n = np.column_stack([n, np.sqrt(1.0 - (n ** 2).sum(1))])
    lights = 2.0 * n[:, 2:3] * n - np.array([0.0, 0.0, 1.0])
    fit, at_mask, at_fit = bench.reference_circle(lights, highlights, (253.8, 148.3, 119.5))
    assert np.allclose(fit, used, atol=0.05)
    assert np.max(at_fit) < 0.01
    assert np.median(at_mask) > 1.0


# ------------------------------------------------------------------ an ambiguous detection
def _two_mirrors(tmp_path):
    """Two mirror spheres side by side, each with its own light (the left one's up and to
    the right, the right one's up and to the left), written as an 8-bit PNG; returns the
    path, the camera, both spheres and both lights."""
    from relight.imageio import write_png
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    left, right = _sphere_at(cam, 50.0, 60.0, 5.0), _sphere_at(cam, 112.0, 60.0, 5.0)
    l1 = np.array([0.4, 0.4, 0.82]) / np.linalg.norm([0.4, 0.4, 0.82])
    l2 = np.array([-0.4, 0.3, 0.87]) / np.linalg.norm([-0.4, 0.3, 0.87])
    a = _render(cam, left, l1, light_radius_deg=2.0)
    b = _render(cam, right, l2, light_radius_deg=2.0)
    ys, xs = np.mgrid[0:H, 0:W] + 0.5
    on_right = pg.surface(cam, right, xs, ys)["hit"]
    image = np.where(on_right[..., None], b, a)
    path = str(tmp_path / "two.png")
    write_png(path, image)
    return path, cam, left, right, l1, l2


def _candidate(cam, sphere, support):
    return {"sphere": sphere, "circle": pg.outline_circle(cam, sphere), "chrome": True, "diffuse": False,
            "edge_support": support, "contrast": 10.0, "highlight": 0.0}


@pytest.mark.parametrize("rival_support, ambiguous", [(0.55, True), (0.45, False)])
def test_a_rival_circle_scoring_nearly_as_well_widens_the_uncertainty(tmp_path, monkeypatch, rival_support,
                                                                      ambiguous):
    # the detector's two chrome circles score 0.6 and 0.55 (margin 0.05 of 0.1: ambiguity
    # 0.5) or 0.6 and 0.45 (not ambiguous); the chosen one's light stands, and the budget
    # grows by the angle to the rival's light times the ambiguity
    from relight.probe.run import ProbeConfig, run_probe
    path, cam, left, right, l1, l2 = _two_mirrors(tmp_path)
    # (the rules' scores alone: the learned locator off, its prior would move them)
    monkeypatch.setattr(detect, "find_spheres", lambda image, camera, clip=None, extra=(), radius_bound=None, outline_check=None: [
        _candidate(cam, left, 0.6), _candidate(cam, right, rival_support)])
    entry = run_probe(ProbeConfig(chrome=path, fov_deg=FOV_DEG, locator=False)).entry
    assert _angle(entry["to_light_camera"], l1) < 3.0
    budget = entry["quality"]["error_budget_deg"]
    if not ambiguous:
        assert "detection" not in entry and "detection_deg" not in budget
        return
    det = entry["detection"]
    assert det["ambiguity"] == pytest.approx(0.5, abs=0.01)     # (the radius term differs a little)
    assert abs(det["separation_deg"] - _angle(l1, l2)) < 3.0
    assert _angle(det["alternative_to_light_camera"], l2) < 3.0
    # (both outlines are the rims' fits moved out by the image's rim shift, detect.chrome_rim_shift_px)
    assert entry["chrome_rim_shift_px"] > 0
    rival = detect.outline_from_rim(cam, right, entry["chrome_rim_shift_px"])
    assert np.allclose(det["alternative_circle"], pg.outline_circle(cam, rival), atol=1e-2)
    assert np.allclose(entry["chrome_circle"], pg.outline_circle(
        cam, detect.outline_from_rim(cam, left, entry["chrome_rim_shift_px"])), atol=1e-2)
    assert budget["detection_deg"] == pytest.approx(det["ambiguity"] * det["separation_deg"], abs=0.01)
    assert entry["quality_deg"] == pytest.approx(math.hypot(budget["circle_deg"], budget["highlight_deg"],
                                                            budget["camera_deg"], budget["detection_deg"]), abs=0.01)


def test_the_rival_is_another_circle_not_the_same_one_found_twice():
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    picked = _candidate(cam, _sphere_at(cam, 50.0, 60.0, 5.0), 0.6)
    twin = _candidate(cam, _sphere_at(cam, 51.0, 60.5, 5.2), 0.59)     # the same sphere, a little off
    other = _candidate(cam, _sphere_at(cam, 112.0, 60.0, 5.0), 0.52)
    rival, margin = detect.rival_sphere([picked, twin, other], picked, "chrome")
    assert rival is other and margin == pytest.approx(0.08, abs=0.002)
    assert detect.rival_sphere([picked, twin], picked, "chrome") == (None, math.inf)


def test_the_command_names_the_rival_circle(tmp_path, monkeypatch, capsys):
    path, cam, left, right, l1, l2 = _two_mirrors(tmp_path)
    monkeypatch.setattr(detect, "find_spheres", lambda image, camera, clip=None, extra=(), radius_bound=None, outline_check=None: [
        _candidate(cam, left, 0.6), _candidate(cam, right, 0.55)])
    out = tmp_path / "probe.json"
    assert _run(["probe", "--chrome", path, "--fov", str(FOV_DEG), "--out", str(out), "--no-locator"]) == 0
    with open(out) as f:
        entry = json.load(f)["predictions"][0]
    assert "detection" in entry
    cx, cy, r = pg.outline_circle(cam, detect.outline_from_rim(cam, right, entry["chrome_rim_shift_px"]))
    assert f"note: another circle, ({cx:.1f}, {cy:.1f}) r {r:.1f}" in capsys.readouterr().out

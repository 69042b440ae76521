"""A light's position from which pixels it clipped (relight.probe.footprint): a light far
above the clip level, a narrow pixel filter, nothing of it beside its clipped pixels.
Checked against the symmetry of symmetric pixel sets, against sub-pixel lights of known
position (their coverage computed by supersampling) and, through locate_highlight, against
box-filtered renders of a mirror sphere with a known light; and that a blurred light is
left to the soft window."""
import math

import numpy as np
import pytest
from scipy import ndimage

from relight.probe import footprint, geometry as pg

from test_probe_hard import FOV_DEG, H, W, _quantise, _render, _sphere_at

ROUND = np.eye(2)
OBLIQUE = np.array([[1.0, 0.4], [0.4, 2.5]])    # an ellipse as near a mirror sphere's rim


def _clipped(centre, radius_px, metric, size=16, ss=32):
    """Pixels a light ellipse ``d^T metric d < radius^2`` touches (a box filter and a
    light far above the clip level: any covered subsample clips the pixel)."""
    g = (np.arange(size * ss) + 0.5) / ss
    x, y = np.meshgrid(g, g)
    dx, dy = x - centre[0], y - centre[1]
    q = metric[0, 0] * dx * dx + 2 * metric[0, 1] * dx * dy + metric[1, 1] * dy * dy
    return (q < radius_px ** 2).reshape(size, ss, size, ss).any(axis=(1, 3))


def _observed(clipped):
    return ndimage.binary_dilation(clipped, np.ones((3, 3), bool))


@pytest.mark.parametrize("metric", [ROUND, OBLIQUE], ids=["round", "oblique"])
@pytest.mark.parametrize("cells", [[(5, 5)], [(5, 5), (5, 6)], [(5, 5), (5, 6), (6, 5), (6, 6)],
                                   [(4, 5), (5, 4), (5, 5), (5, 6), (6, 5)]],
                         ids=["one", "two", "square", "plus"])
def test_a_symmetric_set_of_clipped_pixels_puts_the_light_at_its_centre(cells, metric):
    # a set of pixels symmetric under a half turn, and a light ellipse that is too: every
    # position has its mirror image through the set's centre, equally likely
    clipped = np.zeros((12, 12), bool)
    for y, x in cells:
        clipped[y, x] = True
    ys, xs = np.nonzero(clipped)
    x, y = footprint.footprint_centre(clipped, _observed(clipped), metric)
    assert math.dist((x, y), (xs.mean() + 0.5, ys.mean() + 0.5)) < 1e-6


@pytest.mark.parametrize("metric", [ROUND, OBLIQUE], ids=["round", "oblique"])
def test_a_light_touching_three_of_four_pixels_is_placed_better_than_their_centroid(metric):
    # a sub-pixel light near the corner of four pixels that reaches three of them: their
    # centroid lies a sixth of a pixel from the corner each way, the light itself nearer
    # the pixel between the other two (on a sample of such lights: 0.15 px against 0.26)
    rng = np.random.default_rng(5)
    err, known, cen = [], [], []
    while len(err) < 16:
        centre = 8.0 + rng.uniform(-0.5, 0.5, 2)
        radius = rng.uniform(0.3, 0.9)
        clipped = _clipped(centre, radius, metric)
        ys, xs = np.nonzero(clipped)
        if len(xs) != 3 or np.ptp(xs) != 1 or np.ptp(ys) != 1:
            continue
        err.append(math.dist(footprint.footprint_centre(clipped, _observed(clipped), metric), centre))
        # the light's size known (the radius of the disc of the ellipse's area): the floor
        size = radius / np.linalg.det(metric) ** 0.25
        known.append(math.dist(footprint.footprint_centre(clipped, _observed(clipped), metric, size), centre))
        cen.append(math.dist((xs.mean() + 0.5, ys.mean() + 0.5), centre))
    assert np.mean(err) < 0.75 * np.mean(cen)
    assert np.mean(known) < np.mean(err)


def _non_rectangular_cores(sphere_deg, light_deg, count, seed=1):
    """Box-filtered renders (8 x 8 samples a pixel, the light 10^4 above the clip) of a
    mirror sphere whose light's clipped pixels do not form a rectangle (a rectangle's
    centre is where the light is most likely; the estimate gains elsewhere)."""
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, sphere_deg)
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        light = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.4, 0.6), 1.0])
        light /= np.linalg.norm(light)
        image = _quantise(_render(cam, sphere, light, light_radius_deg=light_deg, radiance=1e4, blur_px=0.0, ss=8))
        ys, xs = np.nonzero(image[..., 0] >= 0.999)
        if len(xs) != (np.ptp(xs) + 1) * (np.ptp(ys) + 1):
            out.append((cam, sphere, light, image, (xs.mean() + 0.5, ys.mean() + 0.5)))
    return out


@pytest.mark.parametrize("sphere_deg, light_deg", [(9.0, 3.0), (5.0, 3.0)], ids=["35px", "19px"])
def test_a_box_filtered_clipped_highlight_is_located_by_its_footprint(sphere_deg, light_deg):
    # measured (12 scenes each): 35 px sphere 0.13 px against the clipped centroid's 0.16;
    # 19 px sphere 0.18 against 0.27
    err, cen = [], []
    for cam, sphere, light, image, centroid in _non_rectangular_cores(sphere_deg, light_deg, 12):
        spot, _ = pg.predict_highlight(cam, sphere, light)
        found = pg.locate_highlight(image, cam, sphere, clip_level=1.0)
        err.append(math.dist(found.pixel, spot))
        cen.append(math.dist(centroid, spot))
    assert np.mean(err) < 0.85 * np.mean(cen)
    assert np.mean(err) < 0.2


def test_a_blurred_clipped_light_is_left_to_the_soft_window():
    # the same light under a lens's blur: a tail surrounds its clipped pixels, and the
    # footprint model (nothing of the light beside them) does not hold
    cam = pg.Camera.from_fov(W, H, FOV_DEG)
    sphere = _sphere_at(cam, 80.0, 60.0, 9.0)
    light = np.array([0.2, 0.3, 1.0]) / np.linalg.norm([0.2, 0.3, 1.0])
    for blur, expect in ((0.0, True), (0.6, False)):
        image = _quantise(_render(cam, sphere, light, light_radius_deg=3.0, radiance=1e4, blur_px=blur, ss=8))
        lum = image[..., 0]
        (x0, y0, x1, y1), usable, _ = pg.sphere_pixels(cam, sphere)
        crop = lum[y0:y1, x0:x1]
        core = usable & (crop >= 0.999)
        core = ndimage.label(core, np.ones((3, 3)))[0] == 1
        got = pg._clipped_footprint_centre(cam, sphere, crop, core, usable, (x0, y0))
        assert (got is not None) == expect, blur

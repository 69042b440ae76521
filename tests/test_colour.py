"""Tests of relight.colour: published chromaticities, RGB properties, sRGB curves."""
from __future__ import annotations

import numpy as np
import pytest

from relight import colour as rc

XY_TOL_A = 1e-3          # illuminant A, published to 4 decimals
XY_TOL_D65 = 2e-3        # D65 is a daylight spectrum, not exactly a (CCT, Duv) point
XY_TOL_PLANCK = 5e-4     # Planckian 6500 K, published to 4 decimals
NORM_TOL = 1e-12
CCT_ROUND_TRIP_K = 1.0
CCT_ROUND_TRIP_REL = 1e-3
DUV_ROUND_TRIP = 1e-4
SRGB_TOL = 1e-12
SRGB_KNOWN_TOL = 1e-5

# Grid of the sampled range. The corner CCT < ~2535 K with Duv > ~+0.0094 is outside
# the sRGB gamut (blue < 0), see test_out_of_gamut_corner_is_documented.
GRID_CCT_K = np.geomspace(rc.CCT_RANGE_K[0], rc.CCT_RANGE_K[1], 60)
GRID_DUV = np.linspace(-rc.DUV_MAX, rc.DUV_MAX, 21)


def in_gamut_grid():
    cct, duv = np.meshgrid(GRID_CCT_K, GRID_DUV, indexing="ij")
    corner = (cct < 2540.0) & (duv > 0.009)
    return cct[~corner], duv[~corner]


def test_illuminant_a_chromaticity():
    # CIE illuminant A: Planckian radiator at 2856 K, xy = (0.4476, 0.4074) (CIE 15:2004).
    xy = rc.cct_duv_to_xy(2856.0, 0.0)
    np.testing.assert_allclose(xy, [0.4476, 0.4074], atol=XY_TOL_A)


def test_d65_like_chromaticity():
    # D65 white point xy = (0.3127, 0.3290) has CCT ~ 6504 K and lies above the
    # Planckian locus by Duv ~ +0.0032 (Ohno 2014, Table 1; colour-science's example
    # 6507.47 K / 0.00322 for uv (0.1978, 0.3122)). So (6504 K, +0.0032) -> ~D65.
    xy = rc.cct_duv_to_xy(6504.0, 0.0032)
    np.testing.assert_allclose(xy, [0.3127, 0.3290], atol=XY_TOL_D65)
    # and the inverse of sRGB white (D65) gives back those numbers
    cct_k, duv = rc.rgb_to_cct_duv([1.0, 1.0, 1.0])
    assert abs(cct_k - 6504.0) < 10.0
    assert abs(duv - 0.0032) < 2e-4


def test_planckian_6500k():
    # Blackbody at 6500 K: xy = (0.3135, 0.3236) (CIE 1931 2 degree observer).
    np.testing.assert_allclose(rc.cct_duv_to_xy(6500.0), [0.3135, 0.3236], atol=XY_TOL_PLANCK)


def test_shapes_broadcast():
    assert rc.cct_duv_to_xy(3000.0).shape == (2,)
    assert rc.cct_duv_to_xy([3000.0, 4000.0], 0.0).shape == (2, 2)
    assert rc.cct_duv_to_rgb(np.full((2, 3), 5000.0), [0.0, 0.005, -0.005]).shape == (2, 3, 3)
    assert rc.xy_to_rgb([[0.3127, 0.329]]).shape == (1, 3)


def test_unit_norm_and_positive_over_range():
    cct, duv = in_gamut_grid()
    rgb = rc.cct_duv_to_rgb(cct, duv)
    np.testing.assert_allclose(np.linalg.norm(rgb, axis=-1), 1.0, atol=NORM_TOL)
    assert np.all(rgb > 0.0)


def test_out_of_gamut_corner_is_documented():
    # 2500 K, Duv +0.01 lies just outside the sRGB gamut: blue slightly negative, but
    # returned exactly (no clipping) and still unit norm.
    rgb = rc.cct_duv_to_rgb(2500.0, 0.01)
    assert -0.01 < rgb[2] < 0.0
    assert abs(np.linalg.norm(rgb) - 1.0) < NORM_TOL
    assert np.all(rc.cct_duv_to_rgb(2540.0, 0.01) > 0.0)
    assert np.all(rc.cct_duv_to_rgb(2500.0, 0.009) > 0.0)


def test_white_point_is_neutral():
    # No chromatic adaptation: D65's own chromaticity maps to equal RGB.
    np.testing.assert_allclose(rc.xy_to_rgb([0.3127, 0.3290]), np.full(3, 3 ** -0.5), atol=1e-4)


@pytest.mark.parametrize("duv", [-rc.DUV_MAX, 0.0, 0.008])
def test_lower_cct_is_redder(duv):
    rgb = rc.cct_duv_to_rgb(GRID_CCT_K, duv)
    r_over_b = rgb[:, 0] / rgb[:, 2]
    assert np.all(np.diff(r_over_b) < 0.0)
    assert r_over_b[0] > 2.0 and r_over_b[-1] < 1.0  # warm is orange, 10000 K is blue


def test_cct_duv_round_trip():
    cct, duv = in_gamut_grid()
    rgb = rc.cct_duv_to_rgb(cct, duv) * 7.5  # scale must not matter
    cct_back, duv_back = rc.rgb_to_cct_duv(rgb)
    assert cct_back.shape == cct.shape
    assert np.max(np.abs(cct_back - cct)) < CCT_ROUND_TRIP_K
    assert np.max(np.abs(cct_back / cct - 1.0)) < CCT_ROUND_TRIP_REL
    assert np.max(np.abs(duv_back - duv)) < DUV_ROUND_TRIP


def test_sample_light_colour_ranges_and_determinism():
    rng = np.random.default_rng(1234)
    draws = [rc.sample_light_colour(rng) for _ in range(300)]
    cct = np.array([d[0] for d in draws])
    duv = np.array([d[1] for d in draws])
    rgb = np.array([d[2] for d in draws])
    assert np.all((cct >= rc.CCT_RANGE_K[0]) & (cct <= rc.CCT_RANGE_K[1]))
    assert np.all(np.abs(duv) <= rc.DUV_MAX)
    assert np.all(rgb > 0.0)
    np.testing.assert_allclose(np.linalg.norm(rgb, axis=-1), 1.0, atol=NORM_TOL)
    np.testing.assert_allclose(rgb, rc.cct_duv_to_rgb(cct, duv), atol=1e-12)
    # uniform in mireds: the median mired is near the middle of [100, 400]
    assert 220.0 < np.median(1e6 / cct) < 280.0
    assert isinstance(draws[0][0], float) and isinstance(draws[0][1], float)
    again = rc.sample_light_colour(np.random.default_rng(1234))
    assert again[0] == draws[0][0] and again[1] == draws[0][1]
    np.testing.assert_array_equal(again[2], draws[0][2])
    other = rc.sample_light_colour(np.random.default_rng(4321))
    assert other[0] != draws[0][0]


def test_srgb_known_values():
    lin = np.array([0.0, rc.SRGB_LINEAR_KNEE, 0.5, 1.0])
    np.testing.assert_allclose(rc.srgb_encode(lin), [0.0, 0.04045, 0.735357, 1.0],
                               atol=SRGB_KNOWN_TOL)
    np.testing.assert_allclose(rc.srgb_decode([0.04045, 0.735357, 1.0]),
                               [0.0031308, 0.5, 1.0], atol=SRGB_KNOWN_TOL)
    # clipping to [0, 1]
    np.testing.assert_array_equal(rc.srgb_encode([-0.5, 2.0]), [0.0, 1.0])


def test_srgb_round_trip_and_monotonic():
    x = np.linspace(0.0, 1.0, 10001)
    np.testing.assert_allclose(rc.srgb_decode(rc.srgb_encode(x)), x, atol=SRGB_TOL)
    np.testing.assert_allclose(rc.srgb_encode(rc.srgb_decode(x)), x, atol=SRGB_TOL)
    assert np.all(np.diff(rc.srgb_encode(x)) > 0.0)
    img = np.random.default_rng(0).random((4, 5, 3))
    assert rc.srgb_encode(img).shape == (4, 5, 3)


def test_srgb_matches_colour_science():
    import colour
    x = np.linspace(0.0, 1.0, 101)
    np.testing.assert_allclose(rc.srgb_encode(x), colour.models.eotf_inverse_sRGB(x), atol=1e-12)


@pytest.mark.parametrize("cct_k, duv", [
    (999.0, 0.0), (25001.0, 0.0), (np.nan, 0.0), (np.inf, 0.0),
    (5000.0, 0.051), (5000.0, -0.06), (5000.0, np.nan), ([3000.0, 500.0], 0.0),
])
def test_bad_cct_duv_raise(cct_k, duv):
    with pytest.raises(ValueError, match="expected"):
        rc.cct_duv_to_rgb(cct_k, duv)


@pytest.mark.parametrize("func, arg", [
    (rc.xy_to_rgb, [0.3, 0.3, 0.3]), (rc.xy_to_rgb, [0.3, 0.0]), (rc.xy_to_rgb, [np.nan, 0.3]),
    (rc.rgb_to_cct_duv, [1.0, 1.0]), (rc.rgb_to_cct_duv, [0.0, 0.0, 0.0]),
    (rc.rgb_to_cct_duv, [1.0, np.inf, 1.0]),
    (rc.srgb_encode, [0.1, np.nan]), (rc.srgb_decode, [np.inf]),
])
def test_bad_inputs_raise(func, arg):
    with pytest.raises(ValueError):
        func(arg)


# --- CCT / Duv of predicted colours (relight.colour.rgb_to_cct_duv_near_locus) ----------

CCT_PUBLISHED_TOL_K = 5.0     # published CCTs are rounded to the kelvin
DUV_PUBLISHED_TOL = 2e-4


@pytest.mark.parametrize("xy, cct_k, duv", [
    ((0.44757, 0.40745), 2856.0, 0.0),      # CIE illuminant A (CIE 15:2004): Planckian 2856 K
    ((0.31271, 0.32902), 6504.0, 0.0032),   # CIE D65 (CIE 15:2004), Duv ~ +0.0032 (Ohno 2014)
])
def test_cct_duv_of_published_illuminants_through_rgb(xy, cct_k, duv):
    rgb = rc.xy_to_rgb(np.array(xy))          # the illuminant as a linear sRGB light colour
    got_cct, got_duv = rc.rgb_to_cct_duv_near_locus(rgb * 3.7)   # any scale
    assert abs(float(got_cct) - cct_k) < CCT_PUBLISHED_TOL_K
    assert abs(float(got_duv) - duv) < DUV_PUBLISHED_TOL


def test_cct_near_locus_round_trip_and_far_colours_are_nan():
    cct, duv = in_gamut_grid()
    got_cct, got_duv = rc.rgb_to_cct_duv_near_locus(rc.cct_duv_to_rgb(cct, duv))
    np.testing.assert_allclose(got_cct, cct, rtol=CCT_ROUND_TRIP_REL, atol=CCT_ROUND_TRIP_K)
    np.testing.assert_allclose(got_duv, duv, atol=DUV_ROUND_TRIP)
    # saturated primaries are far from the locus (|Duv| > 0.05 or no CCT in 1000-25000 K)
    far = np.array([[0, 1, 0], [0, 0, 1], [1, 0, 0], [1, 0, 1], [0.2, 1.0, 0.2]], dtype=float)
    c, d = rc.rgb_to_cct_duv_near_locus(far)
    assert np.isnan(c).all() and np.isnan(d).all()
    # just inside / outside the Duv threshold
    c, d = rc.rgb_to_cct_duv_near_locus(rc.cct_duv_to_rgb([4000.0, 4000.0], [0.049, -0.049]))
    assert np.isfinite(c).all()
    assert rc.rgb_to_cct_duv_near_locus(np.zeros(3))[0].shape == ()
    assert np.isnan(rc.rgb_to_cct_duv_near_locus(np.zeros(3))[0])

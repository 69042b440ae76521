"""Tests of relight.metrics: closed-form errors, statistics, levels and tables."""
from __future__ import annotations

import numpy as np
import pytest

from relight import metrics as m

ANGLE_TOL_DEG = 1e-9
TINY_ANGLE_DEG = 1e-4
TINY_REL_TOL = 1e-6
STAT_TOL = 1e-12


def test_pan_error_closed_forms():
    assert m.pan_error_deg(359.0, 1.0) == pytest.approx(2.0, abs=ANGLE_TOL_DEG)
    assert m.pan_error_deg(1.0, 359.0) == pytest.approx(2.0, abs=ANGLE_TOL_DEG)
    assert m.pan_error_deg(180.0, 0.0) == pytest.approx(180.0, abs=ANGLE_TOL_DEG)
    assert m.pan_error_deg(0.0, 180.0) == pytest.approx(180.0, abs=ANGLE_TOL_DEG)
    assert m.pan_error_deg(725.0, -5.0) == pytest.approx(10.0, abs=ANGLE_TOL_DEG)
    e = m.pan_error_deg(np.linspace(-720, 720, 1001), 0.0)
    assert e.shape == (1001,) and np.all((e >= 0.0) & (e <= 180.0))


def test_tilt_error():
    np.testing.assert_allclose(m.tilt_error_deg([40.0, 30.0], [30.0, 45.5]), [10.0, 15.5])


def test_direction_error_closed_forms():
    assert m.direction_error_deg(0.0, 0.0, 90.0, 0.0) == pytest.approx(90.0, abs=ANGLE_TOL_DEG)
    assert m.direction_error_deg(0.0, 0.0, 180.0, 0.0) == pytest.approx(180.0, abs=ANGLE_TOL_DEG)
    assert m.direction_error_deg(0.0, 0.0, 0.0, 90.0) == pytest.approx(90.0, abs=ANGLE_TOL_DEG)
    assert m.direction_error_deg(10.0, 30.0, 10.0, 30.0) == pytest.approx(0.0, abs=ANGLE_TOL_DEG)


def test_direction_at_zenith_ignores_pan():
    pans = np.array([0.0, 37.0, 180.0, 359.0])
    e = m.direction_error_deg(pans, 90.0, pans[::-1] + 11.0, 90.0)
    np.testing.assert_allclose(e, 0.0, atol=ANGLE_TOL_DEG)


def test_direction_equals_pan_error_on_horizon():
    rng = np.random.default_rng(0)
    p1, p2 = rng.uniform(-400, 400, 500), rng.uniform(-400, 400, 500)
    np.testing.assert_allclose(m.direction_error_deg(p1, 0.0, p2, 0.0),
                               m.pan_error_deg(p1, p2), atol=1e-9)


def test_direction_equals_tilt_error_at_same_pan():
    t1, t2 = np.array([30.0, 45.0, 89.0]), np.array([35.0, 80.0, 60.0])
    np.testing.assert_allclose(m.direction_error_deg(123.0, t1, 123.0, t2),
                               m.tilt_error_deg(t1, t2), atol=1e-9)


def test_direction_tiny_angle_accuracy():
    # arccos of the dot product would lose about half the digits here.
    e_tilt = m.direction_error_deg(20.0, 45.0, 20.0, 45.0 + TINY_ANGLE_DEG)
    assert e_tilt == pytest.approx(TINY_ANGLE_DEG, rel=TINY_REL_TOL)
    e_pan = m.direction_error_deg(20.0, 0.0, 20.0 + TINY_ANGLE_DEG, 0.0)
    assert e_pan == pytest.approx(TINY_ANGLE_DEG, rel=TINY_REL_TOL)
    # at tilt 60 a pan step of d subtends d * cos(60) to first order
    e_pan60 = m.direction_error_deg(20.0, 60.0, 20.0 + TINY_ANGLE_DEG, 60.0)
    assert e_pan60 == pytest.approx(TINY_ANGLE_DEG * 0.5, rel=TINY_REL_TOL)


def test_colour_error_closed_forms():
    assert m.colour_error_deg([1.0, 1.0, 1.0], [2.0, 2.0, 2.0]) == pytest.approx(0.0, abs=ANGLE_TOL_DEG)
    expected = np.degrees(np.arccos(1.0 / np.sqrt(3.0)))
    assert expected == pytest.approx(54.7356, abs=1e-4)
    assert m.colour_error_deg([1.0, 1.0, 1.0], [1.0, 0.0, 0.0]) == pytest.approx(expected, abs=1e-9)
    assert m.colour_error_deg([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]) == pytest.approx(90.0, abs=1e-9)
    # tiny angle and huge/small scales
    a = np.array([1.0, 0.5, 0.25])
    b = a + np.array([0.0, 1e-7, 0.0])
    ref = np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b)), a @ b))
    assert m.colour_error_deg(a * 1e-200, b * 1e200) == pytest.approx(ref, rel=TINY_REL_TOL)
    assert m.colour_error_deg(np.ones((4, 2, 3)), [1.0, 1.0, 1.0]).shape == (4, 2)


@pytest.mark.parametrize("pred, gt", [([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]),
                                      ([1.0, np.nan, 1.0], [1.0, 1.0, 1.0]),
                                      ([1.0, 1.0], [1.0, 1.0])])
def test_colour_error_bad_input(pred, gt):
    with pytest.raises(ValueError):
        m.colour_error_deg(pred, gt)


def test_light_errors_keys_and_values():
    e = m.light_errors([359.0, 10.0], [40.0, 50.0], [[1, 1, 1], [1, 0, 0]],
                       [1.0, 10.0], [30.0, 50.0], [[2, 2, 2], [1, 0, 0]])
    assert list(e) == ["pan", "tilt", "direction", "colour"]
    np.testing.assert_allclose(e["pan"], [2.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(e["tilt"], [10.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(e["colour"], [0.0, 0.0], atol=1e-9)
    assert e["direction"][1] == pytest.approx(0.0, abs=1e-9)
    assert 10.0 <= e["direction"][0] < 12.0  # tilt 10 apart, pan 2 apart near tilt 35


def test_summary_stats_hand_computed():
    s = m.summary_stats(np.arange(1.0, 9.0))
    q1, med, q3 = np.quantile(np.arange(1.0, 9.0), [0.25, 0.5, 0.75])
    assert s["n"] == 8
    assert s["mean"] == pytest.approx(4.5, abs=STAT_TOL)
    assert s["median"] == pytest.approx(4.5, abs=STAT_TOL)
    assert s["best25"] == pytest.approx(1.5, abs=STAT_TOL)
    assert s["worst25"] == pytest.approx(7.5, abs=STAT_TOL)
    assert s["max"] == 8.0
    assert s["trimean"] == pytest.approx((q1 + 2 * med + q3) / 4, abs=STAT_TOL)
    # skewed data: trimean differs from mean; order of input must not matter
    v = np.array([9.0, 1.0, 0.0, 2.0, 100.0, 3.0, 1.0, 4.0])
    s = m.summary_stats(v)
    assert s["median"] == pytest.approx(2.5) and s["mean"] == pytest.approx(15.0)
    assert s["best25"] == pytest.approx(0.5) and s["worst25"] == pytest.approx(54.5)
    assert s["trimean"] == pytest.approx((1.0 + 2 * 2.5 + 5.25) / 4)
    assert m.summary_stats([3.0])["best25"] == 3.0


def test_summary_stats_empty_and_nan():
    s = m.summary_stats([])
    assert s["n"] == 0
    assert all(np.isnan(s[k]) for k in ("mean", "median", "trimean", "best25", "worst25", "max"))
    with pytest.raises(ValueError):
        m.summary_stats([1.0, np.nan])


def test_tilt_level_boundaries():
    labels = m.tilt_level([29.99, 30.0, 49.99, 50.0, 69.99, 70.0, 90.0, 90.01, np.nan])
    assert labels.tolist() == ["", "L1", "L1", "L2", "L2", "L3", "L3", "", ""]
    assert m.tilt_level(55.0) == "L2"


def test_pan_level_boundaries():
    pans = [315.0, 359.9, 0.0, 44.9, 45.0, 134.9, 135.0, 224.9, 225.0, 314.9, -1.0, 405.0]
    labels = m.pan_level(pans, 50.0)
    assert labels.tolist() == ["front", "front", "front", "front", "right", "right",
                               "back", "back", "left", "left", "front", "right"]
    # only tilt in [30, 70] counts (inclusive)
    assert m.pan_level([10.0] * 5, [29.0, 30.0, 70.0, 80.0, 90.0]).tolist() == \
        ["", "front", "front", "", ""]


def _example():
    tilt = np.array([30.0, 40.0, 55.0, 60.0, 75.0, 90.0, 35.0, 65.0])
    pan = np.array([0.0, 90.0, 180.0, 270.0, 10.0, 200.0, 350.0, 100.0])
    errors = {"pan": np.arange(8.0), "tilt": np.arange(8.0) * 2,
              "direction": np.arange(8.0) + 0.5, "colour": np.full(8, 1.25)}
    return errors, tilt, pan


def test_error_tables_structure_and_values():
    errors, tilt, pan = _example()
    t = m.error_tables(errors, tilt, pan)
    assert set(t) == {"overall", "tilt_levels", "pan_levels"}
    assert list(t["tilt_levels"]) == ["L1", "L2", "L3"]
    assert list(t["pan_levels"]) == ["front", "right", "back", "left"]
    assert list(t["overall"]) == ["pan", "tilt", "direction", "colour", "pan_all"]
    # pan where defined: index 5 (tilt 90) left out -> mean of 0..7 without 5 = 23 / 7
    assert t["overall"]["pan"]["n"] == 7 and t["overall"]["pan"]["zenith_left_out"] == 1
    assert t["overall"]["pan"]["mean"] == pytest.approx(23.0 / 7.0)
    assert t["overall"]["pan_all"]["n"] == 8 and t["overall"]["pan_all"]["mean"] == pytest.approx(3.5)
    assert t["overall"]["tilt"]["n"] == 8
    # L1: indices 0, 1, 6 -> pan errors 0, 1, 6
    assert t["tilt_levels"]["L1"]["pan"]["n"] == 3
    assert t["tilt_levels"]["L1"]["pan"]["mean"] == pytest.approx(7.0 / 3.0)
    assert t["tilt_levels"]["L3"]["tilt"]["median"] == pytest.approx(9.0)  # indices 4, 5
    assert t["tilt_levels"]["L3"]["pan"]["n"] == 1 and t["tilt_levels"]["L3"]["pan"]["zenith_left_out"] == 1
    assert t["tilt_levels"]["L3"]["pan"]["mean"] == pytest.approx(4.0)     # index 4 only
    # front: indices 0, 6 (index 4 has tilt 75, excluded); right: 1, 7
    assert t["pan_levels"]["front"]["direction"]["n"] == 2
    assert t["pan_levels"]["front"]["direction"]["mean"] == pytest.approx(3.5)
    assert t["pan_levels"]["right"]["pan"]["median"] == pytest.approx(4.0)
    assert t["pan_levels"]["back"]["pan"]["n"] == 1  # index 5 has tilt 90, excluded
    with pytest.raises(ValueError):
        m.error_tables(errors, tilt[:-1], pan)


def test_format_tables_contains_numbers():
    errors, tilt, pan = _example()
    text = m.format_tables(m.error_tables(errors, tilt, pan))
    assert text.count("Table ") == 3
    assert "| Pan (tilt < 90) | Zenith left out | Tilt | Direction | Colour | Pan, all lights |" in text
    assert "| Mean | 8 | 3.29 | 1 | 7.00 | 4.00 | 1.25 | 3.50 |" in text
    assert "| Median | 8 | 3.00 | 1 | 7.00 | 4.00 | 1.25 | 3.50 |" in text
    assert "| L1 [30, 50) | Mean | 3 | 2.33 | 0 | 4.67 | 2.83 | 1.25 | 2.33 |" in text
    assert "| L3 [70, 90] | Mean | 2 | 4.00 | 1 | 9.00 | 5.00 | 1.25 | 4.50 |" in text
    assert "| front [315, 45) | Median | 2 | 3.00 | 0 | 6.00 | 3.50 | 1.25 | 3.00 |" in text
    assert "L3 [70, 90]" in text
    extra = m.format_tables(m.error_tables(errors, tilt, pan), stats=("trimean", "worst25"))
    assert "Trimean" in extra and "Worst 25%" in extra and "| Mean |" not in extra
    empty = {k: v[:0] for k, v in errors.items()}
    assert "n/a" in m.format_tables(m.error_tables(empty, tilt[:0], pan[:0]))
    with pytest.raises(ValueError):
        m.format_tables(m.error_tables(errors, tilt, pan), stats=("average",))


def test_table_pan_leaves_out_the_zenith_lights_and_counts_them():
    """A constructed set, one light at each SID2 tilt 30, 35, ..., 90 (13 lights) and a second
    at the zenith: each light below the zenith is predicted d = tilt / 10 degrees of pan off,
    the zenith lights at an arbitrary pan. In closed form the table's pan is the mean of d
    over the 12 lights below the zenith, (3 + 3.5 + ... + 8.5) / 12 = 5.75, with 2 zenith
    lights left out; the all-lights column is (12 x 5.75 + e_z1 + e_z2) / 14."""
    tilt = np.array(list(np.arange(30.0, 91.0, 5.0)) + [90.0])
    pan_gt = np.linspace(0.0, 330.0, tilt.size)
    d = tilt / 10.0
    pan_pred = np.where(tilt < 90.0, pan_gt + d, pan_gt + np.array([0.0] * 12 + [150.0, -100.0]))
    rgb = np.ones((tilt.size, 3))
    e = m.light_errors(pan_pred, tilt, rgb, pan_gt, tilt, rgb)
    assert e["direction"][tilt == 90.0] == pytest.approx([0.0, 0.0], abs=1e-6)   # no pan at the zenith
    t = m.error_tables(e, tilt, pan_gt)["overall"]
    assert t["pan"]["zenith_left_out"] == 2 and t["pan"]["n"] == 12
    assert t["pan"]["mean"] == pytest.approx(np.arange(3.0, 8.6, 0.5).mean(), abs=1e-9) == pytest.approx(5.75)
    assert t["pan_all"]["n"] == 14 and t["pan_all"]["mean"] == pytest.approx((12 * 5.75 + 150.0 + 100.0) / 14)
    assert t["tilt"]["n"] == t["direction"]["n"] == t["colour"]["n"] == 14
    table1 = m.format_tables(m.error_tables(e, tilt, pan_gt), only_table1=True)
    assert "| Mean | 14 | 5.75 | 2 | 0.00 | " in table1
    values = m.table_values(e, tilt)
    assert values["pan"].size == 12 and values["pan_all"].size == 14 and list(values)[-1] == "pan_all"
    # a set without zenith lights: nothing left out, the two pan columns agree
    below = tilt < 90.0
    t2 = m.error_tables({k: v[below] for k, v in e.items()}, tilt[below], pan_gt[below])["overall"]
    assert t2["pan"]["zenith_left_out"] == 0 and t2["pan"]["mean"] == t2["pan_all"]["mean"]
    # only zenith lights: pan has no value, the count says why
    at = ~below
    t3 = m.error_tables({k: v[at] for k, v in e.items()}, tilt[at], pan_gt[at])["overall"]
    assert t3["pan"]["n"] == 0 and t3["pan"]["zenith_left_out"] == 2 and np.isnan(t3["pan"]["mean"])
    assert "| Mean | 2 | n/a | 2 |" in m.format_tables(m.error_tables({k: v[at] for k, v in e.items()}, tilt[at],
                                                                      pan_gt[at]), only_table1=True)


def test_pan_by_tilt_shows_the_pan_error_growing_towards_the_zenith():
    """A fixed direction error of 2 deg along the light's parallel is a pan error of
    acos((cos 2 - sin^2 t) / cos^2 t): 2.31 at tilt 30, 22.9 at 85. The rows recover it per
    tilt step (checked against direction_error_deg), and their shares add up to the mean."""
    rng = np.random.default_rng(1)
    tilt = rng.choice(np.arange(30.0, 90.0, 5.0), size=3000) + rng.uniform(-2.4, 2.4, 3000)
    step = np.round(tilt / 5.0) * 5.0
    t = np.radians(tilt)
    dpan = np.degrees(np.arccos((np.cos(np.radians(2.0)) - np.sin(t) ** 2) / np.cos(t) ** 2))
    pan = rng.uniform(0, 360, tilt.size)
    assert m.direction_error_deg(pan + dpan, tilt, pan, tilt) == pytest.approx(np.full(tilt.size, 2.0), abs=1e-6)
    err = m.pan_error_deg(pan + dpan, pan)
    rows = m.pan_by_tilt(err, tilt)
    assert [r["tilt_deg"] for r in rows] == sorted(set(step.tolist()))
    for r in rows:
        assert r["n"] == (step == r["tilt_deg"]).sum()
        assert r["mean"] == pytest.approx(err[step == r["tilt_deg"]].mean())
    means = [r["mean"] for r in rows]
    assert means == sorted(means) and means[0] < 2.5 and means[-1] > 15.0
    assert sum(r["share"] for r in rows) == pytest.approx(err.mean(), rel=1e-12)
    table = m.format_pan_by_tilt(rows)
    assert table.count("\n| 85 |") == 1 and f"{rows[-1]['mean']:.2f}" in table
    assert m.format_pan_by_tilt(m.pan_by_tilt([], [])) == ""
    with pytest.raises(ValueError):
        m.pan_by_tilt(err, tilt[:-1])
    with pytest.raises(ValueError):
        m.pan_by_tilt(err, tilt, step_deg=0.0)


def test_pan_where_defined_separates_the_zenith_guesses():
    """SID2 tilts (30-90, step 5): below the zenith the pan errors are half-normal with
    sigma 3 (mean 3 sqrt(2/pi)); at the zenith a predictor can only guess, |wrap180| of a
    uniform angle, mean 90. The split recovers both, and the two parts make the overall mean."""
    rng = np.random.default_rng(0)
    tilt = rng.choice(np.arange(30.0, 91.0, 5.0), size=20000)
    at = tilt == 90.0
    err = np.where(at, m.pan_error_deg(rng.uniform(0, 360, tilt.size), 0.0), np.abs(rng.normal(0, 3, tilt.size)))
    d = m.pan_where_defined(err, tilt)
    assert d["zenith"]["n"] == at.sum() and d["below_zenith"]["n"] == (~at).sum()
    assert abs(d["zenith"]["mean"] - 90.0) < 3.0
    assert abs(d["below_zenith"]["mean"] - 3.0 * np.sqrt(2.0 / np.pi)) < 0.1
    parts = d["zenith"]["mean"] * d["zenith"]["n"] + d["below_zenith"]["mean"] * d["below_zenith"]["n"]
    assert parts / tilt.size == pytest.approx(err.mean(), rel=1e-12)
    line = m.format_pan_where_defined(d)
    assert f"{d['below_zenith']['mean']:.2f}" in line and f"{at.sum()} of {tilt.size}" in line
    assert f"over all {tilt.size} lights: mean {err.mean():.2f}" in line
    assert m.format_pan_where_defined(m.pan_where_defined(err[~at], tilt[~at])) == ""
    with pytest.raises(ValueError):
        m.pan_where_defined(err, tilt[:-1])

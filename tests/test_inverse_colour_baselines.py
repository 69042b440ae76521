"""Tests of relight.inverse.colour_baselines: closed forms on synthetic linear images."""
from __future__ import annotations

import json

import numpy as np
import pytest

from relight.inverse import colour_baselines as cb
from relight.metrics import colour_error_deg

EXACT_DEG = 1e-6        # angular error of an exact estimate (float64 round-off)
LIGHT = np.array([0.9, 0.6, 0.35])


def grey_world_image(seed=0, size=24):
    """A scene of achromatic surfaces (random greys) under the light ``LIGHT``."""
    grey = np.random.default_rng(seed).uniform(0.05, 0.95, (size, size, 1))
    return grey * LIGHT


def test_gray_world_recovers_light_on_grey_world():
    # every pixel is grey * LIGHT, so the channel means are mean(grey) * LIGHT
    assert colour_error_deg(cb.gray_world(grey_world_image()), LIGHT) < EXACT_DEG


def test_gray_world_is_channel_mean():
    img = np.random.default_rng(1).uniform(0, 1, (8, 9, 3))
    mean = img.reshape(-1, 3).mean(0)
    np.testing.assert_allclose(cb.gray_world(img), mean / np.linalg.norm(mean), rtol=1e-12)


def test_white_patch_is_channel_max():
    img = np.random.default_rng(2).uniform(0, 1, (8, 9, 3))
    img[3, 4] = [5.0, 0.1, 0.1]   # maxima may sit in different pixels per channel
    img[1, 1] = [0.1, 4.0, 0.1]
    mx = np.array([5.0, 4.0, img[..., 2].max()])
    np.testing.assert_allclose(cb.white_patch(img), mx / np.linalg.norm(mx), rtol=1e-12)


def test_shades_of_gray_limits():
    img = np.random.default_rng(3).uniform(0, 2, (16, 16, 3))
    np.testing.assert_allclose(cb.shades_of_gray(img, p=1), cb.gray_world(img), rtol=1e-12)
    np.testing.assert_allclose(cb.shades_of_gray(img, p=np.inf), cb.white_patch(img), rtol=1e-12)
    # large finite p approaches the max without overflow
    assert colour_error_deg(cb.shades_of_gray(img * 1e30, p=400), cb.white_patch(img)) < 1.0
    assert colour_error_deg(cb.shades_of_gray(grey_world_image(), p=6), LIGHT) < EXACT_DEG


def test_gray_edge_on_ramp():
    # I_c(x, y) = LIGHT_c * (0.2 + 0.03 x + 0.01 y): every channel's gradient is LIGHT_c
    # times the same field, so any linear derivative filter gives magnitudes prop. to LIGHT
    y, x = np.mgrid[0:20, 0:20].astype(np.float64)
    img = (0.2 + 0.03 * x + 0.01 * y)[..., None] * LIGHT
    assert colour_error_deg(cb.gray_edge(img), LIGHT) < EXACT_DEG
    assert colour_error_deg(cb.gray_edge(img, sigma_px=0), LIGHT) < EXACT_DEG


def test_gray_edge_ignores_flat_colour_offset():
    # a uniform coloured veil has no edges: Gray Edge sees only the grey ramp's light
    y, x = np.mgrid[0:20, 0:20].astype(np.float64)
    img = (0.2 + 0.03 * x)[..., None] * LIGHT + np.array([0.0, 0.5, 0.0])
    assert colour_error_deg(cb.gray_edge(img), LIGHT) < EXACT_DEG
    assert colour_error_deg(cb.gray_world(img), LIGHT) > 5.0


def test_bad_inputs():
    with pytest.raises(cb.ColourBaselineError, match="shape"):
        cb.gray_world(np.zeros((4, 4)))
    with pytest.raises(cb.ColourBaselineError, match="no signal"):
        cb.white_patch(np.zeros((4, 4, 3)))
    with pytest.raises(cb.ColourBaselineError, match="no signal"):
        cb.gray_edge(np.ones((8, 8, 3)))     # flat image: no edges
    with pytest.raises(cb.ColourBaselineError, match="finite"):
        cb.gray_world(np.full((4, 4, 3), np.nan))
    with pytest.raises(cb.ColourBaselineError, match="valid: gray-world"):
        cb.estimate("retinex", np.ones((4, 4, 3)))
    # NaN pixels are skipped, not propagated
    img = grey_world_image()
    img[0, 0] = np.nan
    assert colour_error_deg(cb.gray_world(img), LIGHT) < EXACT_DEG


def test_colour_predictions_round_trip(tmp_path):
    path = tmp_path / "gw.json"
    cb.write_colour_predictions(path, [{"id": "a", "rgb": [1.0, 2.0, 2.0]}], dataset="d", method="gray-world")
    doc = json.loads(path.read_text())
    assert doc["colour_only"] is True and doc["format"] == "relight.predictions/v1"
    got = cb.read_colour_predictions(path)
    np.testing.assert_allclose(got["a"], [1 / 3, 2 / 3, 2 / 3], rtol=1e-12)
    with pytest.raises(cb.PredictionsError, match="non-negative"):
        cb.write_colour_predictions(path, [{"id": "a", "rgb": [0.0, 0.0, 0.0]}])
    with pytest.raises(cb.PredictionsError, match="duplicate"):
        cb.write_colour_predictions(path, [{"id": "a", "rgb": [1, 1, 1]}, {"id": "a", "rgb": [1, 1, 1]}])
    assert cb.read_colour_predictions(path)["a"] is not None  # failed writes left the file intact

"""Image metrics on linear images: closed forms for RMSE/PSNR/SSIM, identities, bad input."""
import math

import numpy as np
import pytest

from relight.verify import imagemetrics as im

EXACT_TOL = 1e-12
SSIM_TOL = 1e-9


def _random_image(seed=0, shape=(24, 20, 3)):
    return np.random.default_rng(seed).uniform(0.0, 1.0, shape)


def test_identical_images():
    a = _random_image()
    assert im.rmse(a, a) == 0.0
    assert im.psnr(a, a) == math.inf
    assert im.ssim(a, a) == pytest.approx(1.0, abs=SSIM_TOL)


def test_rmse_psnr_closed_form():
    # constant offset 0.1 everywhere: RMSE = 0.1, PSNR = 20 log10(1 / 0.1) = 20 dB
    a = np.zeros((8, 8, 3))
    b = a + 0.1
    assert im.rmse(a, b) == pytest.approx(0.1, abs=EXACT_TOL)
    assert im.psnr(a, b) == pytest.approx(20.0, abs=1e-9)
    # peak 2: 20 log10(2 / 0.1) = 26.0206 dB
    assert im.psnr(a, b, peak=2.0) == pytest.approx(20.0 * math.log10(20.0), abs=1e-9)
    # half the pixels differ by 0.2: RMSE = sqrt(0.5 * 0.04)
    c = a.copy()
    c[:4] = 0.2
    assert im.rmse(a, c) == pytest.approx(math.sqrt(0.02), abs=EXACT_TOL)


def test_ssim_constant_images_closed_form():
    # Constant images x and y have zero variance: SSIM = (2xy + C1) / (x^2 + y^2 + C1)
    # (the contrast-structure term is C2 / C2 = 1); Wang et al. 2004 eq. 13.
    x, y = 0.3, 0.5
    c1 = (im.SSIM_K1 * 1.0) ** 2
    expected = (2 * x * y + c1) / (x * x + y * y + c1)
    got = im.ssim(np.full((16, 16, 3), x), np.full((16, 16, 3), y))
    assert got == pytest.approx(expected, abs=SSIM_TOL)


def test_ssim_properties():
    a = _random_image(1)
    noisy = a + np.random.default_rng(2).normal(0, 0.05, a.shape)
    noisier = a + np.random.default_rng(3).normal(0, 0.2, a.shape)
    s1, s2 = im.ssim(a, noisy), im.ssim(a, noisier)
    assert 1.0 > s1 > s2 > -1.0
    assert im.ssim(noisy, a) == pytest.approx(s1, abs=SSIM_TOL)  # symmetric
    assert im.ssim(a[..., 0], noisy[..., 0]) == pytest.approx(
        float(np.mean(im.ssim_map(a, noisy)[..., 0])), abs=SSIM_TOL)  # channels independent


def test_image_errors_keys():
    a = _random_image(4)
    e = im.image_errors(a, a * 0.9)
    assert set(e) == {"rmse", "psnr_db", "ssim"}
    assert e["psnr_db"] == pytest.approx(20 * math.log10(1.0 / e["rmse"]))


@pytest.mark.parametrize("a, b", [
    (np.zeros((4, 4, 3)), np.zeros((4, 5, 3))),           # shape mismatch
    (np.zeros((4,)), np.zeros((4,))),                      # not an image
    (np.full((4, 4), np.nan), np.zeros((4, 4))),           # non-finite
])
def test_bad_input(a, b):
    with pytest.raises(ValueError):
        im.rmse(a, b)


def test_bad_peak():
    with pytest.raises(ValueError):
        im.psnr(np.zeros((4, 4)), np.ones((4, 4)), peak=0.0)

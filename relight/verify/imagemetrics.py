"""Image differences on linear images: RMSE, PSNR and SSIM.

All functions take two ``(H, W)`` or ``(H, W, C)`` arrays of linear (scene-referred)
values, compared as they are (no tone mapping, no gamma). Linear relight renders are
exposure-normalised so that a white diffuse surface facing the light is near 1, so the
default ``peak`` / ``data_range`` is 1.0 ("display white").

SSIM is Wang et al. 2004 ("Image quality assessment: from error visibility to
structural similarity", IEEE TIP 13(4)), eq. 13, with its usual settings: a Gaussian
window of standard deviation 1.5 px truncated at 3.5 sigma (11 x 11), K1 = 0.01,
K2 = 0.03, ``C1 = (K1 L)^2``, ``C2 = (K2 L)^2``; local statistics use the sample
(unbiased) covariance, borders are reflected, and the map is averaged over pixels
and channels.
"""
from __future__ import annotations

__all__ = [
    "SSIM_SIGMA_PX", "SSIM_TRUNCATE", "SSIM_K1", "SSIM_K2", "DEFAULT_PEAK", "rmse", "psnr", "ssim_map", "ssim",
    "image_errors",
]

import math

import numpy as np

SSIM_SIGMA_PX = 1.5
SSIM_TRUNCATE = 3.5   # window radius in sigmas: 1.5 * 3.5 -> radius 5 (11 x 11)
SSIM_K1 = 0.01
SSIM_K2 = 0.03
DEFAULT_PEAK = 1.0


def _pair(a, b) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"images must have the same shape, got {a.shape} and {b.shape}")
    if a.ndim not in (2, 3) or a.size == 0:
        raise ValueError(f"expected (H, W) or (H, W, C) images, got shape {a.shape}")
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise ValueError("images must hold finite values")
    return a, b


def rmse(a, b) -> float:
    """Root mean square difference over all pixels and channels (same units as the images)."""
    a, b = _pair(a, b)
    return float(np.sqrt(np.mean((a - b) ** 2)))


def psnr(a, b, peak: float = DEFAULT_PEAK) -> float:
    """Peak signal-to-noise ratio in dB: ``20 log10(peak / RMSE)``; ``inf`` if identical.

    ``peak`` is the value taken as full scale (linear units, default 1.0).
    """
    if not peak > 0:
        raise ValueError(f"peak must be positive, got {peak}")
    e = rmse(a, b)
    return math.inf if e == 0.0 else 20.0 * math.log10(peak / e)


def _blur(x: np.ndarray, sigma_px: float) -> np.ndarray:
    """Gaussian-weighted local mean over the two image axes (channels kept apart)."""
    from scipy.ndimage import gaussian_filter
    sigmas = (sigma_px, sigma_px) + (0.0,) * (x.ndim - 2)
    return gaussian_filter(x, sigma=sigmas, mode="reflect", truncate=SSIM_TRUNCATE)


def ssim_map(a, b, data_range: float = DEFAULT_PEAK, sigma_px: float = SSIM_SIGMA_PX) -> np.ndarray:
    """Per-pixel SSIM (Wang et al. 2004, eq. 13) with a Gaussian window; shape of the input.

    ``data_range`` is L in ``C1 = (0.01 L)^2``, ``C2 = (0.03 L)^2`` (linear units).
    """
    a, b = _pair(a, b)
    if not data_range > 0:
        raise ValueError(f"data_range must be positive, got {data_range}")
    c1 = (SSIM_K1 * data_range) ** 2
    c2 = (SSIM_K2 * data_range) ** 2
    radius = int(SSIM_TRUNCATE * sigma_px + 0.5)
    w = np.exp(-0.5 * (np.arange(-radius, radius + 1) / sigma_px) ** 2)
    w2 = np.outer(w, w) / np.sum(w) ** 2
    unbias = 1.0 / (1.0 - np.sum(w2 ** 2))  # sample covariance with normalised weights
    mu_a, mu_b = _blur(a, sigma_px), _blur(b, sigma_px)
    var_a = (_blur(a * a, sigma_px) - mu_a ** 2) * unbias
    var_b = (_blur(b * b, sigma_px) - mu_b ** 2) * unbias
    cov_ab = (_blur(a * b, sigma_px) - mu_a * mu_b) * unbias
    return ((2 * mu_a * mu_b + c1) * (2 * cov_ab + c2)
            / ((mu_a ** 2 + mu_b ** 2 + c1) * (var_a + var_b + c2)))


def ssim(a, b, data_range: float = DEFAULT_PEAK, sigma_px: float = SSIM_SIGMA_PX) -> float:
    """Mean SSIM in [-1, 1] (1 for identical images); see :func:`ssim_map`."""
    return float(np.mean(ssim_map(a, b, data_range, sigma_px)))


def image_errors(a, b, peak: float = DEFAULT_PEAK) -> dict[str, float]:
    """``{"rmse", "psnr_db", "ssim"}`` between two linear images (``peak`` as in :func:`psnr`)."""
    return {"rmse": rmse(a, b), "psnr_db": psnr(a, b, peak), "ssim": ssim(a, b, peak)}

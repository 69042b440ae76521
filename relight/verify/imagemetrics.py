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
    "fitted_scale", "light_scores",
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


# --- scores that mean the same for every kind of light prediction --------------------
# Used by compare after it fits one global scale (a map's exposure is arbitrary).
RGB_ANGLE_MIN_NORM = 1e-6   # pixels darker than this x the brightest are left out of the angle


def fitted_scale(a, b) -> float:
    """The one global scale ``s`` minimising ``sum (s b - a)^2`` over all pixels and
    channels: ``<a, b> / <b, b>`` (1 for a black ``b``)."""
    a, b = _pair(a, b)
    bb = float(np.sum(b * b))
    return float(np.sum(a * b) / bb) if bb > 0 else 1.0


def light_scores(a, b) -> dict[str, float]:
    """Scores of a re-render ``b`` against the original ``a`` (linear ``(H, W, 3)``):

    * ``scale``: :func:`fitted_scale`;
    * ``rel_rmse``: ``RMSE(scale b, a) / mean(a)`` (the noise calibration's relative RMSE);
    * ``si_rmse``: the same with one least-squares scale per channel (insensitive to a
      global colour cast as well as exposure: what is left is shading and shadows);
    * ``rgb_angle_deg``: mean over pixels (both brighter than ``RGB_ANGLE_MIN_NORM`` x
      the brightest) of the angle between their RGB vectors, degrees (LeGendre et al.
      2019; scale invariant per pixel).
    """
    a, b = _pair(a, b)
    mean = float(np.mean(a))
    s = fitted_scale(a, b)
    rel = float(np.sqrt(np.mean((s * b - a) ** 2)) / mean) if mean > 0 else float("nan")
    bb = np.sum(b * b, axis=(0, 1))
    s_c = np.where(bb > 0, np.sum(a * b, axis=(0, 1)) / np.where(bb > 0, bb, 1.0), 1.0)
    si = float(np.sqrt(np.mean((s_c * b - a) ** 2)) / mean) if mean > 0 else float("nan")
    na, nb = np.linalg.norm(a, axis=-1), np.linalg.norm(b, axis=-1)
    live = (na > RGB_ANGLE_MIN_NORM * na.max()) & (nb > RGB_ANGLE_MIN_NORM * max(nb.max(), 1e-300))
    if live.any():
        cos = np.sum(a * b, axis=-1)[live] / (na[live] * nb[live])
        angle = float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).mean())
    else:
        angle = float("nan")
    return {"scale": s, "rel_rmse": rel, "si_rmse": si, "rgb_angle_deg": angle}

"""Where a light lies from the pixels it clipped.

A light far above an 8-bit image's clip level clips every pixel whose filter its image
reaches, however little of it; with a narrow pixel filter (a box one pixel wide,
Mitsuba's and ``relight export-blender``'s; Blackman-Harris 1.5 px, Blender's default)
the pixels beside stay at their background. Which pixels clip is then all the image says
about where the light is, and the light's image on a mirror sphere is mostly a pixel or
two across: the clipped pixels' centroid is off by a median 0.2 px, a degree on a
20 px sphere.

What a light predicts does better. Its image on the sphere is a small ellipse whose
shape the sphere's geometry gives (the mirror map's Jacobian at the highlight: a light
of angular radius ``t`` covers the pixel offsets ``d`` with ``d^T M d < t^2``) and whose
size, the light's angular size, is not known. A pixel clips with probability
``1 - (1 - a)^N`` when the ellipse covers a share ``a`` of its filter (``N`` samples,
:data:`SAMPLES`: a renderer's stratified samples leave a pixel the light reaches by a few
percent unclipped only rarely; the filter one of :data:`PIXEL_FILTERS`). The light's
centre is the mean over the centres, sizes and filters that clip the observed pixels
and leave the others, under a flat prior: the posterior mean. A set of clipped pixels
symmetric under a half turn (a rectangle) keeps its centre; elsewhere (three pixels of
four, an L) the light lies nearer the middle pixel than their centroid says. On the
harder probe set's Cycles renders (820 scenes, the true circle) the median highlight
error went 1.04 -> 0.98 deg (three clipped pixels: 0.21 -> 0.17 px); knowing each
light's true size gives 0.95, the binary image's floor (``bench_probe.py --floor``;
docs/probe-history.md, nineteenth round).
"""
from __future__ import annotations

__all__ = ["SUBSTEPS", "SIZES", "PIXEL_FILTERS", "BH_SPAN_PX", "BH_COEFFICIENTS", "SAMPLES", "OUTLIER", "SEARCH_PX", "footprint_centre"]

import math

import numpy as np
from scipy import ndimage

SUBSTEPS = 16                     # fine grid: steps per pixel for centres and coverage
SIZES = 32                        # light sizes tried, from 0.05 px to the clipped area's radius + 1.5 px
PIXEL_FILTERS = ("box", "blackman-harris")   # a box one pixel wide (Mitsuba's, export-blender's);
                                  # Blackman-Harris 1.5 px, which Cycles spreads over 3 px (Blender's default)
BH_SPAN_PX = 3.0                  # the span Cycles gives Blackman-Harris 1.5 px (its filter table)
BH_COEFFICIENTS = (0.35875, -0.48829, 0.14128, -0.01168)   # the window: sum_j a_j cos(2 pi j u), u in [0, 1]
SAMPLES = 1000                    # a pixel covered by a share a stays unclipped with probability (1 - a)^N
OUTLIER = 1e-4                    # ... and any pixel's observation is at least this likely (noise, a stray hit)
SEARCH_PX = 1.0                   # centres within this of the clipped pixels' centroid, in x and y


def _blackman_harris(span_px: float = BH_SPAN_PX) -> np.ndarray:
    """Cycles' Blackman-Harris pixel filter (1-D; the filter is separable) over its span,
    on the fine grid, summing to 1."""
    n = int(round(span_px * SUBSTEPS / 2))
    u = np.arange(-n, n + 1) / (2 * n) + 0.5
    w = sum(a * np.cos(2 * np.pi * j * u) for j, a in enumerate(BH_COEFFICIENTS))
    return w / w.sum()


def _box() -> np.ndarray:
    """A box one pixel wide on the fine grid, centred: the trapezoid rule over
    :data:`SUBSTEPS` steps (an even-sized uniform filter would sit half a step off centre)."""
    w = np.ones(SUBSTEPS + 1)
    w[[0, -1]] = 0.5
    return w / SUBSTEPS


def _coverages(metric: np.ndarray, sizes: np.ndarray, half_px: int) -> list[np.ndarray]:
    """Share of a pixel's filter that the ellipse ``d^T metric d < size^2`` centred at the
    origin covers, for each of ``sizes`` and pixels centred on a fine grid of offsets
    ``-half_px .. half_px`` px in :data:`SUBSTEPS` steps: one ``(len(sizes), n, n)`` array
    for each of :data:`PIXEL_FILTERS`."""
    g = np.arange(-half_px * SUBSTEPS, half_px * SUBSTEPS + 1) / SUBSTEPS
    x, y = np.meshgrid(g, g)
    q = metric[0, 0] * x * x + 2.0 * metric[0, 1] * x * y + metric[1, 1] * y * y
    inside = (q[None] < (sizes * sizes)[:, None, None]).astype(np.float64)
    kernels = {"box": _box, "blackman-harris": _blackman_harris}
    return [ndimage.convolve1d(ndimage.convolve1d(inside, w, axis=1, mode="constant"), w, axis=2, mode="constant")
            for w in (kernels[f]() for f in PIXEL_FILTERS)]


def footprint_centre(clipped: np.ndarray, observed: np.ndarray, metric: np.ndarray,
                     size_px: float | None = None) -> tuple[float, float]:
    """Posterior-mean centre ``(x, y)`` (pixel coordinates, centres at +0.5) of a light's
    elliptical image from which pixels clipped.

    Args:
        clipped: ``(H, W)`` bool, the light's clipped pixels (at least one).
        observed: ``(H, W)`` bool, the pixels whose state counts: the clipped ones and
            the unclipped ones around them. Others (another clipped structure beside it,
            the rim) say nothing.
        metric: ``(2, 2)`` symmetric positive definite, the ellipse's shape in pixel
            offsets (only its shape matters: it is scaled to unit determinant).
        size_px: the light's size if known (the radius of the disc of the ellipse's area,
            pixels): the floor of what the clipped pixels say (`bench_probe.py --floor`).
    """
    clipped = np.asarray(clipped, bool)
    if not clipped.any():
        raise ValueError("footprint_centre needs at least one clipped pixel")
    observed = np.asarray(observed, bool) | clipped
    m = np.asarray(metric, np.float64)
    m = m / math.sqrt(np.linalg.det(m))
    ys, xs = np.nonzero(observed)
    hit = clipped[ys, xs]
    cy, cx = np.nonzero(clipped)
    # the clipped pixels' centroid on the fine grid through the pixel centres, so that every
    # offset from a candidate centre to a pixel centre is a whole number of fine steps
    start = tuple(float(np.round((c.mean() + 0.5) * SUBSTEPS) / SUBSTEPS) for c in (cx, cy))
    search = int(round(SEARCH_PX * SUBSTEPS))
    steps = np.arange(-search, search + 1)
    # offsets of every observed pixel's centre from every candidate centre, in fine steps
    ox = np.rint((xs + 0.5 - start[0]) * SUBSTEPS).astype(int)[:, None, None] - steps[None, None, :]
    oy = np.rint((ys + 0.5 - start[1]) * SUBSTEPS).astype(int)[:, None, None] - steps[None, :, None]
    top = math.sqrt(clipped.sum() / math.pi) + 1.5
    sizes = np.linspace(0.05, top, SIZES) if size_px is None else np.array([float(size_px)])
    # the coverage is needed out to the farthest offset plus the support: the grid ends there
    far = max(int(np.abs(ox).max()), int(np.abs(oy).max())) / SUBSTEPS
    half_px = int(math.ceil(far + BH_SPAN_PX / 2)) + 1
    reach = half_px * SUBSTEPS
    logs = []
    for coverage in _coverages(m, sizes, half_px):
        a = coverage[:, oy + reach, ox + reach]   # (sizes, pixels, y, x)
        log_unclipped = SAMPLES * np.log1p(-np.clip(a, 0.0, 1.0 - 1e-12))
        p = np.where(hit[None, :, None, None], -np.expm1(log_unclipped), np.exp(log_unclipped))
        logs.append(np.log(np.maximum(p, OUTLIER)).sum(1))
    logs = np.concatenate(logs)
    w = np.exp(logs - logs.max()).sum(0)
    return (float(start[0] + (w.sum(0) * steps).sum() / SUBSTEPS / w.sum()),
            float(start[1] + (w.sum(1) * steps).sum() / SUBSTEPS / w.sum()))

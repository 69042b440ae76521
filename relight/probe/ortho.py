"""The paper's sphere procedure: light direction from a chrome sphere's highlight and
light colour (and a shading-based direction) from a diffuse sphere.

Paper, Experiment 2: "the angle of incident light is equal to the angle of outgoing
light at the specular highlight on a spherical ball" (after Schnieders et al.), and
"the color of the light is obtained from the average color of the diffuse sphere".

Convention: directions come back in the camera frame of :mod:`relight.frames`
(x to the image right, y to the image top, z toward the camera), pointing from the
sphere toward the light (``to_light``). The projection is taken as orthographic (a
far camera), so the view direction is +z everywhere on the sphere.
Images are linear RGB ``(H, W, 3)``; masks are boolean ``(H, W)``.
"""
from __future__ import annotations

__all__ = [
    "HIGHLIGHT_FRACTION", "LIT_FRACTION", "RIM_MARGIN", "Circle", "fit_circle", "sphere_normals",
    "chrome_light_direction", "diffuse_light",
]

from dataclasses import dataclass

import numpy as np

from relight.errors import ProbeError

HIGHLIGHT_FRACTION = 0.98    # pixels at >= 98% of the chrome sphere's peak form the highlight
LIT_FRACTION = (0.25, 0.95)  # diffuse pixels used for the shading fit, as fractions of the peak
RIM_MARGIN = 0.9             # ignore the outer 10% of the radius (blurred, grazing normals)


@dataclass(frozen=True)
class Circle:
    """A sphere's outline in pixels: centre column/row and radius."""
    cx: float
    cy: float
    r: float


def fit_circle(mask: np.ndarray) -> Circle:
    """Least-squares (Kasa) circle through the boundary pixels of a boolean mask; robust
    to a mask cut by a stand or the image border, unlike the area-based radius."""
    mask = np.asarray(mask, bool)
    if mask.ndim != 2 or mask.sum() < 20:
        raise ProbeError("sphere mask is empty or not 2-D")
    inner = mask.copy()
    inner[1:-1, 1:-1] = mask[1:-1, 1:-1] & mask[:-2, 1:-1] & mask[2:, 1:-1] & mask[1:-1, :-2] & mask[1:-1, 2:]
    rows, cols = np.nonzero(mask & ~inner)
    # exclude border pixels of the image itself (a cut, not the sphere's outline)
    h, w = mask.shape
    keep = (rows > 0) & (rows < h - 1) & (cols > 0) & (cols < w - 1)
    x, y = cols[keep] + 0.5, rows[keep] + 0.5
    a = np.stack([x, y, np.ones_like(x)], 1)
    b = x * x + y * y
    (c0, c1, c2), *_ = np.linalg.lstsq(a, b, rcond=None)
    cx, cy = c0 / 2.0, c1 / 2.0
    r = float(np.sqrt(c2 + cx * cx + cy * cy))
    if not np.isfinite(r) or r < 3:
        raise ProbeError("could not fit a circle to the sphere mask")
    return Circle(float(cx), float(cy), r)


def sphere_normals(shape: tuple[int, int], circle: Circle) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame unit normals ``(H, W, 3)`` of an orthographic sphere and the mask of
    pixels it covers (within :data:`RIM_MARGIN` of its radius)."""
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]] + 0.5
    nx = (cols - circle.cx) / circle.r
    ny = -(rows - circle.cy) / circle.r       # image rows go down, camera y goes up
    rho2 = nx * nx + ny * ny
    inside = rho2 < RIM_MARGIN ** 2
    nz = np.sqrt(np.clip(1.0 - rho2, 0.0, 1.0))
    return np.stack([nx, ny, nz], -1), inside


def chrome_light_direction(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Direction to the light (camera frame, unit) from a mirror sphere's highlight.

    The highlight's normal n bisects the view direction v = +z and the light: the
    light direction is the mirror reflection ``l = 2 (n . v) n - v``.
    """
    circle = fit_circle(mask)
    lum = np.asarray(image, np.float64).mean(-1) if np.ndim(image) == 3 else np.asarray(image, np.float64)
    _, inside = sphere_normals(lum.shape, circle)
    region = inside & np.asarray(mask, bool)
    peak = lum[region].max() if region.any() else 0.0
    if peak <= 0:
        raise ProbeError("no highlight on the chrome sphere")
    sel = region & (lum >= HIGHLIGHT_FRACTION * peak)
    rows, cols = np.nonzero(sel)
    w = lum[sel]
    cx, cy = np.average(cols + 0.5, weights=w), np.average(rows + 0.5, weights=w)
    nx, ny = (cx - circle.cx) / circle.r, -(cy - circle.cy) / circle.r
    n = np.array([nx, ny, np.sqrt(max(0.0, 1.0 - nx * nx - ny * ny))])
    n /= np.linalg.norm(n)
    v = np.array([0.0, 0.0, 1.0])
    return 2.0 * n.dot(v) * n - v


def diffuse_light(image: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Light direction (camera frame, unit) and colour (unit-norm RGB) from a diffuse sphere.

    Direction: Lambert shading plus a constant ambient term, ``I = rho max(0, n . l) + a``,
    is linear in ``(b = rho l, a)`` on lit pixels, so least squares over pixels between
    :data:`LIT_FRACTION` of the peak (away from the terminator and from clipping) gives
    ``l = b / |b|``. The ambient term absorbs light bounced from the surroundings (on the
    real gray ball it brings the median error from 12 to 4 degrees).
    Colour: the mean RGB of those pixels (the paper's average colour), unit-normalised.
    """
    img = np.asarray(image, np.float64)
    if img.ndim != 3 or img.shape[2] != 3:
        raise ProbeError(f"expected an (H, W, 3) image, got shape {img.shape}")
    circle = fit_circle(mask)
    normals, inside = sphere_normals(img.shape[:2], circle)
    lum = img.mean(-1)
    region = inside & np.asarray(mask, bool)
    peak = np.percentile(lum[region], 99.5) if region.any() else 0.0
    if peak <= 0:
        raise ProbeError("the diffuse sphere is black")
    lit = region & (lum > LIT_FRACTION[0] * peak) & (lum < LIT_FRACTION[1] * peak)
    if lit.sum() < 20:
        raise ProbeError("too few lit pixels on the diffuse sphere")
    design = np.concatenate([normals[lit], np.ones((int(lit.sum()), 1))], axis=1)
    solution, *_ = np.linalg.lstsq(design, lum[lit], rcond=None)
    b = solution[:3]
    rgb = img[lit].mean(0)
    if np.linalg.norm(b) == 0 or rgb.max() <= 0:
        raise ProbeError("degenerate diffuse sphere shading")
    return b / np.linalg.norm(b), rgb / np.linalg.norm(rgb)

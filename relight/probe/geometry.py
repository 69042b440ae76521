"""The sphere procedure for real cameras: a sphere's 3-D position from its outline, each
pixel's own view ray reflected about the sphere's normal there, and the light's direction
from the chrome sphere's highlight (plus colour and a shading direction from a diffuse one).

Convention (``shared/conventions.md``, "Camera frame"): camera frame x to the image right,
y to the image top, z toward the camera; pixel coordinates x right, y down, origin at the
image's top-left corner, pixel centres at +0.5. The principal point is the image centre.
Directions come back as ``to_light`` unit vectors in the camera frame (from the sphere
toward the light), the light being taken as distant compared with the sphere's radius.

Perspective (a focal length in pixels): the rays tangent to a sphere form a right circular
cone around the direction of its centre, so its outline is a conic (an ellipse, longer
along the line to the image centre, for a sphere off the optical axis). Fitting that cone
to outline points gives the centre's direction ``a`` and angular radius ``alpha``; with the
scale fixed by ``|C| = 1`` the sphere is ``C = a``, ``R = sin(alpha)``. Orthographic (no
focal length): view rays are parallel to -z, the outline is a circle and ``R`` its radius
in pixels.

The mirror map (reflected direction per pixel) of a sphere is close to equal-area (exactly
so for an orthographic view: ``d omega_l = 4 dA / r^2``), so the highlight's direction is
the intensity-weighted mean of the reflected directions over its pixels, weighted also by
each pixel's solid angle of reflected directions; the weights are intensities above the
local background, which makes an anti-aliased or blurred edge count by its coverage and
gives sub-pixel localisation, clipped or not.
"""
from __future__ import annotations

__all__ = [
    "HIGHLIGHT_FRACTION", "TIE_FRACTION", "MAX_LIGHT_SPREAD_DEG", "CORE_RIM_PX", "MERGED_FRACTION",
    "RIM_EXCLUDE_PX", "MAX_RIM_ANGLE_DEG", "ISOLATION_RING_PX", "ISOLATION_LEVEL", "ISOLATION_WEIGHT",
    "SHADING_DOWN_LEVEL", "SHADING_DOWN_WEIGHT", "SHADING_DOWN_GAP", "SHADING_DOWN_REF_PX", "GRAZING_WEIGHT",
    "CLIPS_AT", "UNCLIPPED_STRIKE", "FIREFLY_PX", "FIREFLY_DROP", "FIREFLY_MIN", "FIREFLY_STRIKE",
    "LIT_FRACTION", "DIFFUSE_RIM_FRACTION", "ORTHO_DEPTH",
    "OUTLINE_LOSS_SCALE_PX", "Camera", "Sphere", "sphere_from_cone", "sphere_from_circle", "fit_sphere",
    "mask_outline_points", "sphere_from_mask", "outline_circle", "outline_polygon", "bounding_box", "surface",
    "reflected_direction", "mirror_jacobian", "predict_highlight", "Highlight", "sphere_pixels", "sphere_surface", "usable_pixels", "locate_highlight",
    "highlight_likelihood", "lone_clipped_pixels",
    "diffuse_light",
    "error_budget",
]

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage, optimize
from relight import frames
from relight.errors import ProbeError
from relight.probe import footprint

HIGHLIGHT_FRACTION = 0.5       # highlight candidates: pixels >= half the brightest sphere pixel
TIE_FRACTION = 0.98            # candidates within 2% of the peak count as equally bright (clipping)
MAX_LIGHT_SPREAD_DEG = 8.0     # a blob spreading wider (rms, reflected directions) is not a light alone
CORE_RIM_PX = 3                # a highlight reaching beyond its core grown by 3 px ...
MERGED_FRACTION = 0.1          # ... with over 10% of its pixels touches other bright things
RIM_EXCLUDE_PX = 1.0           # pixels within 1 px of the outline are mixed with the background
MAX_RIM_ANGLE_DEG = 80.0       # normals more than 80 deg from the view ray are too foreshortened
LIT_FRACTION = (0.25, 0.95)    # diffuse pixels used for the shading fit, as fractions of the peak
DIFFUSE_RIM_FRACTION = 0.9     # diffuse fit: normals within 0.9 of the radius (as relight.probe.ortho)
ORTHO_DEPTH = 1.0e4            # z of an orthographic sphere's centre (any value works)
OUTLINE_LOSS_SCALE_PX = 0.5    # robust outline fit: residuals beyond ~0.5 px count less
RIM_BLOB_ANGLE_DEG = 65.0      # a blob whose normals lie beyond this from the view ray is grazing ...
GRAZING_WEIGHT = 0.5           # ... and costs 0.5 score units per share of its pixels there (a lit floor's reflection
                               # stretched along the rim is marked by its elongation and spread too; a light near the rim
                               # is not; 2.0 until the twenty-sixth round)
SMALL_HIGHLIGHT_PX = 12        # an unclipped highlight of at most this many pixels: measured in a soft window
WINDOW_MARGIN_PX = 1.5         # a compact highlight's centroid window: its core's radius plus 1.5 px (lens blur)
AMBIGUITY_MARGIN = 0.5         # two highlight candidates within this score of each other: ambiguous
ISOLATION_RING_PX = (2, 3)     # a candidate's surroundings: pixels 2-3 px from it (past its blur) ...
ISOLATION_LEVEL = 0.1          # ... whose 90th percentile above 10% of the candidate's peak ...
ISOLATION_WEIGHT = 1.5         # ... costs 1.5 score units per unit of that share (a lit surface continues)
SHADING_DOWN_LEVEL = 0.6       # a clipped candidate whose touching pixels stand above its surroundings by 60% of its peak ...
SHADING_DOWN_WEIGHT = 1.5      # ... costs 1.5 score units per unit beyond (a lit object's patch shades down; a light drops at once)
SHADING_DOWN_GAP = 0.3         # ... or by 0.3 more than the clipped candidate that drops most at once (what the image's blur
                               # alone leaves beside a clipped light) ...
SHADING_DOWN_REF_PX = 2        # ... among those of at least 2 pixels (a lone clipped pixel with dark neighbours, a hot
                               # pixel or a speck, says nothing of the blur)
CLIPS_AT = 0.995               # a luminance within 0.5% of the clip level clips
UNCLIPPED_STRIKE = 1.0         # in an image that clips on the sphere, a candidate that does not: one strike
FOOTPRINT_MAX_PX = 30          # a clipped core of at most this many pixels is located by its footprint
                               # (relight.probe.footprint) when its edge is hard: ...
BLUR_TAIL_SHARE = 0.05         # ... the pixels touching it no further, at the median, than 5% of the way
                               # from the level around them to the clip (else a blur surrounds it)
MIRROR_SHARE = 0.25            # beside a clipped core, a pixel whose mirror image holds under 25% of it is not the light
DOWNHILL_MARGIN = 0.05         # a highlight's blur pixel has no neighbour outside it brighter by 5% of its peak
CORE_STRUCTURE = ndimage.generate_binary_structure(2, 1)   # the brightest cores are 4-connected: a light's clipped
                               # disc touching a lit surface's clipped patch at a corner is two candidates, not one
FIREFLY_PX = 2                 # a clipped blob of at most 2 pixels whose touching pixels stay below ...
FIREFLY_DROP = 0.7             # ... 70% of its peak is a lone clipped pixel; an image holding ...
FIREFLY_MIN = 2                # ... at least 2 of them off the chrome sphere shows fireflies or hot pixels ...
FIREFLY_STRIKE = 1.0           # ... so a lone clipped candidate beside a larger clipped core takes a strike
RIM_LIGHT_RATIO = 2.0          # the rim band holds the light when it is this much brighter than the interior (or clips
                               # where the interior does not)


@dataclass(frozen=True)
class Camera:
    """Pinhole camera (``focal_px``) or orthographic camera (``focal_px=None``) of an
    image ``width`` x ``height`` pixels with the principal point at the image centre."""
    width: int
    height: int
    focal_px: float | None = None

    def __post_init__(self):
        if int(self.width) < 1 or int(self.height) < 1:
            raise ProbeError(f"image size must be positive, got {self.width} x {self.height}")
        if self.focal_px is not None and not (math.isfinite(self.focal_px) and self.focal_px > 0):
            raise ProbeError(f"focal length must be a positive number of pixels, got {self.focal_px}")

    @classmethod
    def from_fov(cls, width: int, height: int, fov_deg: float) -> "Camera":
        """Pinhole camera whose horizontal field of view (across the width) is ``fov_deg``
        in (0, 180) degrees, as Mitsuba's ``fov_axis="x"``."""
        if not (math.isfinite(fov_deg) and 0.0 < fov_deg < 180.0):
            raise ProbeError(f"field of view must be in (0, 180) degrees, got {fov_deg}")
        return cls(int(width), int(height), 0.5 * width / math.tan(math.radians(fov_deg) / 2.0))

    @property
    def perspective(self) -> bool:
        return self.focal_px is not None

    def rays(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Ray origins and unit directions ``(..., 3)`` (camera frame, from the camera into
        the scene) through pixel coordinates ``x``, ``y`` (x right, y down, pixels)."""
        px = np.asarray(x, np.float64) - self.width / 2.0
        py = -(np.asarray(y, np.float64) - self.height / 2.0)
        if self.perspective:
            d = np.stack([px, py, np.full_like(px, -self.focal_px)], -1)
            return np.zeros_like(d), d / np.linalg.norm(d, axis=-1, keepdims=True)
        d = np.zeros(px.shape + (3,))
        d[..., 2] = -1.0
        return np.stack([px, py, np.zeros_like(px)], -1), d

    def project(self, points) -> np.ndarray:
        """Pixel coordinates ``(..., 2)`` (x, y) of camera-frame points ``(..., 3)``."""
        p = np.asarray(points, np.float64)
        if self.perspective:
            x = self.width / 2.0 + self.focal_px * p[..., 0] / -p[..., 2]
            y = self.height / 2.0 - self.focal_px * p[..., 1] / -p[..., 2]
        else:
            x, y = self.width / 2.0 + p[..., 0], self.height / 2.0 - p[..., 1]
        return np.stack([x, y], -1)

    def pixel_scale(self, direction) -> float:
        """Pixels per radian of ray angle near ``direction`` (perspective), or 1."""
        if not self.perspective:
            return 1.0
        cos_t = abs(float(np.asarray(direction)[2]))
        return self.focal_px / max(cos_t, 1e-6)


@dataclass(frozen=True)
class Sphere:
    """A sphere in the camera frame: centre ``(3,)`` and radius. Perspective spheres are
    scaled to ``|centre| = 1``; orthographic ones are in pixels (``centre[2]`` arbitrary)."""
    centre: tuple[float, float, float]
    radius: float
    outline_rms_px: float = 0.0
    outline_points: int = 0
    outline_sigma_px: float | None = None   # the outline centre's error (px, rms) where the fit knows it
                                            # beyond its rms (relight.probe.detect.outline_centre_sigma_px)

    @property
    def c(self) -> np.ndarray:
        return np.asarray(self.centre, np.float64)


def sphere_from_cone(axis, alpha_rad: float, **kw) -> Sphere:
    """The unit-distance sphere whose tangent cone has ``axis`` and half-angle ``alpha``."""
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a)
    return Sphere(tuple(a.tolist()), float(math.sin(alpha_rad)), **kw)


def sphere_from_circle(camera: Camera, cx: float, cy: float, r: float) -> Sphere:
    """The sphere whose outline is best approximated by the image circle ``(cx, cy, r)``
    (pixels): the circle itself (orthographic) or the cone fitted to 64 of its points."""
    if not all(math.isfinite(v) for v in (cx, cy, r)) or r < 2:
        raise ProbeError(f"circle must be finite with a radius of at least 2 px, got {(cx, cy, r)}")
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    return fit_sphere(camera, cx + r * np.cos(t), cy + r * np.sin(t), robust=False)


def fit_sphere(camera: Camera, x, y, robust: bool = True) -> Sphere:
    """Sphere from outline points ``x``, ``y`` (pixels): a circle (orthographic) or a
    tangent cone (perspective), algebraic first, then geometric least squares with a
    robust loss (``robust``) so that a stand, an occluder or a faint edge counts less."""
    x, y = np.asarray(x, np.float64).ravel(), np.asarray(y, np.float64).ravel()
    if x.size < 8:
        raise ProbeError(f"too few outline points to fit a sphere ({x.size})")
    loss = dict(loss="soft_l1", f_scale=OUTLINE_LOSS_SCALE_PX) if robust else {}
    if not camera.perspective:
        a = np.stack([x, y, np.ones_like(x)], 1)
        (c0, c1, c2), *_ = np.linalg.lstsq(a, x * x + y * y, rcond=None)
        p0 = np.array([c0 / 2, c1 / 2, math.sqrt(max(c2 + c0 * c0 / 4 + c1 * c1 / 4, 1e-9))])
        res = optimize.least_squares(lambda p: np.hypot(x - p[0], y - p[1]) - p[2], p0, **loss)
        cx, cy, r = res.x
        resid = res.fun
        sphere_c = (cx - camera.width / 2.0, -(cy - camera.height / 2.0), -ORTHO_DEPTH)
        if not (np.isfinite(res.x).all() and r > 1):
            raise ProbeError("could not fit a circle to the sphere outline")
        rms = float(np.sqrt(np.mean(np.minimum(resid, 3.0) ** 2)))
        return Sphere(tuple(float(v) for v in sphere_c), float(r), rms, int(x.size))
    _, d = camera.rays(x, y)
    ap, *_ = np.linalg.lstsq(d, np.ones(len(d)), rcond=None)      # d . (a / cos alpha) = 1
    norm = np.linalg.norm(ap)
    if not np.isfinite(norm) or norm <= 1.0:
        raise ProbeError("could not fit a sphere to the outline (points not on a cone)")
    a0 = ap / norm
    e1, e2 = frames.perpendicular_pair(a0)
    scale = camera.pixel_scale(a0)

    def axis(p):
        v = a0 + p[0] * e1 + p[1] * e2
        return v / np.linalg.norm(v)

    def residual(p):
        return (np.arccos(np.clip(d @ axis(p), -1, 1)) - p[2]) * scale

    res = optimize.least_squares(residual, [0.0, 0.0, math.acos(1.0 / norm)], **loss)
    if not np.isfinite(res.x).all() or not 0 < res.x[2] < math.pi / 2:
        raise ProbeError("could not fit a sphere to the outline")
    rms = float(np.sqrt(np.mean(np.minimum(res.fun, 3.0) ** 2)))
    return sphere_from_cone(axis(res.x), float(res.x[2]), outline_rms_px=rms, outline_points=int(x.size))


def mask_outline_points(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel outline points of a boolean mask: the midpoints between each inside pixel
    and its outside 4-neighbour (unbiased, unlike the inside boundary pixels); edges along
    the image border (a cut, not the outline) are left out."""
    m = np.asarray(mask, bool)
    xs, ys = [], []
    for axis in (0, 1):
        a, b = (m[:-1], m[1:]) if axis == 0 else (m[:, :-1], m[:, 1:])
        rows, cols = np.nonzero(a != b)
        if axis == 0:
            xs.append(cols + 0.5), ys.append(rows + 1.0)
        else:
            xs.append(cols + 1.0), ys.append(rows + 0.5)
    return np.concatenate(xs), np.concatenate(ys)


def sphere_from_mask(camera: Camera, mask: np.ndarray) -> Sphere:
    """Sphere fitted to the outline of a boolean mask ``(H, W)`` of the camera's size."""
    m = np.asarray(mask, bool)
    if m.shape != (camera.height, camera.width):
        raise ProbeError(f"mask is {m.shape[1]} x {m.shape[0]} pixels but the image is "
                         f"{camera.width} x {camera.height}")
    if m.sum() < 20:
        raise ProbeError("the sphere mask is empty (fewer than 20 white pixels)")
    return fit_sphere(camera, *mask_outline_points(m))


def outline_circle(camera: Camera, sphere: Sphere) -> tuple[float, float, float]:
    """``(cx, cy, r)`` in pixels: the circle closest to the sphere's image outline."""
    x, y = outline_polygon(camera, sphere, 128)
    a = np.stack([x, y, np.ones_like(x)], 1)
    (c0, c1, c2), *_ = np.linalg.lstsq(a, x * x + y * y, rcond=None)
    return float(c0 / 2), float(c1 / 2), float(math.sqrt(c2 + c0 * c0 / 4 + c1 * c1 / 4))


def outline_polygon(camera: Camera, sphere: Sphere, n: int = 128) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points (x, y) of the sphere's image outline (the projected tangent cone)."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    c = sphere.c
    if not camera.perspective:
        p = camera.project(c + sphere.radius * np.stack([np.cos(t), np.sin(t), 0 * t], -1))
        return p[:, 0], p[:, 1]
    a = c / np.linalg.norm(c)
    e1, e2 = frames.perpendicular_pair(a)
    alpha = math.asin(min(sphere.radius / np.linalg.norm(c), 1.0))
    d = math.cos(alpha) * a + math.sin(alpha) * (np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2)
    p = camera.project(d)
    return p[:, 0], p[:, 1]


def bounding_box(camera: Camera, sphere: Sphere, margin: int = 2) -> tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)`` pixel index bounds (end exclusive) of the sphere, clipped to the image."""
    x, y = outline_polygon(camera, sphere, 64)
    x0 = max(int(math.floor(x.min())) - margin, 0)
    y0 = max(int(math.floor(y.min())) - margin, 0)
    x1 = min(int(math.ceil(x.max())) + margin, camera.width)
    y1 = min(int(math.ceil(y.max())) + margin, camera.height)
    if x1 <= x0 or y1 <= y0:
        raise ProbeError("the sphere lies outside the image")
    return x0, y0, x1, y1


def surface(camera: Camera, sphere: Sphere, x, y) -> dict:
    """Where each pixel's ray meets the sphere: ``hit`` (bool), ``normal`` and reflected
    direction ``reflect`` (unit, camera frame), ``cos_view`` (normal . direction to the
    camera) and ``point`` (camera frame), all of shape ``x.shape (+ (3,))``."""
    o, d, b, disc = _ray_sphere(camera, sphere, x, y)
    t = b - np.sqrt(np.maximum(disc, 0.0))
    p = o + t[..., None] * d
    n = (p - sphere.c) / sphere.radius
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    dn = np.sum(d * n, -1)
    refl = d - 2.0 * dn[..., None] * n
    return {"hit": disc >= 0, "normal": n, "reflect": refl, "cos_view": -dn, "point": p}


def _ray_sphere(camera: Camera, sphere: Sphere, x, y):
    """Each pixel's ray ``(o, d)``, its distance ``b`` to the point nearest the sphere's
    centre and the discriminant ``disc`` (the ray meets the sphere where ``disc >= 0``)."""
    o, d = camera.rays(x, y)
    oc = sphere.c - o
    b = np.sum(d * oc, -1)
    return o, d, b, b * b - (np.sum(oc * oc, -1) - sphere.radius ** 2)


def reflected_direction(camera: Camera, sphere: Sphere, x: float, y: float) -> np.ndarray:
    """The mirror-reflected view ray at pixel ``(x, y)`` on the sphere (unit, camera frame)."""
    s = surface(camera, sphere, np.array([x]), np.array([y]))
    if not s["hit"][0]:
        raise ProbeError(f"pixel ({x:.1f}, {y:.1f}) is not on the sphere")
    return s["reflect"][0]


def predict_highlight(camera: Camera, sphere: Sphere, to_light) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form check: pixel ``(x, y)`` and surface point of a distant light's mirror
    highlight. The normal there bisects the direction to the camera and ``to_light``:
    ``n = (v + l) / |v + l|`` with ``P = C + R n`` and ``v = (o - P) / |o - P|``;
    iterated to a fixed point (converges at the rate ``R / |C|``)."""
    l = np.asarray(to_light, np.float64)
    l = l / np.linalg.norm(l)
    c = sphere.c
    p = c.copy()
    for _ in range(60):
        v = -p / np.linalg.norm(p) if camera.perspective else np.array([0.0, 0.0, 1.0])
        n = (v + l) / np.linalg.norm(v + l)
        p_new = c + sphere.radius * n
        if np.linalg.norm(p_new - p) < 1e-13 * max(1.0, sphere.radius):
            p = p_new
            break
        p = p_new
    return camera.project(p), p


@dataclass
class Highlight:
    """The chrome sphere's highlight: direction toward the light and how it was found."""
    to_light: np.ndarray                    # unit, camera frame
    pixel: tuple[float, float]              # intensity-weighted centroid (x, y), pixels
    quality: dict = field(default_factory=dict)


def _luminance(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image, np.float64)
    from relight.colour import luminance
    return img if img.ndim == 2 else luminance(img)


def sphere_pixels(camera: Camera, sphere: Sphere, mask: np.ndarray | None = None,
                  rim_exclude_px: float = RIM_EXCLUDE_PX):
    """Pixels of the sphere's interior usable for measurement, in its bounding box:
    returns ``(box, usable (h, w) bool, surface dict over the box)``."""
    box, s = sphere_surface(camera, sphere)
    return box, usable_pixels(camera, sphere, box, s, rim_exclude_px, mask), s


def sphere_surface(camera: Camera, sphere: Sphere) -> tuple[tuple[int, int, int, int], dict]:
    """The sphere's bounding box and :func:`surface` over it (pixel centres)."""
    x0, y0, x1, y1 = box = bounding_box(camera, sphere)
    ys, xs = np.mgrid[y0:y1, x0:x1] + 0.5
    return box, surface(camera, sphere, xs, ys)


def usable_pixels(camera: Camera, sphere: Sphere, box, s: dict, rim_exclude_px: float = RIM_EXCLUDE_PX,
                  mask: np.ndarray | None = None) -> np.ndarray:
    """Of the ``box``'s pixels (``s``: :func:`sphere_surface`), those usable for
    measurement: on the sphere, at least ``rim_exclude_px`` from its outline (every
    pixel whose neighbourhood leaves the sphere is out), seen at most
    :data:`MAX_RIM_ANGLE_DEG` from the view ray, and in ``mask`` if one is given."""
    x0, y0, x1, y1 = box
    ys, xs = np.mgrid[y0:y1, x0:x1] + 0.5
    shrunk = s["hit"].copy()
    for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1), (0.7, 0.7), (-0.7, 0.7), (0.7, -0.7), (-0.7, -0.7)):
        shrunk &= _ray_sphere(camera, sphere, xs + dx * rim_exclude_px, ys + dy * rim_exclude_px)[3] >= 0
    usable = shrunk & (s["cos_view"] >= math.cos(math.radians(MAX_RIM_ANGLE_DEG)))
    if mask is not None:
        usable &= np.asarray(mask, bool)[y0:y1, x0:x1]
    return usable


def _solid_angle_weights(camera: Camera, sphere: Sphere, xs, ys) -> np.ndarray:
    """Solid angle of reflected directions per pixel, ``|dl/dx x dl/dy|`` by central
    differences (half a pixel each way); where a neighbour misses the sphere, the median."""
    h = 0.5
    lx1 = surface(camera, sphere, xs + h, ys)
    lx0 = surface(camera, sphere, xs - h, ys)
    ly1 = surface(camera, sphere, xs, ys + h)
    ly0 = surface(camera, sphere, xs, ys - h)
    ok = lx1["hit"] & lx0["hit"] & ly1["hit"] & ly0["hit"]
    j = np.linalg.norm(np.cross(lx1["reflect"] - lx0["reflect"], ly1["reflect"] - ly0["reflect"]), axis=-1)
    if ok.any():
        j = np.where(ok, j, np.median(j[ok]))
    else:
        j = np.ones_like(j)
    return j


def highlight_likelihood(image: np.ndarray, camera: Camera, sphere: Sphere) -> float:
    """How much the brightest spot on ``sphere`` looks like a small light's mirror
    highlight: the best score of :func:`_core_scores` (0 a perfect candidate, each unit a
    clear strike: spread, elongation, pressed against the rim, bright surroundings).
    A chrome sphere in a room lit by a small light shows one; a circle drawn on a lit,
    textured floor or wall encloses only patches of that surface.

    Args:
        image: linear RGB ``(H, W, 3)`` or luminance ``(H, W)``.
        camera: the camera.
        sphere: the sphere to look at.

    Returns:
        The best candidate's score (<= about 0.1), or -10 when the sphere has too few
        usable pixels or no bright spot.
    """
    lum = _luminance(image)
    try:
        (x0, y0, x1, y1), usable, s = sphere_pixels(camera, sphere)
    except ProbeError:
        return -10.0
    if usable.sum() < 5:
        return -10.0
    crop = lum[y0:y1, x0:x1]
    peak = float(crop[usable].max())
    if not peak > 0:
        return -10.0
    return float(_scored_cores(camera, sphere, crop, usable, s, (x0, y0), peak, None)[2].max())


def _scored_cores(camera: Camera, sphere: Sphere, crop: np.ndarray, usable: np.ndarray, s: dict,
                  offset: tuple[int, int], peak: float, expect_to_light, clip_level: float | None = None,
                  fireflies: bool = False):
    """The brightest cores of a sphere's crop (4-connected pixels, :data:`CORE_STRUCTURE`, within
    :data:`TIE_FRACTION` of ``peak``: clipped blobs, or the peak pixel of an unclipped
    image), each scored by what a small light predicts (:func:`_core_scores`). Returns
    ``(cores, core_index, scores, core_dirs, spread_limit)``: the label image, the labels,
    their scores and reflected directions, and the compactness limit in degrees."""
    x0, y0 = offset
    cores, n_cores = ndimage.label(usable & (crop >= TIE_FRACTION * peak), CORE_STRUCTURE)
    core_index = np.arange(1, n_cores + 1)
    cys, cxs = np.nonzero(cores > 0)
    footprint_deg = math.degrees(math.sqrt(float(np.median(_solid_angle_weights(
        camera, sphere, cxs + x0 + 0.5, cys + y0 + 0.5)))))
    spread_limit = MAX_LIGHT_SPREAD_DEG + 3.0 * footprint_deg
    scores, core_dirs = _core_scores(camera, sphere, crop, cores, core_index, s, (x0, y0), spread_limit,
                                     expect_to_light, usable, clip_level, fireflies)
    return cores, core_index, scores, core_dirs, spread_limit


def locate_highlight(image: np.ndarray, camera: Camera, sphere: Sphere, mask: np.ndarray | None = None,
                     clip_level: float | None = None, expect_to_light=None,
                     circle_px: float | None = None) -> Highlight:
    """Direction toward the light from a chrome (mirror) sphere's highlight.

    The light's core is the connected set of pixels within :data:`TIE_FRACTION` of the
    brightest usable pixel (the peak pixel itself when nothing clips) that best fits a
    small light (see "Candidates" below): compact (spanning at most
    :data:`MAX_LIGHT_SPREAD_DEG` of reflected directions plus three pixels' worth, as one
    pixel spans more directions near the rim), round, not pressed against the rim. The highlight is the connected region around that core of pixels
    at least :data:`HIGHLIGHT_FRACTION` of the peak, grown by two pixels; when more than
    :data:`MERGED_FRACTION` of that region lies beyond the core grown by
    :data:`CORE_RIM_PX` (the light touches bright surroundings, or the lobe is broad),
    only the grown core counts, above the level just outside it. A compact highlight's direction is the view ray
    through its centroid (weights: intensity above the local background), reflected: the
    lens blurs the blob symmetrically in the image, and near the rim, where one pixel spans
    many degrees, a mean over directions would not be. A broad one (wider than that
    limit: a lobe from an extended source) is the mean of the
    reflected view rays weighted by intensity and by each pixel's solid angle. A compact
    core that clips, however large (a lens's blur spreads a light far above the clip level
    into a clipped disc), is centred in a soft window over its own pixels, continued past
    the outline, where the blur spreads it as far as inward (:func:`_soft_window_centroid`),
    unless nothing of the light lies beside its clipped pixels (a box or Blackman-Harris
    pixel filter and no lens blur): then which pixels clip is all the image says, and the
    footprint a light predicts places it (:func:`_clipped_footprint_centre`).

    Args:
        image: linear RGB ``(H, W, 3)`` or luminance ``(H, W)``.
        clip_level: the value at which the sensor clips (1 for PNG/JPEG), if any: a
            candidate that does not reach it in an image that does is scored down, a
            clipped core is measured as above, and ``clipped`` is reported.
        expect_to_light: a rough direction toward the light (a diffuse sphere's
            shading), used to choose among candidate blobs.
        circle_px: the outline's position uncertainty in pixels (a given circle's
            tolerance) for the error budget; default: from the outline fit.

    Candidates: several blobs may be equally bright (clipped in 8-bit: the light and a
    grazing reflection of a lit floor or wall). Each is scored by what a small light
    predicts (:func:`_core_scores`); when the runner-up comes within
    :data:`AMBIGUITY_MARGIN` of the best, ``quality`` reports ``ambiguity`` (0-1), the
    other candidate's direction and pixel, and the error budget widens by the angle
    between the two times the ambiguity.
    """
    lum = _luminance(image)
    (x0, y0, x1, y1), usable, s = sphere_pixels(camera, sphere, mask)
    if usable.sum() < 5:
        raise ProbeError("the chrome sphere is too small or hidden (fewer than 5 usable pixels)")
    crop = lum[y0:y1, x0:x1]
    mask_crop = None if mask is None else np.asarray(mask, bool)[y0:y1, x0:x1]
    usable = usable | _rim_light(crop, usable, s, mask_crop, clip_level)
    values = crop[usable]
    peak = float(values.max())
    floor = float(np.median(values))
    if not peak > 0 or peak <= 1.5 * floor + 1e-6:
        raise ProbeError("no highlight on the chrome sphere (it is black or evenly lit)")
    labels, count = ndimage.label(usable & (crop >= HIGHLIGHT_FRACTION * peak), np.ones((3, 3)))
    refl = s["reflect"]
    # lone clipped pixels off the sphere: the image's own fireflies or hot pixels
    lone = (lone_clipped_pixels(lum, CLIPS_AT * clip_level, (x0 - 2, y0 - 2, x1 + 2, y1 + 2))
            if clip_level is not None and peak >= CLIPS_AT * clip_level else 0)
    fireflies = lone >= FIREFLY_MIN
    cores, core_index, scores, core_dirs, spread_limit = _scored_cores(
        camera, sphere, crop, usable, s, (x0, y0), peak, expect_to_light, clip_level, fireflies)
    order = np.argsort(-scores)
    best_core = cores == int(core_index[order[0]])
    rival = None
    if len(order) > 1 and scores[order[0]] - scores[order[1]] < AMBIGUITY_MARGIN:
        rival = (float(1.0 - (scores[order[0]] - scores[order[1]]) / AMBIGUITY_MARGIN), core_dirs[order[1]],
                 int(core_index[order[1]]))
    best = int(np.max(labels[best_core]))
    region = labels == best
    square = np.ones((3, 3))
    near_core = ndimage.binary_dilation(best_core, square, iterations=CORE_RIM_PX) & usable
    merged = (region & ~near_core).sum() > MERGED_FRACTION * region.sum()
    if merged:
        # a light merged with bright surroundings (or a broad lobe): measure its core and
        # rim only, above the level of the surroundings just outside that rim
        grown = near_core
        ring = ndimage.binary_dilation(grown, square, iterations=2) & usable & ~grown
        region &= grown
        background = float(np.percentile(crop[ring], 90)) if ring.sum() >= 4 else floor
    else:
        grown = ndimage.binary_dilation(region, square, iterations=2) & usable
        ring = ndimage.binary_dilation(grown, square, iterations=2) & usable & ~grown & (labels == 0)
        background = float(np.median(crop[ring])) if ring.sum() >= 4 else floor
    weights = np.clip(crop - background, 0.0, None) * grown
    if not (weights > 0).any():
        # the core merged with surroundings as bright as itself (all clipped): nothing
        # stands above the level around it, so the core's own pixels, equally weighted
        weights = best_core.astype(float)
    ys, xs = np.nonzero(weights > 0)
    w = weights[ys, xs] * _solid_angle_weights(camera, sphere, xs + x0 + 0.5, ys + y0 + 0.5)
    total = refl[ys, xs] * w[:, None]
    to_light = total.sum(0)
    if not np.linalg.norm(to_light) > 0:
        raise ProbeError("no highlight on the chrome sphere")
    to_light /= np.linalg.norm(to_light)
    px = float(np.average(xs + x0 + 0.5, weights=weights[ys, xs]))
    py = float(np.average(ys + y0 + 0.5, weights=weights[ys, xs]))
    # in an image that clips, a light far above the clip level clips wherever it reaches:
    # its pixels are the clipped core, and what else stands above half the peak beside it
    # (a lit edge's reflection touching it) is not the light, however few its pixels
    clips = clip_level is not None and peak >= CLIPS_AT * clip_level
    light_pixels = best_core if clips else region
    compact = _spread_deg(refl[light_pixels]) <= spread_limit
    if compact and (clips or region.sum() <= SMALL_HIGHLIGHT_PX
                    or (merged and best_core.sum() <= SMALL_HIGHLIGHT_PX)):
        # a light far above the clip level in a narrowly filtered image (its clipped pixels
        # hard-edged, nothing of it beside them): which pixels clip is all there is, and the
        # footprint a light predicts locates it better than their centroid. Else the core's
        # own centre, then a soft window around it above the level of its surroundings (the
        # 90th percentile of a ring just outside the window: a lit floor's reflection beside
        # a small clipped highlight, or touching it, must not pull it). Every other compact
        # clipped core is measured so, however large: a blurred lens or pixel filter spreads
        # a light far above the clip level into a clipped disc of many pixels, and their
        # plain centroid follows whatever bright pixels lie beside it and whatever of it the
        # outline cuts off
        centre = _clipped_footprint_centre(camera, sphere, crop, best_core, usable, (x0, y0)) if clips else None
        if centre is None:
            centre = _windowed_centre(crop, usable, s, mask_crop,
                                      best_core, cores, clips, background)
        px, py = centre[0] + x0, centre[1] + y0
    at_centroid = surface(camera, sphere, np.array([px]), np.array([py]))
    if compact and at_centroid["hit"][0]:
        # a small highlight: the lens blurs it symmetrically in the image, not in directions
        to_light = at_centroid["reflect"][0]
    cos_view = float(np.average(s["cos_view"][ys, xs], weights=w))
    clipped = clip_level is not None and int((crop[region] >= CLIPS_AT * clip_level).sum()) >= 2
    spread_deg = _spread_deg(refl[region])
    quality = {
        "highlight_px": [px, py],
        "highlight_pixels": int(region.sum()),
        "highlight_spread_deg": spread_deg,
        "peak": peak,
        "background": background,
        "clipped": bool(clipped),
        "view_angle_deg": math.degrees(math.acos(min(max(cos_view, -1.0), 1.0))),
        "ambiguity": rival[0] if rival else 0.0,
        "candidates": len(core_index),
        "lone_clipped_pixels": lone,
    }
    if rival is not None:
        ry, rx = np.nonzero(cores == rival[2])
        quality["alternative_to_light"] = [float(v) for v in rival[1]]
        quality["alternative_px"] = [float(rx.mean() + x0 + 0.5), float(ry.mean() + y0 + 0.5)]
        quality["alternative_separation_deg"] = math.degrees(math.acos(float(np.clip(rival[1] @ to_light, -1, 1))))
    budget = error_budget(camera, sphere, quality, circle_px)
    quality["error_budget_deg"] = {k: round(v, 3) for k, v in budget.items()}
    quality["uncertainty_deg"] = budget["total_deg"]
    return Highlight(to_light, (px, py), quality)


def lone_clipped_pixels(lum: np.ndarray, clip_at: float, exclude: tuple[int, int, int, int] | None = None) -> int:
    """How many lone clipped pixels the image holds outside ``exclude`` (a box ``(x0, y0,
    x1, y1)``): clipped blobs (8-connected, luminance at least ``clip_at``) of at most
    :data:`FIREFLY_PX` pixels whose touching pixels' 90th percentile stays below
    :data:`FIREFLY_DROP` of ``clip_at``: a path tracer's fireflies, a sensor's hot pixels."""
    clipped = lum >= clip_at
    if exclude is not None:
        x0, y0, x1, y1 = exclude
        clipped[max(y0, 0):max(y1, 0), max(x0, 0):max(x1, 0)] = False
    labels, n = ndimage.label(clipped, np.ones((3, 3), bool))
    if n == 0:
        return 0
    small = np.bincount(labels.ravel(), minlength=n + 1) <= FIREFLY_PX
    small[0] = False
    grown = ndimage.grey_dilation(np.where(small[labels], labels, 0), footprint=np.ones((3, 3), bool))
    ring = (grown > 0) & (labels == 0)          # touching pixels (8-connected blobs never touch)
    if not ring.any():
        return 0
    owner, values = grown[ring], lum[ring]
    order = np.lexsort((values, owner))
    owner, values = owner[order], values[order]
    first = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]])
    count = np.diff(np.r_[first, owner.size])
    rank = 0.9 * (count - 1)                    # np.percentile's linear interpolation, per blob
    low = np.floor(rank).astype(int)
    high = np.minimum(low + 1, count - 1)
    p90 = values[first + low] + (rank - low) * (values[first + high] - values[first + low])
    return int(np.sum(p90 < FIREFLY_DROP * clip_at))


def _rim_band(usable: np.ndarray, s: dict, mask: np.ndarray | None) -> np.ndarray:
    """The rim band: the pixels on the sphere, facing the camera, that the search leaves
    out as within :data:`RIM_EXCLUDE_PX` of the outline (not ``usable``), within ``mask``
    (cropped as ``usable``) if given."""
    band = s["hit"] & ~usable & (s["cos_view"] > 0)
    return band if mask is None else band & mask


def _rim_light(crop: np.ndarray, usable: np.ndarray, s: dict, mask: np.ndarray | None,
               clip_level: float | None) -> np.ndarray:
    """The rim band's pixels (on the sphere within :data:`RIM_EXCLUDE_PX` of its outline,
    which the search leaves out) that hold the light: a light behind the sphere puts its
    highlight at the rim, and an outline fitted a pixel small (a mirror's rim shows what
    lies right behind it, so its edge can lie that far inside) leaves all of it in the
    band, the search then choosing a dim reflection inside. They count when the band's
    brightest pixels stand :data:`RIM_LIGHT_RATIO` above everything inside (or clip where
    nothing inside does) and are the sphere's own: nothing as bright lies past the
    outline beside them (within :data:`TIE_FRACTION` of them where they clip, else half),
    or, continued there, they still form a disc (the blur spreads a light across the
    outline as much as inward); a bright wall, or the light itself, seen right behind the
    sphere runs along the outline instead. Empty otherwise."""
    none = np.zeros(crop.shape, bool)
    band = _rim_band(usable, s, mask)
    if not band.any() or not usable.any():
        return none
    inner, top = float(crop[usable].max()), float(crop[band].max())
    clipped = clip_level is not None and top >= CLIPS_AT * clip_level
    if clip_level is not None and inner >= CLIPS_AT * clip_level:
        return none
    if not (clipped or top >= RIM_LIGHT_RATIO * inner):
        return none
    blobs, n = ndimage.label(band & (crop >= TIE_FRACTION * top), np.ones((3, 3)))
    light = none.copy()
    for k in range(1, n + 1):
        blob = blobs == k
        whole = _core_into_rim(crop, blob, ~s["hit"], TIE_FRACTION if clipped else HIGHLIGHT_FRACTION)
        if whole.sum() == blob.sum() or _disc_like(whole):
            light |= blob
    return light


def _clipped_footprint_centre(camera: Camera, sphere: Sphere, crop: np.ndarray, core: np.ndarray,
                              usable: np.ndarray, origin: tuple[int, int]) -> tuple[float, float] | None:
    """A clipped core's centre (crop pixel coordinates) from which pixels clipped
    (:func:`relight.probe.footprint.footprint_centre`), when that is all the image says:
    the core is small (at most :data:`FOOTPRINT_MAX_PX` pixels), two pixels clear of the
    rim band (the mirror map is near linear over it) and hard-edged: the pixels touching
    it stand, at the median, within :data:`BLUR_TAIL_SHARE` of the way from the level
    two to three pixels out to the clip (on the harder set's Cycles renders 96% of the
    clipped highlights do, under a 1 px Gaussian blur 1%). Else ``None``: a lens's or
    wide filter's blur surrounds it, and its shape says where it is
    (:func:`_windowed_centre`)."""
    core = np.asarray(core, bool)
    if core.sum() > FOOTPRINT_MAX_PX:
        return None
    square = np.ones((3, 3), bool)
    beside = ndimage.binary_dilation(core, square)
    near = ndimage.binary_dilation(beside, square)
    if (near & ~usable).any():
        return None
    touching = beside & ~core
    around = ndimage.binary_dilation(near, square) & ~beside & usable
    if around.sum() < 4:
        return None
    level = float(np.median(crop[around]))
    clip = float(crop[core].max())
    if float(np.median(crop[touching])) - level > BLUR_TAIL_SHARE * (clip - level):
        return None
    # every unclipped pixel touching it says the light hardly reaches it (a light far above
    # the clip level clips what it covers by a few thousandths); another clipped pixel there
    # (a lit surface's reflection) says nothing
    unclipped = beside & (crop < CLIPS_AT * clip)
    cy, cx = np.nonzero(core)
    jac = mirror_jacobian(camera, sphere, cx.mean() + 0.5 + origin[0], cy.mean() + 0.5 + origin[1])
    return None if jac is None else footprint.footprint_centre(core, unclipped, jac.T @ jac)


def mirror_jacobian(camera: Camera, sphere: Sphere, x: float, y: float, step_px: float = 0.25) -> np.ndarray | None:
    """How the reflected direction changes per pixel at ``(x, y)``: ``(3, 2)``, columns
    d/dx and d/dy by central differences ``step_px`` each way (``None`` off the sphere). A
    small light of angular radius ``a`` seen in the mirror there covers the pixel offsets
    ``d`` with ``|J d| < a``."""
    e = step_px
    at = surface(camera, sphere, np.array([x + e, x - e, x, x]), np.array([y, y, y + e, y - e]))
    if not at["hit"].all():
        return None
    return np.stack([at["reflect"][0] - at["reflect"][1], at["reflect"][2] - at["reflect"][3]], 1) / (2 * e)


def _windowed_centre(crop: np.ndarray, usable: np.ndarray, s: dict, mask: np.ndarray | None, best_core: np.ndarray,
                     cores: np.ndarray, clips: bool, background: float) -> tuple[float, float]:
    """A compact highlight's centre (crop pixel coordinates) in a soft window over its own
    pixels (:func:`_soft_window_centroid`), its core continued into the rim band (within
    ``mask``, cropped like ``crop``, if given) and, when it clips, past the outline."""
    # the rim band (pixels on the sphere within RIM_EXCLUDE_PX of its outline) is left out
    # of the search, as its pixels mix the sphere with what lies beyond; but where the
    # chosen core runs into it at the core's own brightness, those pixels are the light
    # (a light behind the sphere puts its highlight there), and leaving them out moves
    # the highlight inward by up to a pixel: several degrees near the rim
    rim_band = _rim_band(usable, s, mask)
    best_core = _core_into_rim(crop, best_core, rim_band)
    # A clipped core also continues past the outline itself: the blur spreads the light
    # beyond the sphere's edge as much as inward, and the disc cut there has its centre
    # inward (a pixel, 7 deg at the median, for lights near the rim under a 1 px blur).
    # The clipped pixels it runs into there are its own while the two together stay a
    # disc: a clipped wall or window behind the sphere, which the core can run into
    # too, does not. (With a mask given, what lies outside it is not looked at.)
    if clips and mask is None:
        whole = _core_into_rim(crop, best_core, ~s["hit"])
        if whole.sum() > best_core.sum() and _disc_like(whole):
            best_core = whole
    cy_, cx_ = np.nonzero(best_core)
    start = (float(cx_.mean()) + 0.5, float(cy_.mean()) + 0.5)
    radius = math.sqrt(best_core.sum() / math.pi) + WINDOW_MARGIN_PX
    yy, xx = np.mgrid[0:crop.shape[0], 0:crop.shape[1]] + 0.5
    dist = np.hypot(xx - start[0], yy - start[1])
    ring = usable & (dist > radius + 1.0) & (dist <= radius + 3.0)
    level = float(np.percentile(crop[ring], 90)) if ring.sum() >= 4 else background
    # only the light's own pixels count: those reached from its core by steps
    # downhill (its blur falls off monotonically; a lit surface's reflection beside
    # it, or another candidate, rises again)
    # in a linear image (nothing clips) the light's blur continues into the rim band too,
    # far above anything the outline's mixing can give there (half the core's peak); in a
    # clipped one a mixed rim pixel can reach that level, so only the core itself goes there
    rim_tail = rim_band & (crop >= HIGHLIGHT_FRACTION * float(crop[best_core].max())) if not clips else False
    own = _downhill_from(crop, best_core, (usable | rim_tail) & ~((cores > 0) & ~best_core),
                         int(math.ceil(radius)) + 2, prune=clips)
    return _soft_window_centroid(crop, own, start, level, radius, core=best_core if clips else None)


def _principal_variances(xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """The variances of pixels ``(xs, ys)`` along their principal axes (ascending), each
    pixel's own extent (a unit square: 1/12) included."""
    return np.linalg.eigvalsh(np.cov(np.stack([xs, ys]).astype(np.float64)) + np.eye(2) / 12.0)


def _disc_like(blob: np.ndarray, max_elongation: float = 1.5, max_excess: float = 0.3) -> bool:
    """Whether ``blob`` is a filled disc: its principal axes within ``max_elongation`` of
    each other (a pixel's own extent included) and its area at most ``1 + max_excess``
    times the disc those axes describe (a disc of radius R spreads R^2 / 4 along each)."""
    ys, xs = np.nonzero(blob)
    if ys.size < 3:
        return True
    ev = _principal_variances(xs, ys)
    return (math.sqrt(ev[1] / max(ev[0], 1e-9)) <= max_elongation
            and ys.size <= (1.0 + max_excess) * 4.0 * math.pi * math.sqrt(ev[0] * ev[1]))


def _core_into_rim(crop: np.ndarray, core: np.ndarray, rim_band: np.ndarray,
                   fraction: float = TIE_FRACTION) -> np.ndarray:
    """``core`` grown through connected ``rim_band`` pixels at least ``fraction`` of the
    core's brightest pixel (the light's core continued where the search does not look)."""
    level = fraction * float(crop[core].max())
    grown = np.asarray(core, bool).copy()
    square = np.ones((3, 3), bool)
    while True:
        new = ndimage.binary_dilation(grown, square) & rim_band & ~grown & (crop >= level)
        if not new.any():
            return grown
        grown |= new


def _downhill_from(crop: np.ndarray, seed: np.ndarray, allowed: np.ndarray, steps: int,
                   prune: bool = False) -> np.ndarray:
    """Pixels reached from ``seed`` within ``steps`` steps (8-neighbours) through
    ``allowed`` pixels, each step to a strictly darker pixel than a reached neighbour:
    a blurred highlight's own pixels, not a brighter structure beside it.

    The descent can also run down the flank of a bright structure touching the seed (a
    lit edge's reflection beside a clipped highlight). With ``prune`` (``seed`` is a
    clipped core: the light's whole image), a blur's pixel has no brighter neighbour
    outside the blur, so reached pixels with one (brighter by more than
    :data:`DOWNHILL_MARGIN` of the seed's peak) are dropped, until none is left. Not in a
    linear image: there the seed is the peak alone, and a light's image spanning several
    pixels can hold a second, lower maximum beside it (a Cycles EXR: pruning moved its
    highlight by 0.35 px, 0.5 -> 1.8 deg)."""
    seed = np.asarray(seed, bool)
    reached = seed.copy()
    square = np.ones((3, 3), bool)
    for _ in range(steps):
        around = ndimage.maximum_filter(np.where(reached, crop, -np.inf), footprint=square, mode="constant",
                                        cval=-np.inf)
        new = allowed & ~reached & (crop < around)
        if not new.any():
            break
        reached |= new
    if not prune:
        return reached
    margin = DOWNHILL_MARGIN * float(crop[seed].max())
    while True:
        beside = ndimage.maximum_filter(np.where(allowed & ~reached, crop, -np.inf), footprint=square,
                                        mode="constant", cval=-np.inf)
        drop = reached & ~seed & (beside > crop + margin)
        if not drop.any():
            return reached
        reached &= ~drop


def _soft_window_centroid(crop: np.ndarray, usable: np.ndarray, start: tuple[float, float], background: float,
                          radius: float, rounds: int = 6, core: np.ndarray | None = None) -> tuple[float, float]:
    """Sub-pixel centre ``(x, y)`` (crop pixel coordinates, centres at +0.5) of a compact
    highlight: the centroid of intensity above ``background`` within a round window of
    ``radius`` pixels whose edge tapers linearly over two pixels, re-centred on the
    centroid until it settles. A pixel entering or leaving the window does so with a
    weight near zero, so the estimate follows an image shift smoothly (a threshold
    region would jump by whole pixels).

    With a clipped ``core`` (the light itself), every other pixel counts only when the
    point mirrored through the current centre (bilinear) holds at least
    :data:`MIRROR_SHARE` of its signal: a lens blurs the light alike on all sides, while
    a bright structure beside it (a lit edge's reflection touching it) has no
    counterpart on the far side and drops out. (A weight of the lesser of the two would
    move with the clipped plateau's shape; the half-pixel shift test fails with it.)"""
    h, w = crop.shape
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    signal = np.clip(crop - background, 0.0, None) * usable
    cx, cy = start
    for _ in range(rounds):
        taper = np.clip(radius + 1.0 - np.hypot(xs - cx, ys - cy), 0.0, 2.0) / 2.0
        weights = signal * taper
        if core is not None:
            mirrored = ndimage.map_coordinates(signal, [2.0 * cy - ys - 0.5, 2.0 * cx - xs - 0.5], order=1,
                                               mode="constant", cval=0.0)
            weights = np.where(core | (mirrored >= MIRROR_SHARE * signal), weights, 0.0)
        total = weights.sum()
        if not total > 0:
            break
        nx, ny = float((weights * xs).sum() / total), float((weights * ys).sum() / total)
        done = math.hypot(nx - cx, ny - cy) < 1e-4
        cx, cy = nx, ny
        if done:
            break
    return cx, cy


def _core_scores(camera: Camera, sphere: Sphere, crop: np.ndarray, cores: np.ndarray, index: np.ndarray,
                 s: dict, origin: tuple[int, int], spread_limit: float, expect_to_light=None,
                 usable: np.ndarray | None = None, clip_level: float | None = None,
                 fireflies: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """How much each brightest blob (``cores`` labels ``index``) looks like a small
    light's highlight, and its reflected direction (intensity-weighted mean).

    A small light's highlight is compact (spread of reflected directions within
    ``spread_limit``), round in the image (elongation: the ratio of the blob's principal
    axes, a pixel's own extent included), not compressed against the rim (the share of
    its pixels whose normal is more than :data:`RIM_BLOB_ANGLE_DEG` from the view ray: a
    grazing reflection of a lit floor or wall lies there, stretched along the rim),
    standing alone (:func:`_surround_share` of the ``usable`` pixels around it: a lit
    surface's clipped patch continues into bright surroundings; a candidate whose
    touching pixels all lie below half its peak is judged without the other candidates
    beyond that gap: a light reflected beside a lit object's clipped spot is not that
    object's continuation), not shading down (where it clips: the 90th percentile of its
    touching pixels above its surroundings by more than :data:`SHADING_DOWN_LEVEL` of its
    peak marks a lit object's clipped patch, bright at its edge and dark a pixel or two
    out; a light far above the clip level drops from it at once, to 0.07 of it at the
    median on the harder probe set's Cycles renders, 0.70 under a 0.6 px lens blur; so a
    clipped candidate standing more than :data:`SHADING_DOWN_GAP` above the one that drops
    most at once (of at least :data:`SHADING_DOWN_REF_PX` pixels) is shading down too,
    whatever the level: that one shows what the image's blur alone leaves beside a clipped
    light), and,
    when ``expect_to_light`` (a diffuse sphere's shading direction) is given, near that
    direction. In a linear HDR image a dimmer blob loses by its brightness too; in one
    that clips (``clip_level``, reached on the sphere) a blob that does not clip takes
    :data:`UNCLIPPED_STRIKE`: it is known to be dimmer than one that does, while a small
    light, hundreds of times brighter than the lit surfaces it shines on, clips wherever
    it reaches even when it covers a fraction of a pixel. Where the image shows fireflies
    (``fireflies``: lone clipped pixels off the sphere, :func:`lone_clipped_pixels`), a
    candidate as lone as they are (at most :data:`FIREFLY_PX` pixels, its touching pixels
    below :data:`FIREFLY_DROP` of its peak) takes :data:`FIREFLY_STRIKE` when a larger
    clipped candidate is there to take instead. Scores are
    log-likelihood-like: 0 is a perfect candidate, each unit a clear strike."""
    peak = float(crop[cores > 0].max())
    clip_at = None if clip_level is None or peak < CLIPS_AT * clip_level else CLIPS_AT * clip_level
    if usable is None:
        usable = np.ones(crop.shape, bool)
    refl = s["reflect"]
    cos_view = s["cos_view"]
    scores, dirs = [], []
    shading_down: dict[int, float] = {}
    reference: list[float] = []
    lone: list[int] = []
    larger_clipped = False
    for k in index:
        ys, xs = np.nonzero(cores == k)
        w = crop[ys, xs]
        d = (refl[ys, xs] * w[:, None]).sum(0)
        d = d / max(np.linalg.norm(d), 1e-12)
        dirs.append(d)
        score = 0.0
        spread = _spread_deg(refl[ys, xs]) if ys.size > 1 else 0.0
        score -= max(0.0, spread - spread_limit) / max(spread_limit, 1e-6)
        if ys.size >= 3:
            ev = _principal_variances(xs, ys)
            score -= 0.5 * max(0.0, math.sqrt(ev[1] / max(ev[0], 1e-9)) - 1.5)
        grazing = float(np.mean(cos_view[ys, xs] < math.cos(math.radians(RIM_BLOB_ANGLE_DEG))))
        score -= GRAZING_WEIGHT * grazing
        blob = cores == k
        touching = _touching_pixels(crop, blob, usable)
        # a candidate that drops below half its peak at once is judged on its own
        # surroundings: another candidate across that gap is not its continuation
        top = float(w.max())
        apart = touching.size == 0 or float(touching.max()) < HIGHLIGHT_FRACTION * top
        around = _surround_share(crop, blob, usable)
        surround = _surround_share(crop, blob, usable, (cores > 0) & ~blob) if apart else around
        score -= ISOLATION_WEIGHT * max(0.0, surround - ISOLATION_LEVEL)
        if clip_at is not None and top >= clip_at:
            # what stays beside a clipped candidate, over its peak: a firefly's and a light's
            # neighbours drop at once, a lit object's patch shades down
            beside = float(np.percentile(touching, 90)) / top if touching.size else 0.0
            if ys.size <= FIREFLY_PX and beside < FIREFLY_DROP:
                lone.append(len(scores))
            elif ys.size > FIREFLY_PX:
                larger_clipped = True
            if touching.size >= 3:
                shading_down[len(scores)] = beside - around
                if ys.size >= SHADING_DOWN_REF_PX:
                    reference.append(shading_down[len(scores)])
        if expect_to_light is not None:
            e = np.asarray(expect_to_light, np.float64)
            angle = math.degrees(math.acos(float(np.clip(d @ (e / np.linalg.norm(e)), -1.0, 1.0))))
            score -= max(0.0, angle - 15.0) / 30.0
        score += 2.0 * math.log10(max(top, 1e-12) / peak)   # HDR: a dimmer blob is less likely
        if clip_at is not None and top < clip_at:
            score -= UNCLIPPED_STRIKE
        score += 0.05 * math.log10(ys.size)                             # ties: the larger blob (a brighter light)
        scores.append(score)
    if shading_down:
        level = min([SHADING_DOWN_LEVEL] + [value + SHADING_DOWN_GAP for value in reference])
        for i, value in shading_down.items():
            scores[i] -= SHADING_DOWN_WEIGHT * max(0.0, value - level)
    if fireflies and larger_clipped:
        for i in lone:
            scores[i] -= FIREFLY_STRIKE
    return np.asarray(scores), np.asarray(dirs)


def _surround_share(crop: np.ndarray, blob: np.ndarray, usable: np.ndarray,
                    others: np.ndarray | None = None) -> float:
    """How bright a candidate's surroundings are: the 90th percentile of the usable pixels
    :data:`ISOLATION_RING_PX` pixels from the blob (chessboard distance, past a lens's or
    pixel filter's blur), over the blob's own peak. A small light's highlight stands
    alone on the mirrored scene (near 0); a clipped patch of a lit floor or wall is the
    brightest part of a surface that continues beside it (often 0.2-0.9). Pixels within
    a pixel of ``others`` (other candidates) are left out when given."""
    square = np.ones((3, 3), bool)
    near = ndimage.binary_dilation(blob, square, iterations=ISOLATION_RING_PX[0] - 1)
    ring = ndimage.binary_dilation(blob, square, iterations=ISOLATION_RING_PX[1]) & ~near & usable
    if others is not None:
        ring &= ~ndimage.binary_dilation(others, square)
    if ring.sum() < 3:
        return 0.0
    return float(np.percentile(crop[ring], 90)) / max(float(crop[blob].max()), 1e-12)


def _touching_pixels(crop: np.ndarray, blob: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """The values of the usable pixels touching a candidate (8-neighbours)."""
    return crop[ndimage.binary_dilation(blob, np.ones((3, 3), bool)) & ~blob & usable]


def _spread_deg(directions: np.ndarray) -> float:
    """RMS angle (degrees, small-angle) of unit vectors ``(N, 3)`` about their mean."""
    return float(math.degrees(math.sqrt(max(2.0 * (1.0 - np.linalg.norm(directions.mean(0))), 0.0))))


FOCAL_REL_UNCERTAINTY = 0.02   # a stated field of view or focal length: about 2% (EXIF, calibration)


def error_budget(camera: Camera, sphere: Sphere, q: dict, circle_px: float | None = None) -> dict:
    """Rough 1-sigma error budget of the direction (degrees), by source:

    * ``circle_deg``: the outline's position error (``circle_px``, e.g. a given circle's
      stated uncertainty; else 0.05 px plus the fit's own figure: a chrome outline found
      in the image its centre's error, ``outline_sigma_px``
      (:func:`relight.probe.detect.outline_centre_sigma_px`), any other the fit's rms over
      the square root of an eighth of its point count),
    * ``highlight_deg``: the highlight's position error (pixels, growing with its size),
      its spread, and, when two candidates remain, the angle to the other one times the
      ambiguity,
    * ``camera_deg``: the camera model: a perspective focal length known to
      :data:`FOCAL_REL_UNCERTAINTY` tilts each view ray by that share of its angle off
      the axis (orthographic: 0, the far camera taken as exact);

    each position error turned into a normal error on a sphere of radius ``r_px``,
    doubled by the reflection and stretched by foreshortening: at a normal ``theta`` from
    the view ray a shift across the outline's radius tilts it by ``1 / cos(theta)`` times
    what one along the outline does, and an error in any direction by their rms,
    ``sqrt((1 + 1 / cos^2 theta) / 2)`` (``cos theta`` at least 0.1). ``total_deg`` adds
    them in quadrature."""
    r_px = sphere.radius * (camera.pixel_scale(sphere.c / np.linalg.norm(sphere.c)) / np.linalg.norm(sphere.c)
                            if camera.perspective else 1.0)
    if circle_px is None:
        circle_px = 0.05 + (sphere.outline_sigma_px if sphere.outline_sigma_px is not None
                            else sphere.outline_rms_px / math.sqrt(max(sphere.outline_points, 1) / 8.0))
    highlight_px = 0.1 + 0.1 * math.sqrt(q["highlight_pixels"])
    cos_n = max(math.cos(math.radians(q["view_angle_deg"])), 0.1)
    to_deg = math.degrees(2.0 / r_px * math.sqrt(0.5 * (1.0 + 1.0 / cos_n ** 2)))
    circle_deg = circle_px * to_deg
    highlight_deg = (highlight_px * to_deg + 0.1 * q["highlight_spread_deg"]
                     + q.get("ambiguity", 0.0) * q.get("alternative_separation_deg", 0.0))
    camera_deg = 0.0
    if camera.perspective:
        c = sphere.c / np.linalg.norm(sphere.c)
        off_axis = math.acos(min(abs(float(c[2])), 1.0))
        camera_deg = math.degrees(FOCAL_REL_UNCERTAINTY * math.sin(off_axis) * math.cos(off_axis))
    return {"circle_deg": circle_deg, "highlight_deg": highlight_deg, "camera_deg": camera_deg,
            "total_deg": math.sqrt(circle_deg ** 2 + highlight_deg ** 2 + camera_deg ** 2)}


def diffuse_light(image: np.ndarray, camera: Camera, sphere: Sphere,
                  mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, dict]:
    """Light direction (unit, camera frame), colour (unit-norm linear RGB) and fit figures
    from a diffuse sphere, with each pixel's perspective normal.

    As :func:`relight.probe.ortho.diffuse_light`: Lambert shading plus a constant ambient term
    fitted on pixels between :data:`LIT_FRACTION` of the peak; colour = their mean RGB.
    """
    img = np.asarray(image, np.float64)
    if img.ndim != 3 or img.shape[2] < 3:
        raise ProbeError(f"expected an (H, W, 3) image, got shape {img.shape}")
    img = img[..., :3]
    (x0, y0, x1, y1), usable, s = sphere_pixels(camera, sphere, mask, rim_exclude_px=1.5)
    usable &= s["cos_view"] >= math.sqrt(1.0 - DIFFUSE_RIM_FRACTION ** 2)
    crop = img[y0:y1, x0:x1]
    lum = _luminance(crop)
    if usable.sum() < 20:
        raise ProbeError("the diffuse sphere is too small (fewer than 20 usable pixels)")
    peak = float(np.percentile(lum[usable], 99.5))
    if not peak > 1e-6:
        raise ProbeError("the diffuse sphere is black")
    lit = usable & (lum > LIT_FRACTION[0] * peak) & (lum < LIT_FRACTION[1] * peak)
    if lit.sum() < 20:
        raise ProbeError("too few lit pixels on the diffuse sphere")
    design = np.concatenate([s["normal"][lit], np.ones((int(lit.sum()), 1))], axis=1)
    solution, *_ = np.linalg.lstsq(design, lum[lit], rcond=None)
    b = solution[:3]
    rgb = crop[lit].mean(0)
    if not np.linalg.norm(b) > 0 or not rgb.max() > 0 or (rgb < 0).any():
        raise ProbeError("degenerate diffuse sphere shading")
    resid = lum[lit] - design @ solution
    info = {"lit_pixels": int(lit.sum()), "shading_rms": float(np.sqrt(np.mean(resid ** 2)) / peak),
            "ambient": float(solution[3] / peak)}
    return b / np.linalg.norm(b), rgb / np.linalg.norm(rgb), info

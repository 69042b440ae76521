"""Finding probe spheres in a photograph: image loading, sub-pixel outline refinement from
image edges, and automatic detection of the chrome and the diffuse sphere.

Outline refinement: along radial lines through the sphere's outline guess, the strongest
colour edge (the norm of the RGB derivative of the linear image, clipped and smoothed by
:func:`edge_sigma_px`) is located to a fraction of a pixel (parabola through the peak);
the sphere is fitted to those points with a robust loss, and the search narrows around the
fitted outline. A chrome sphere's rim reflects what lies beside it, so parts of its outline
are faint; the robust fit and the strength threshold leave those out.

Detection: OpenCV's Hough transform proposes circles; each is refined as above and scored
by the share of its outline that has an edge (``edge_support``); a mirror sphere shows a
compact highlight many times brighter than its median (or clipping, in an image that clips:
then its contrast is only a lower bound), a diffuse sphere none, and its
pixels fit a diffuse shading model (second-order spherical harmonics of the normal, which
hold any Lambertian sphere to a few percent, or one light plus ambient, which follows a
hard terminator).
"""
from __future__ import annotations

__all__ = [
    "EDGE_SIGMA_PX", "EDGE_SIGMA_MAX_PX", "EDGE_NOISE_LEFT", "edge_sigma_px", "image_noise", "EDGE_ANGLES", "EDGE_MIN_FRACTION", "REJECT_ROUNDS", "REJECT_SIGMAS", "REJECT_MIN_PX",
    "EDGE_INLIER_PX", "SUPPORT_BAND_FRACTION", "MIN_EDGE_SUPPORT", "MIN_RADIUS_FRACTION",
    "MAX_RADIUS_FRACTION", "MAX_CANDIDATES", "SPOT_PROPOSALS", "CLIPPED_SPOT_PROPOSALS", "CHROME_MIN_CONTRAST",
    "CHROME_MAX_BLOB_FRACTION", "CHROME_MIN_EXCESS", "CHROME_FLAT", "CHROME_FLAT_EXCESS", "CHROME_MIN_CLIPPED_CONTRAST", "CLIP_FRACTION", "DIFFUSE_MAX_RESIDUAL", "TRIM_FRACTION",
    "read_probe_image", "load_mask", "edge_points", "refine_sphere", "sphere_features", "hough_circles",
    "camera_exposure", "exposed_like_a_camera", "detection_view", "HDR_CLIP_SHARE", "find_spheres", "is_chrome", "is_diffuse", "pick_sphere",
    "outline_fit_px", "support_at", "NARROW_FIRST_BAND_PX", "constrained_refinement", "GROW_RADII", "GROW_FINE_RADII", "GROW_MIN_SUPPORT_RATIO", "GROW_ROUNDS",
    "PICK_HIGHLIGHT_WEIGHT", "PICK_RADIUS_WEIGHT", "CHROME_INSIDE_PX", "ON_OUTLINE_PX", "RIM_FIT_ROUNDS", "RIM_FIT_SETTLED_PX", "outer_rim_fit", "DETECTION_MARGIN",
    "rival_sphere", "share_the_rest", "CHROME_RIM_SHIFT", "PIXEL_BLUR_PX", "edge_blur_px", "chrome_rim_shift_px",
    "outline_from_rim", "RIM_BIAS_PX", "RIM_BIAS_ARC_DEG", "outline_centre_sigma_px", "with_centre_error",
    "CHECK_DISPUTE", "disputed_outline",
]

import dataclasses
import math
import os

import numpy as np
from scipy import ndimage

from relight.colour import srgb_decode, srgb_encode
from relight.probe.geometry import (RIM_EXCLUDE_PX, TIE_FRACTION, Camera, ProbeError, Sphere, fit_sphere, highlight_likelihood,
                                    outline_circle, outline_polygon, sphere_from_circle, sphere_surface,
                                    usable_pixels)

EDGE_SIGMA_PX = 0.5            # edge smoothing: at least half a pixel (a sampled Gaussian narrower than that
                               # collapses onto its centre pixel) ...
EDGE_SIGMA_MAX_PX = 0.7        # ... at most 0.7 px (wider merges a mirror's rim with the reflections its last
                               # pixel compresses: the found outline shrinks) ...
EDGE_NOISE_LEFT = 0.001        # ... and in between as much as leaves this noise (in the exposed linear image):
                               # the rms rounding error of an 8-bit sRGB code at mid-grey (0.18 linear: 0.00095)
EDGE_ANGLES = 360
EDGE_MIN_FRACTION = 0.3        # an edge weaker than 30% of the median edge strength is dropped
REJECT_ROUNDS = 3               # outline fit: drop points beyond REJECT_SIGMAS robust sigmas
REJECT_SIGMAS = 1.5
REJECT_MIN_PX = 0.75
EDGE_INLIER_PX = 1.0           # edge points this close to the fitted outline support it
SUPPORT_BAND_FRACTION = 0.25   # ... when they are the strongest edge within 25% of the radius
NARROW_FIRST_BAND_PX = 3.0     # a proposal refined again on this band when the wide one left it less supported
ACCEPT_FIT_RATIO = 0.6        # a given circle's refinement is kept only when it cuts the edge misfit by 40%
MIN_EDGE_SUPPORT = 0.2         # share of the outline where it is the strongest edge, to call it a sphere
MIN_RADIUS_PX = 7              # detection radii: at least 7 px (spheres down to 10 px are found) ...
MIN_RADIUS_FRACTION = 0.015    # ... and 1.5% of the image's shorter side
MAX_RADIUS_FRACTION = 0.45
MAX_CANDIDATES = 60
SPOT_PROPOSALS = 20            # ... of which the last 20: the rest's circles with the most highlight-like spot
CLIPPED_SPOT_PROPOSALS = 20    # ... and in a clipping image as many again holding a compact clipped spot
GROW_RADII = (1.2, 1.4)         # a chrome candidate: larger concentric outlines tried ...
GROW_FINE_RADII = (1.1,)       # ... and, when none of those grows, this finer step (near its rim a mirror
                               # compresses its surroundings into concentric bands ~10% apart, which a 20%
                               # step jumps over: issue-29 scene 29's dark rim) ...
GROW_MIN_SUPPORT_RATIO = 0.8   # ... and kept with at least 80% of its edge support,
GROW_ROUNDS = 3                # ... again from the larger one, up to three times
CHECK_MOVE = 0.1               # the learned outline check's circle this far from a chrome outline: fitted again there
CHECK_DISPUTE = 0.08           # a found chrome outline the check puts the sphere this far from (by _circle_gap) is
                               # disputed: its stated centre error takes in the two outlines' distance (disputed_outline)
CHECK_PREFER = 0.05            # of two nested chrome circles the outer one goes when the check, asked from each, puts
                               # the sphere this much nearer the inner one (by _circle_gap): a cast shadow's circle
CHROME_INSIDE_PX = 0.5         # a chrome outline's edge points further inside than this are reflections
                               # (about 1.5 robust sigmas of the edge points' scatter on a true rim, 0.3 px)
ON_OUTLINE_PX = 1e-6           # an edge point this close to a threshold is on it: edge points sit on the search's
                               # quarter-pixel steps around the outline they were searched from, so a distance
                               # compared with 0, -0.5 or 0.75 px is otherwise decided by the last bits of a
                               # projection (which the CPU's BLAS kernel sets: docs/probe-history.md, 23rd round)
RIM_FIT_ROUNDS = 3             # a chrome outline's fit to its outermost edges repeated from its own outline at most this often,
RIM_FIT_SETTLED_PX = 0.01      # ... until it moves less than this
CHROME_RIM_SHIFT = 0.2         # a mirror sphere's rim edges lie this many blur widths inside its outline
RIM_BIAS_PX = 0.2              # ... by an amount that varies along it, by this much (1 sigma) ...
RIM_BIAS_ARC_DEG = 20.0        # ... alike over arcs of about this many degrees (outline_centre_sigma_px)
PIXEL_BLUR_PX = math.sqrt(1.0 / 12.0)   # a pixel's own blur (a box one pixel wide: its standard deviation)
PICK_HIGHLIGHT_WEIGHT = 0.1    # choosing the chrome sphere: per unit of highlight likelihood (strikes) ...
PICK_RADIUS_WEIGHT = 0.1       # ... and per unit of log radius (a chrome sphere's reflections are smaller circles)
DETECTION_MARGIN = 0.1         # another circle of the kind within this pick score of the chosen one: ambiguous
LOCATOR_WEIGHT = 0.1           # ... and per unit of the log probability the learned locator puts near its
LOCATOR_FLOOR = 0.01           # centre (relight.probe.locator), that probability taken as at least this
LOCATOR_ADMIT = 0.5            # a circle neither chrome nor diffuse by the rules is a chrome candidate too
                               # when the locator puts this much probability near its centre
RADIUS_HYPOTHESES = (1.0, 0.85, 1.15)  # a Hough circle's radius is often off on a chrome sphere's faint rim
PROPOSAL_RADIUS_HYPOTHESES = (1.0, 0.85, 1.15, 1.3)  # an extra proposal's (the learned locator's: the true
                                                     # radius is 0.79-1.45 times its, locator.RADIUS_BOUND)
CHROME_MIN_CONTRAST = 4.0      # chrome: brightest / median sphere pixel at least this,
CHROME_MIN_CLIPPED_CONTRAST = 2.0  # ... or, when its brightest pixel clips (the contrast then is only a lower
                               # bound: a mirror of a bright room reads 1 / 0.32 = 3.1 at most in 8-bit), the
                               # clip level at least twice the median (most of it below half the spot, the
                               # level the blob test below reads),
CLIP_FRACTION = 0.999          # a pixel clips when every channel is within 0.1% of the clip level (an 8-bit
                               # code of 254 decodes to 0.991)
CHROME_MAX_BLOB_FRACTION = 0.15  # in a bright region covering at most 15% of the sphere (not a lit side),
CHROME_MIN_EXCESS = 0.15       # above what one light on a diffuse sphere gives,
CHROME_MIN_RESIDUAL = 0.25     # and no smooth shading model fits it (it mirrors its surroundings: a
                               # diffuse ball with a hot pixel fits within 0.2; on the probe set
                               # chrome spheres measure 0.29-1.9, gray and coloured balls 0.02-0.48)
CHROME_FLAT = 0.15             # ... unless the sphere is a flat disc (its pixels' 10th-90th percentile spread at most
                               # 15% of their median: a mirror of an evenly lit world; a diffuse ball under a light
                               # shades across it, 0.44-9 on two of the harder set's Cycles sets) ...
CHROME_FLAT_EXCESS = 0.8       # ... whose highlight one light on a diffuse sphere leaves 80% unexplained
HDR_CLIP_SHARE = 0.02          # detection in a linear HDR image: exposed so that its brightest 2% clip
DIFFUSE_MAX_RESIDUAL = 0.3     # diffuse: a shading model fits within 30% rms
TRIM_FRACTION = 0.01           # ... leaving out the worst 1% of pixels (glints, hot pixels)


def read_probe_image(path: str, linear: bool = False) -> tuple[np.ndarray, float | None, str]:
    """Read an image as linear RGB ``(H, W, 3)`` float64.

    8- and 16-bit PNG/JPEG/TIFF are sRGB-decoded unless ``linear`` (16-bit files from
    measurement datasets usually are linear); EXR is linear. Returns ``(image,
    clip_level, how)``: ``clip_level`` is 1.0 for integer files (the value at which the
    sensor or the file clips) and None for EXR.
    """
    if not os.path.exists(path):
        raise ProbeError(f"image not found: {path}")
    if path.lower().endswith(".exr"):
        from relight.imageio import read_exr
        return np.asarray(read_exr(path), np.float64), None, "linear (EXR)"
    from relight.imageio import load_image as read_any   # every PNG mode and depth, JPEG
    pixels, _, note = read_any(path)
    bits = 16 if note.startswith("16-bit") else 8
    rgb = pixels.astype(np.float64)
    if linear:
        return rgb, 1.0, f"linear {bits}-bit"
    return srgb_decode(rgb), 1.0, f"sRGB {bits}-bit (decoded to linear)"


def load_mask(path: str) -> np.ndarray:
    """A mask image: True where the pixel is brighter than half of full scale."""
    image, _, _ = read_probe_image(path, linear=True)
    return image.mean(-1) > 0.5


def _encoded(image: np.ndarray) -> np.ndarray:
    """sRGB-encoded, clipped ``(H, W, 3)``: edges weigh alike in dark and bright parts."""
    return srgb_encode(np.clip(np.asarray(image, np.float64)[..., :3], 0.0, 1.0))


def _edge_image(image: np.ndarray) -> np.ndarray:
    """The image in which outlines are located: linear (a blur moves no edge there, while
    the sRGB curve would push each edge toward its dark side), exposed by
    :func:`_exposure`, clipped, smoothed by :func:`edge_sigma_px` of its own noise."""
    lin = _exposed_for_edges(image)
    sigma = edge_sigma_px(lin)
    return ndimage.gaussian_filter(lin, (sigma, sigma, 0))


def _exposed_for_edges(image: np.ndarray) -> np.ndarray:
    """Linear RGB exposed by :func:`_exposure` and clipped: what :func:`_edge_image` smooths."""
    lin = np.asarray(image, np.float64)[..., :3]
    return np.clip(lin * _exposure(lin), 0.0, 1.0)


def image_noise(lin: np.ndarray) -> float:
    """Per-pixel noise (standard deviation) of an exposed, clipped linear ``(H, W, 3)``
    image: the mean absolute response to the 3x3 Laplacian-difference mask
    ``[[1,-2,1],[-2,4,-2],[1,-2,1]]`` (which cancels any locally linear shading; white
    noise of std s gives 6 s sqrt(2/pi) on average), over unclipped pixels, leaving out
    the largest 10% (edges and texture; the mean of the rest of white noise's responses
    is 6 s sqrt(2/pi) (1 - exp(-z^2/2)) / 0.9, z = 1.645 its 90th percentile), averaged
    over the channels."""
    mask = np.array([[1.0, -2.0, 1.0], [-2.0, 4.0, -2.0], [1.0, -2.0, 1.0]])
    z90 = 1.6448536269514722
    per_std = 6.0 * math.sqrt(2.0 / math.pi) * (1.0 - math.exp(-0.5 * z90 * z90)) / 0.9
    lin = np.asarray(lin, np.float64)
    out = []
    for c in range(lin.shape[2]):
        v = lin[..., c]
        resp = np.abs(ndimage.convolve(v, mask, mode="nearest"))[1:-1, 1:-1]
        free = (v[1:-1, 1:-1] > 0.0) & (v[1:-1, 1:-1] < 1.0)
        a = np.sort(resp[free])[:int(0.9 * free.sum())]
        out.append(float(a.mean()) / per_std if a.size else 0.0)
    return float(np.mean(out)) if out else 0.0


def edge_sigma_px(lin: np.ndarray) -> float:
    """The edge smoothing for an exposed, clipped linear image: the Gaussian that leaves
    :data:`EDGE_NOISE_LEFT` of its noise (:func:`image_noise`; white noise of std s comes
    out of a 2-D Gaussian of sigma p pixels as s / (2 sqrt(pi) p)), within
    :data:`EDGE_SIGMA_PX` to :data:`EDGE_SIGMA_MAX_PX`. A clean render wants the least (its
    edges are exact and a mirror's rim stays apart from the reflections inside it), a
    noisy or coarsely quantized photograph more."""
    need = image_noise(lin) / (2.0 * math.sqrt(math.pi) * EDGE_NOISE_LEFT)
    return float(np.clip(need, EDGE_SIGMA_PX, EDGE_SIGMA_MAX_PX))


def edge_blur_px(image: np.ndarray) -> float:
    """How wide an outline's edge is in :func:`_edge_image` (pixels, a Gaussian's sigma):
    the smoothing :func:`edge_sigma_px` and the pixel's own box, :data:`PIXEL_BLUR_PX`,
    in quadrature (a lens's blur is not known and not counted)."""
    return math.hypot(edge_sigma_px(_exposed_for_edges(image)), PIXEL_BLUR_PX)


def chrome_rim_shift_px(image: np.ndarray) -> float:
    """How far inside a mirror sphere's outline its rim's edges lie in ``image`` (pixels):
    :data:`CHROME_RIM_SHIFT` blur widths (:func:`edge_blur_px`). A mirror's rim reflects
    what lies right behind it, so the image is nearly continuous across the outline and
    the contrast grows inward: the blurred edge's steepest point, where
    :func:`edge_points` puts it, lies inside (on the harder probe set's true outlines
    0.12-0.25 px inside for a blur of 0.58-1.5 px, about 0.2 blur widths; on a uniform
    disc 0.02 px: the shift is the mirror's, not the method's). The outermost-rim fit,
    settled (:func:`outer_rim_fit`), comes out that much small: 0.15 px on the harder
    set's Cycles renders, 0.11 px on Mitsuba rooms, at the median. See docs/probe-history.md,
    sixteenth and seventeenth rounds."""
    return CHROME_RIM_SHIFT * edge_blur_px(image)


def outline_from_rim(camera: Camera, sphere: Sphere, shift_px: float) -> Sphere:
    """The sphere whose outline lies ``shift_px`` outside ``sphere``'s (each outline point
    moved that far out from its centre): a mirror sphere's outline from the one fitted to
    its rim's edges (:func:`chrome_rim_shift_px`)."""
    if shift_px == 0.0:
        return sphere
    cx, cy, _ = outline_circle(camera, sphere)
    x, y = outline_polygon(camera, sphere, 64)
    dist = np.hypot(x - cx, y - cy)
    grown = fit_sphere(camera, x + shift_px * (x - cx) / dist, y + shift_px * (y - cy) / dist, robust=False)
    return Sphere(grown.centre, grown.radius, sphere.outline_rms_px, sphere.outline_points, sphere.outline_sigma_px)


def outline_centre_sigma_px(camera: Camera, sphere: Sphere, x, y) -> float:
    """How far the centre of a mirror sphere's outline fitted to its rim's edge points
    ``(x, y)`` may be off (pixels; the rms of the centre's error, both coordinates
    together): each point off by the fit's own rms independently, and by a bias its
    neighbours share. A mirror's rim shows no edge of its own where it mirrors what lies
    right beside it; the edge found there is a reflection's, inside the outline (by 0.3-1 px
    on the team-like Cycles renders: a contact shadow, a wall's edge mirrored at the top),
    or a background edge just outside it, and alike along an arc. That bias is taken as
    :data:`RIM_BIAS_PX` (1 sigma), correlated as ``exp(-d^2 / 2 a^2)`` between points
    ``d`` apart in angle around the outline (``a`` = :data:`RIM_BIAS_ARC_DEG`), and carried
    through the linearised circle fit (centre and radius): ``C = A J^T S J A`` with
    ``A = (J^T J)^-1``. The points' spread around the outline decides it: on a whole
    outline opposite arcs' biases largely cancel; where an arc has no points (the rim at
    the floor), the arc opposite alone places the centre along that line, and its bias
    moves it whole."""
    x, y = np.asarray(x, np.float64).ravel(), np.asarray(y, np.float64).ravel()
    cx, cy, _ = outline_circle(camera, sphere)
    phi = np.arctan2(y - cy, x - cx)
    jac = np.stack([np.cos(phi), np.sin(phi), np.ones_like(phi)], 1)
    gap = np.angle(np.exp(1j * (phi[:, None] - phi[None, :])))
    cov_points = (sphere.outline_rms_px ** 2 * np.eye(phi.size)
                  + RIM_BIAS_PX ** 2 * np.exp(-0.5 * (gap / math.radians(RIM_BIAS_ARC_DEG)) ** 2))
    a = np.linalg.pinv(jac.T @ jac)
    cov = a @ jac.T @ cov_points @ jac @ a
    return float(math.sqrt(max(cov[0, 0] + cov[1, 1], 0.0)))


def with_centre_error(image: np.ndarray, camera: Camera, sphere: Sphere) -> Sphere:
    """A found chrome outline (fitted to its rim's edges in ``image``, the detection's
    view) with its centre's error stated (:func:`outline_centre_sigma_px`): its own when
    the rim fit (:func:`outer_rim_fit`) ended with one, else from the rim's edge points
    around it that such a fit keeps (at their gradient's peak within 1.5 px, at most
    :data:`CHROME_INSIDE_PX` inside and :data:`REJECT_MIN_PX` outside), as few as they
    are: the rim fit leaves an outline as it was where under 30% of the radial lines
    hold such a point, and there the arcs without one are what the error is about."""
    if sphere.outline_sigma_px is not None:
        return sphere
    x, y, _ = edge_points(_edge_image(image), camera, sphere, 1.5, peak=True)
    dist = _outline_distance(camera, sphere, x, y)
    keep = (dist >= -CHROME_INSIDE_PX - ON_OUTLINE_PX) & (dist <= REJECT_MIN_PX + ON_OUTLINE_PX)
    if keep.sum() < 8:
        return sphere
    return dataclasses.replace(sphere, outline_sigma_px=outline_centre_sigma_px(camera, sphere, x[keep], y[keep]))


def disputed_outline(sphere: Sphere, cand: dict) -> tuple[Sphere, float | None]:
    """A found chrome outline (``sphere``, from candidate ``cand``) whose circle the learned
    outline check puts elsewhere, by more than :data:`CHECK_DISPUTE` (``cand``'s
    ``check_gap``, :func:`_checked_outline`), with its stated centre error
    (``outline_sigma_px``, the error budget's circle term) taken in quadrature with half
    the largest distance between the two outlines (their centres' distance plus their
    radii's difference, pixels). Returns the sphere and that distance (``None``, and the
    sphere as it was, when the check does not dispute it or has no opinion).

    Neither the edges nor the check is right every time. On the 780 Cycles scenes of the
    team-like and held-out sets (docs/probe-history.md, twenty-ninth round) the check
    disputes 39 found outlines by that margin, 29 of them more than 0.5 px from the true
    outline (of the 741 others, 38); yet, asked offline, the outline fitted where the check
    puts the sphere was the better one on only 23 of 44 disputed outlines. Two estimates
    that far apart, with nothing to choose between them, leave the outline known to about
    half their distance either way: stated so, the direction's error lies within twice its
    stated uncertainty on 98.8% of the 780 (97.9% before; within it, 87.9% against 84.6%).
    The direction is not changed."""
    gap, seen = cand.get("check_gap"), cand.get("check_circle")
    if gap is None or seen is None or gap <= CHECK_DISPUTE:
        return sphere, None
    a = cand["circle"]
    apart = math.hypot(seen[0] - a[0], seen[1] - a[1]) + abs(seen[2] - a[2])
    return dataclasses.replace(sphere, outline_sigma_px=math.hypot(sphere.outline_sigma_px or 0.0, 0.5 * apart)), apart


def _exposure(image: np.ndarray) -> float:
    """Scale putting the 99th percentile of luminance at 0.5, so that a dark photo's
    outlines count as much as a bright one's and a clipped highlight's flare less."""
    return 0.5 / max(float(np.percentile(np.asarray(image)[..., :3].mean(-1), 99.0)), 1e-6)


def _polar_outline(camera: Camera, sphere: Sphere, angles: np.ndarray):
    """Centre (x, y) of the outline's best circle and the outline's radius along each angle."""
    cx, cy, _ = outline_circle(camera, sphere)
    x, y = outline_polygon(camera, sphere, 720)
    theta = np.arctan2(y - cy, x - cx)
    rad = np.hypot(x - cx, y - cy)
    order = np.argsort(theta)
    theta, rad = theta[order], rad[order]
    theta = np.concatenate([theta - 2 * np.pi, theta, theta + 2 * np.pi])
    rad = np.concatenate([rad, rad, rad])
    return cx, cy, np.interp(angles, theta, rad)


def edge_points(smoothed: np.ndarray, camera: Camera, guess: Sphere, band_px: float,
                angles: int = EDGE_ANGLES, prior: bool = True, peak: bool = False
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sub-pixel outline points (x, y) and their edge strengths along ``angles`` radial
    lines within ``band_px`` of the guessed outline (``smoothed``: the linear RGB image,
    exposed, clipped and smoothed, :func:`_edge_image`): on each line the strongest edge in
    the image's linear interpolation, weighted toward the guess (``prior``), placed to a
    fraction of the sampling step by a parabola through its gradient.

    With ``peak`` (an outline's last fit, :func:`outer_rim_fit`) the chosen edge is placed
    at its own gradient's peak (:func:`_climb` from the choice, which the prior pulls
    toward the guess) in a cubic spline's samples (:func:`_spline_samples`); a line whose
    peak lies at the band's end is left out. Without, its place is read where the weighted
    choice fell, up to half a step from it toward the guess, in a linear interpolation,
    whose gradient is constant between pixel centres (55% of the points lay on the
    lattice's half steps). That is imprecise, but an edge whose gradient still rises at
    the band's end (an outline beyond it) pulls the fit there step by step, which the
    search for an outline relies on: started away from the outline, fits with edges at
    their peaks settled on reflections inside it (docs/probe-history.md, twentieth round)."""
    theta = np.linspace(-np.pi, np.pi, angles, endpoint=False)
    cx, cy, r_theta = _polar_outline(camera, guess, theta)
    step = 0.25
    offsets = np.arange(-band_px, band_px + step / 2, step)
    s = r_theta[:, None] + offsets[None, :]
    xs = cx + s * np.cos(theta)[:, None]
    ys = cy + s * np.sin(theta)[:, None]
    h, w = smoothed.shape[:2]
    inside = (xs > 1) & (xs < w - 1) & (ys > 1) & (ys < h - 1)
    coords = [ys.ravel() - 0.5, xs.ravel() - 0.5]
    samples = np.stack([ndimage.map_coordinates(smoothed[..., c], coords, order=1, mode="nearest")
                        .reshape(xs.shape) for c in range(smoothed.shape[2])], -1)
    grad = np.linalg.norm(np.gradient(samples, step, axis=1), axis=-1)
    grad[~inside] = 0.0
    # prefer edges near the guess (``prior``): a sphere's texture or reflections lie inside it
    weight = np.exp(-0.5 * (offsets / (0.5 * band_px)) ** 2) if prior else np.ones_like(offsets)
    idx = np.argmax(grad * weight[None, :], axis=1)
    rows = np.arange(angles)
    last = len(offsets) - 1
    ok = (idx > 0) & (idx < last) & inside[rows, idx]
    strength = grad[rows, idx]
    radius = s[rows, idx] + _parabola_peak(grad, idx) * step
    if peak:   # the chosen edge at its own gradient's peak, in a cubic spline's samples
        fine = np.linalg.norm(np.gradient(_spline_samples(smoothed, xs, ys), step, axis=1), axis=-1)
        fine[~inside] = 0.0
        idx = _climb(fine, idx)
        ok &= (idx > 0) & (idx < last) & inside[rows, idx]
        radius = s[rows, idx] + _parabola_peak(fine, idx) * step
    if ok.any():
        ok &= strength >= EDGE_MIN_FRACTION * np.median(strength[ok])
    x = cx + radius * np.cos(theta)
    y = cy + radius * np.sin(theta)
    return x[ok], y[ok], strength[ok]


def _spline_samples(image: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """``image`` (H, W, C) at the points ``(xs, ys)`` (pixel coordinates, a pixel's centre
    at +0.5) by cubic spline interpolation over the points' bounding box: a gradient along
    a line is then smooth and its peak lies where the edge is (a linear interpolation's
    gradient is constant between pixel centres: its peak spans a pixel, and the edge
    points it gave sat at the lattice's steps)."""
    h, w = image.shape[:2]
    x0, x1 = max(int(np.floor(xs.min())) - 4, 0), min(int(np.ceil(xs.max())) + 5, w)
    y0, y1 = max(int(np.floor(ys.min())) - 4, 0), min(int(np.ceil(ys.max())) + 5, h)
    coords = [ys.ravel() - 0.5 - y0, xs.ravel() - 0.5 - x0]
    return np.stack([ndimage.map_coordinates(image[y0:y1, x0:x1, c], coords, order=3, mode="nearest")
                     .reshape(xs.shape) for c in range(image.shape[2])], -1)


def _parabola_peak(grad: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Where the parabola through each row's samples ``idx - 1, idx, idx + 1`` of ``grad``
    (rows, samples) peaks, in steps from ``idx``, within half a step."""
    rows, last = np.arange(grad.shape[0]), grad.shape[1] - 1
    g0, g1, g2 = grad[rows, np.maximum(idx - 1, 0)], grad[rows, idx], grad[rows, np.minimum(idx + 1, last)]
    denom = g0 - 2 * g1 + g2
    frac = np.where(np.abs(denom) > 1e-12, 0.5 * (g0 - g2) / np.where(denom == 0, 1, denom), 0.0)
    return np.clip(frac, -0.5, 0.5)


def _climb(grad: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """From each row's sample ``idx`` up ``grad`` (rows, samples) to the nearest local maximum."""
    rows = np.arange(grad.shape[0])
    last = grad.shape[1] - 1
    for _ in range(last):
        here = grad[rows, idx]
        up = (idx < last) & (grad[rows, np.minimum(idx + 1, last)] > here)
        down = ~up & (idx > 0) & (grad[rows, np.maximum(idx - 1, 0)] > here)
        if not (up.any() or down.any()):
            break
        idx = idx + up - down
    return idx


def refine_sphere(image: np.ndarray, camera: Camera, guess: Sphere, smoothed: np.ndarray | None = None,
                  first_band_px: float | None = None) -> tuple[Sphere, float]:
    """Fit the sphere to the image's edges near ``guess``; returns ``(sphere,
    edge_support)``, ``edge_support`` being the share of radial lines whose strongest edge
    within :data:`SUPPORT_BAND_FRACTION` of the radius lies within :data:`EDGE_INLIER_PX`
    of the final outline."""
    if smoothed is None:
        smoothed = _edge_image(image)
    r = outline_circle(camera, guess)[2]
    sphere = guess
    for band in (first_band_px or max(3.0, 0.15 * r), 3.0, 2.0):
        x, y, _ = edge_points(smoothed, camera, sphere, band)
        if x.size < 0.2 * EDGE_ANGLES:
            raise ProbeError("too little of the sphere's outline is visible as an edge")
        sphere = fit_sphere(camera, x, y)
        for _ in range(REJECT_ROUNDS):
            dist = _outline_distance(camera, sphere, x, y)
            mad = 1.4826 * np.median(np.abs(dist - np.median(dist)))
            keep = np.abs(dist) <= max(REJECT_MIN_PX, REJECT_SIGMAS * mad)
            if keep.sum() < 0.2 * EDGE_ANGLES or keep.all():
                break
            x, y = x[keep], y[keep]
            sphere = fit_sphere(camera, x, y, robust=False)     # outliers are gone
    return sphere, support_at(smoothed, camera, sphere, r)


def support_at(smoothed: np.ndarray, camera: Camera, sphere: Sphere, radius_px: float | None = None) -> float:
    """``sphere``'s edge support, as :func:`refine_sphere` states it: the share of radial
    lines whose strongest edge within :data:`SUPPORT_BAND_FRACTION` of the radius (at least
    4 px; ``radius_px``, else the sphere's own) lies within :data:`EDGE_INLIER_PX` of its
    outline. The band is wide: a narrow one would find some edge near any circle drawn on
    a textured image."""
    r = outline_circle(camera, sphere)[2] if radius_px is None else radius_px
    wide = max(4.0, SUPPORT_BAND_FRACTION * r)
    return _edge_support(camera, sphere, *edge_points(smoothed, camera, sphere, wide, prior=False)[:2])


def _refine_proposal(image: np.ndarray, camera: Camera, guess: Sphere, smoothed: np.ndarray, r: float
                     ) -> tuple[Sphere, float]:
    """A proposed circle of radius ``r`` refined on the edges (:func:`refine_sphere`): first
    searching a band of 12% of the radius, as a proposal's radius is often that far off;
    and when that ends less supported than the proposal itself, again from it on a
    narrow band (:data:`NARROW_FIRST_BAND_PX`), the better supported of the two kept. A
    refinement must not make the outline fit worse: where a mirror's rim shows no edge
    of its own (dark beside dark) the wide band's strongest edges are a reflection's
    inside it, and the fit locked onto those (psm_spheres' chrome.10: a proposal 0.5 px
    from the mask's circle, support 0.32, refined 8 px off to 0.24; docs/probe-history.md,
    twenty-eighth round)."""
    sphere, support = refine_sphere(image, camera, guess, smoothed, first_band_px=max(3.0, 0.12 * r))
    if support_at(smoothed, camera, guess) <= support:
        return sphere, support
    try:
        narrow, narrow_support = refine_sphere(image, camera, guess, smoothed, first_band_px=NARROW_FIRST_BAND_PX)
    except ProbeError:
        return sphere, support
    return (narrow, narrow_support) if narrow_support > support else (sphere, support)


def outline_fit_px(smoothed: np.ndarray, camera: Camera, sphere: Sphere, x, y, chrome: bool = False) -> float:
    """How well edge points ``(x, y)`` fit ``sphere``'s outline: the mean of
    ``min(|distance|, 1.5)`` pixels (a robust misfit; far points count alike). With
    ``chrome``, a point more than :data:`CHROME_INSIDE_PX` inside the outline counts as
    that much: within a mirror every edge but the rim is a reflection, which no outline
    is to fit (:func:`outer_rim_fit` leaves such points out)."""
    d = _outline_distance(camera, sphere, x, y)
    if chrome:
        return float(np.mean(np.where(d < -CHROME_INSIDE_PX, CHROME_INSIDE_PX, np.minimum(np.abs(d), 1.5))))
    return float(np.mean(np.minimum(np.abs(d), 1.5)))


def constrained_refinement(image: np.ndarray, camera: Camera, circle, tolerance_px: float,
                           rim_shift_px: float = 0.0, chrome: bool = False) -> tuple[Sphere, dict]:
    """Refine a given circle ``(cx, cy, r)`` on the image's edges within ``tolerance_px``:
    the edge fit, started from the circle, is pulled back so that its centre moves and
    its radius changes by at most ``tolerance_px``, and it is kept only when the
    outline's misfit to the edges near the circle (:func:`outline_fit_px`) is at most
    :data:`ACCEPT_FIT_RATIO` of the given circle's. Returns the sphere and a report:
    ``tolerance_px``, ``accepted``, ``moved_px``, ``radius_change_px``, ``fit_given_px``,
    ``fit_refined_px`` (or ``reason`` when no fit was possible). ``rim_shift_px``: how
    far inside the outline its edges lie (a mirror sphere's, :func:`chrome_rim_shift_px`;
    the fit and the misfits are of the outline the edges then imply).

    A ``chrome`` sphere's edge fit is the one its detection ends with
    (:func:`outer_rim_fit`: the outermost edges, those further inside being reflections),
    and so is its misfit; any other sphere's is :func:`refine_sphere`'s symmetric robust
    fit. On the harder probe set's Cycles renders with the true circle given (held-out
    14-18 and a set drawn as the team's renders, docs/probe-history.md, twenty-first round) the
    symmetric fit, pulled in by the reflections, moved circles that were right (the light
    7.5 deg off on one); the chrome fit leaves them, and the light's median error is that
    of the circle unrefined."""
    guess = sphere_from_circle(camera, *circle)
    report = {"tolerance_px": float(tolerance_px), "accepted": False}
    smoothed = _edge_image(image)
    if chrome:
        fitted = outer_rim_fit(smoothed, camera, guess)
        if fitted is guess:
            report["reason"] = "no chrome outline fits the edges near the circle"
            return guess, report
    else:
        try:
            fitted, _ = refine_sphere(image, camera, guess, smoothed, first_band_px=max(2.0, tolerance_px + 1.5))
        except ProbeError as exc:
            report["reason"] = str(exc)
            return guess, report
    cx, cy, r = outline_circle(camera, outline_from_rim(camera, fitted, rim_shift_px))
    dx, dy, dr = cx - circle[0], cy - circle[1], r - circle[2]
    shift = math.hypot(dx, dy)
    if shift > tolerance_px:
        dx, dy = dx * tolerance_px / shift, dy * tolerance_px / shift
    dr = float(np.clip(dr, -tolerance_px, tolerance_px))
    candidate = sphere_from_circle(camera, circle[0] + dx, circle[1] + dy, circle[2] + dr)
    x, y, _ = edge_points(smoothed, camera, guess, tolerance_px + 1.5, prior=False)
    if x.size < 0.2 * EDGE_ANGLES:
        report["reason"] = "too little of the outline is visible as an edge"
        return guess, report
    if rim_shift_px:     # where the outline lies, seen from each rim edge
        out = rim_shift_px / np.maximum(np.hypot(x - circle[0], y - circle[1]), 1e-9)
        x, y = x + out * (x - circle[0]), y + out * (y - circle[1])
    given_fit = outline_fit_px(smoothed, camera, guess, x, y, chrome)
    refined_fit = outline_fit_px(smoothed, camera, candidate, x, y, chrome)
    report.update(moved_px=round(math.hypot(dx, dy), 4), radius_change_px=round(dr, 4),
                  fit_given_px=round(given_fit, 4), fit_refined_px=round(refined_fit, 4))
    if refined_fit < ACCEPT_FIT_RATIO * given_fit:
        report["accepted"] = True
        rms = float(np.sqrt(np.mean(np.minimum(_outline_distance(camera, candidate, x, y) ** 2, 2.25))))
        return Sphere(candidate.centre, candidate.radius, rms, int(x.size)), report
    return guess, report


def _outline_distance(camera: Camera, sphere: Sphere, x, y) -> np.ndarray:
    """Signed radial distance (pixels, + outside) of points from the sphere's outline."""
    cx, cy, _ = outline_circle(camera, sphere)
    _, _, r_theta = _polar_outline(camera, sphere, np.arctan2(y - cy, x - cx))
    return np.hypot(x - cx, y - cy) - r_theta


def _edge_support(camera: Camera, sphere: Sphere, x, y) -> float:
    return float((np.abs(_outline_distance(camera, sphere, x, y)) <= EDGE_INLIER_PX).sum() / EDGE_ANGLES)


def sphere_features(image: np.ndarray, camera: Camera, sphere: Sphere, clip_level: float | None = None) -> dict:
    """Figures telling a chrome from a diffuse sphere: ``contrast`` (99.9th percentile over
    median luminance of the sphere's pixels) and ``residual`` (rms misfit, over the mean
    luminance, of the better of two diffuse shading models: second-order spherical
    harmonics of the normal, and one light plus ambient).

    With the image's ``clip_level`` (8-bit files: 1.0): ``clipped``, whether a pixel of the
    sphere clips in every channel (:data:`CLIP_FRACTION`) among the pixels the highlight is
    looked for in (:func:`relight.probe.geometry.usable_pixels`: all but the outermost
    :data:`relight.probe.geometry.RIM_EXCLUDE_PX`, the rim included: a light behind the sphere puts its highlight
    there, outside the pixels the other figures read; seen 120 deg from the view, 0.13
    of the radius from the outline, 1.3 px on a 10 px sphere), and ``clip_contrast``, the
    clip level over the median luminance: a clipped highlight's contrast is at least that,
    whatever it really is. ``flatness``: the 10th-90th percentile spread of the sphere's
    pixels over their median (:func:`is_chrome`)."""
    box, s = sphere_surface(camera, sphere)
    x0, y0, x1, y1 = box
    usable = usable_pixels(camera, sphere, box, s, 1.5) & (s["cos_view"] >= 0.45)
    if usable.sum() < 30:
        return {"contrast": 0.0, "residual": 1.0, "mean": 0.0, "clipped": False, "clip_contrast": 0.0,
                "flatness": 1.0}
    crop = np.asarray(image, np.float64)[y0:y1, x0:x1, :3]
    searched = usable_pixels(camera, sphere, box, s, RIM_EXCLUDE_PX)
    clipped = clip_level is not None and bool((crop[searched].min(-1) >= CLIP_FRACTION * clip_level).any())
    lum = crop.mean(-1)[usable]
    n = s["normal"][usable]
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    design = np.stack([np.ones_like(x), x, y, z, x * y, x * z, y * z, x * x - y * y, 3 * z * z - 1], 1)
    coef, *_ = np.linalg.lstsq(design, lum, rcond=None)
    mean = float(lum.mean())
    resid = _trimmed_rms(lum - design @ coef) / max(mean, 1e-9)
    lambert_rms, lambert = _lambert_fit(n, lum)
    resid = min(resid, lambert_rms / max(mean, 1e-9))
    low, median, high, top = np.percentile(lum, [10, 50, 90, 99.9])   # one sort for the figures below
    median = max(float(median), 1e-6)
    contrast = float(top) / median
    flatness = float(high - low) / median
    # the brightest spot's region: of the connected regions of pixels at least half the
    # brightest, the smallest holding a pixel within TIE_FRACTION of it (in 8-bit a lit
    # floor's reflection clips as the highlight does, and may be much larger), and how much of
    # it the one-light diffuse model leaves unexplained (a highlight: most; a lit crescent: little)
    crop_lum = np.zeros(usable.shape)
    crop_lum[usable] = lum
    labels, count = ndimage.label(usable & (crop_lum >= 0.5 * lum.max()), np.ones((3, 3)))
    blob, excess = 0, 0.0
    if count:
        sizes = np.bincount(labels.ravel(), minlength=count + 1)
        peaks = np.unique(labels[usable & (crop_lum >= TIE_FRACTION * lum.max())])
        spot = int(peaks[np.argmin(sizes[peaks])])
        blob = int(sizes[spot])
        in_blob = (labels == spot)[usable]
        excess = float(np.sum(lum[in_blob] - lambert[in_blob]) / max(np.sum(lum[in_blob]), 1e-12))
    clip_contrast = float(clip_level) / median if clipped else 0.0
    return {"contrast": contrast, "residual": resid, "mean": mean, "blob_pixels": blob,
            "blob_fraction": blob / float(usable.sum()), "blob_excess": excess, "clipped": clipped,
            "clip_contrast": clip_contrast, "flatness": flatness}


def _trimmed_rms(r: np.ndarray) -> float:
    """RMS of residuals without the largest :data:`TRIM_FRACTION` (glints, hot pixels)."""
    a = np.sort(np.abs(r))
    return float(np.sqrt(np.mean(a[:max(1, int(len(a) * (1.0 - TRIM_FRACTION)))] ** 2)))


def _lambert_fit(normals: np.ndarray, lum: np.ndarray, samples: int = 1500) -> tuple[float, np.ndarray]:
    """Fit ``a + b max(0, n . l)`` (one distant light plus ambient, the light direction
    free) to a sphere's pixels; returns the trimmed rms misfit and the model at every
    pixel. Unlike a smooth expansion it follows a hard terminator, so a back-lit diffuse
    sphere (a thin lit crescent) fits too."""
    from scipy import optimize
    step = max(1, len(lum) // samples)
    n, y = normals[::step], lum[::step]

    def model(p, nn):
        l = np.array([math.cos(p[1]) * math.cos(p[0]), math.sin(p[1]), math.cos(p[1]) * math.sin(p[0])])
        return np.stack([np.ones(len(nn)), np.maximum(nn @ l, 0.0)], 1)

    def resid(p):
        a = model(p, n)
        coef, *_ = np.linalg.lstsq(a, y, rcond=None)
        return a @ coef - y

    best, best_p = np.inf, None
    for start in ((0, 0, 1), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0.5, -1)):
        l0 = np.asarray(start, float) / np.linalg.norm(start)
        r = optimize.least_squares(resid, [math.atan2(l0[2], l0[0]), math.asin(l0[1])], max_nfev=60)
        rms = _trimmed_rms(r.fun)
        if rms < best:
            best, best_p = rms, r.x
    coef, *_ = np.linalg.lstsq(model(best_p, n), y, rcond=None)
    return best, model(best_p, normals) @ coef


def hough_circles(image: np.ndarray, clip_level: float | None = None, screen=None
                  ) -> list[tuple[float, float, float]]:
    """Circle candidates ``(cx, cy, r)`` in pixels (pixel-centre convention) from three
    OpenCV Hough transforms (gradient-orientation: few, well-shaped circles; classic:
    more, looser; classic with a finer blur and fewer votes: small circles), taken in
    turns by each one's rank, near-duplicates merged, at most :data:`MAX_CANDIDATES`
    (the last :data:`SPOT_PROPOSALS` of them, when there are more, chosen by the
    brightest spot inside over the median).

    With the image's ``clip_level`` and a ``screen`` (a circle's score: how much of it is
    an edge), up to :data:`CLIPPED_SPOT_PROPOSALS` more go to the circles holding a compact
    clipped spot (a connected region of pixels clipping in every channel, wholly inside the
    circle, at most :data:`CHROME_MAX_BLOB_FRACTION` of its area), which the brightest-spot
    order misses: a clipped spot's contrast is only a lower bound (in 8-bit a mirror of a
    bright room reads about 3 at most, while a circle on a dark patch holding one bright
    pixel reads far more), and a light behind the sphere puts its highlight at the rim,
    outside the 80% of the radius read. Each such spot's circles (the best screened first)
    take turns, so that no one bright patch's many circles crowd out the others'."""
    import cv2
    img = np.asarray(image, np.float64)[..., :3]
    gray = np.round(_encoded(img * _exposure(img)) @ np.array([0.299, 0.587, 0.114]) * 255).astype(np.uint8)
    h, w = gray.shape
    short = min(h, w)
    rmin, rmax = max(MIN_RADIUS_PX, int(MIN_RADIUS_FRACTION * short)), int(MAX_RADIUS_FRACTION * short)
    found = []
    alt = cv2.HoughCircles(cv2.GaussianBlur(gray, (0, 0), 1.5), cv2.HOUGH_GRADIENT_ALT, dp=1.5,
                           minDist=rmin, param1=100, param2=0.7, minRadius=rmin, maxRadius=rmax)
    blurred = cv2.GaussianBlur(gray, (0, 0), 2.5)
    classic = cv2.HoughCircles(blurred, cv2.HOUGH_GRADIENT, dp=1,
                               minDist=rmin, param1=50, param2=20, minRadius=rmin, maxRadius=rmax)
    # small spheres: a finer blur and fewer votes (a 10 px circle has few edge pixels)
    fine = cv2.HoughCircles(cv2.GaussianBlur(gray, (0, 0), 1.2), cv2.HOUGH_GRADIENT, dp=1,
                            minDist=rmin, param1=60, param2=14, minRadius=rmin, maxRadius=min(rmax, 4 * rmin + 20))
    # the classic one again over each octave of radii: it gives each centre the one radius
    # holding the most edge pixels per unit of radius, and edges running radially from the
    # centre (a mirror's reflected room: as many at every radius) make that its smallest
    # radius, so over the whole range a sphere's centre went to a small circle, and OpenCV
    # keeps one circle per centre (a 35 px mirror in a room of wedges: 3 of 7 lights left
    # no proposal near it; over octaves, none; docs/probe-history.md, twenty-eighth round)
    octaves = []
    lo = rmin
    while lo < rmax:
        hi = min(2 * lo, rmax)
        band = cv2.HoughCircles(blurred, cv2.HOUGH_GRADIENT, dp=1,
                                minDist=lo, param1=50, param2=20, minRadius=lo, maxRadius=hi)
        if band is not None:
            octaves.append(band[0])
        lo = hi
    octave = [b[rank] for rank in range(max((len(b) for b in octaves), default=0)) for b in octaves if rank < len(b)]
    # each proposer ranks its circles by votes: they take turns, so that the fine one's
    # best small circles are not queued behind the classic one's hundred weaker ones
    lists = [c[0] for c in (alt, classic, fine) if c is not None] + ([np.array(octave)] if octave else [])
    for rank in range(max((len(c) for c in lists), default=0)):
        for x, y, r in (c[rank] for c in lists if rank < len(c)):
            # OpenCV's pixel (i, j) has its centre at (i, j); ours at (i + 0.5, j + 0.5)
            c = (float(x) + 0.5, float(y) + 0.5, float(r))
            if not any(math.hypot(c[0] - f[0], c[1] - f[1]) < 0.15 * f[2] and abs(c[2] - f[2]) < 0.15 * f[2]
                       for f in found):
                found.append(c)
    if len(found) <= MAX_CANDIDATES:
        return found
    # the proposers rank by votes, which a small chrome sphere's faint rim seldom wins:
    # the last places go to the rest's circles holding the most highlight-like spot
    # (brightest over median luminance inside), a chrome sphere's mark
    keep = MAX_CANDIDATES - SPOT_PROPOSALS
    lum = img.mean(-1)
    ys, xs = np.mgrid[0:h, 0:w] + 0.5

    def spot(c):
        x0, x1 = max(int(c[0] - c[2]), 0), min(int(c[0] + c[2]) + 1, w)
        y0, y1 = max(int(c[1] - c[2]), 0), min(int(c[1] + c[2]) + 1, h)
        inside = np.hypot(xs[y0:y1, x0:x1] - c[0], ys[y0:y1, x0:x1] - c[1]) < 0.8 * c[2]
        v = lum[y0:y1, x0:x1][inside]
        return float(v.max() / max(np.median(v), 1e-6)) if v.size >= 8 else 0.0
    rest = sorted(found[keep:], key=spot, reverse=True)
    if clip_level is None or screen is None:
        return found[:keep] + rest[:SPOT_PROPOSALS]
    taken, rest = rest[:SPOT_PROPOSALS], rest[SPOT_PROPOSALS:]
    labels, _ = ndimage.label(img.min(-1) >= CLIP_FRACTION * clip_level, np.ones((3, 3)))
    sizes = np.bincount(labels.ravel())
    by_spot: dict[int, list] = {}
    for c in rest:
        x0, x1 = max(int(c[0] - c[2]), 0), min(int(c[0] + c[2]) + 1, w)
        y0, y1 = max(int(c[1] - c[2]), 0), min(int(c[1] + c[2]) + 1, h)
        inside = np.hypot(xs[y0:y1, x0:x1] - c[0], ys[y0:y1, x0:x1] - c[1]) < c[2]
        held = np.bincount(labels[y0:y1, x0:x1][inside], minlength=sizes.size)
        for spot_label in np.nonzero((held == sizes) & (sizes <= CHROME_MAX_BLOB_FRACTION * math.pi * c[2] ** 2))[0]:
            if spot_label:
                by_spot.setdefault(int(spot_label), []).append(c)
    turns = [sorted(cs, key=screen, reverse=True) for _, cs in sorted(by_spot.items(), key=lambda kv: sizes[kv[0]])]
    chosen: list = []
    for rank in range(max((len(t) for t in turns), default=0)):
        for t in turns:
            if len(chosen) < CLIPPED_SPOT_PROPOSALS and rank < len(t) and not any(t[rank] is c for c in chosen):
                chosen.append(t[rank])
    return found[:keep] + taken + chosen


def camera_exposure(image: np.ndarray, clip_share: float = HDR_CLIP_SHARE) -> float:
    """The scale a camera's auto exposure would give a linear HDR image: its brightest
    ``clip_share`` of pixels (by mean channel) reach 1."""
    level = float(np.percentile(np.asarray(image, np.float64)[..., :3].mean(-1), 100.0 * (1.0 - clip_share)))
    return 1.0 / max(level, 1e-12)


def exposed_like_a_camera(image: np.ndarray) -> np.ndarray:
    """A linear HDR image as a camera's auto exposure would record it
    (:func:`camera_exposure`), clipped at 1."""
    return np.clip(np.asarray(image, np.float64) * camera_exposure(image), 0.0, 1.0)


def detection_view(image: np.ndarray, clip_level: float | None) -> tuple[np.ndarray, float]:
    """The image automatic detection searches, and its clip level: a linear HDR one
    (``clip_level`` None, it does not clip) as a camera would have exposed it
    (:func:`exposed_like_a_camera`, clipping at 1), any other as it is."""
    if clip_level is None:
        return exposed_like_a_camera(image), 1.0
    return image, clip_level


def find_spheres(image: np.ndarray, camera: Camera, clip_level: float | None = None, extra=(),
                 radius_bound=None, outline_check=None) -> list[dict]:
    """Refined sphere candidates with their features: ``sphere``, ``edge_support``,
    ``contrast``, ``residual``, ``chrome`` and ``diffuse`` (bool), best supported first.
    Of candidates of one kind and similar radius within half a radius of each other the
    best supported stays (:func:`_merge_candidate`); so does no circle lying inside a better
    supported one (a highlight or a reflection). ``clip_level``: the image's (1.0 for an
    integer file: a clipped highlight's contrast is then read as a lower bound,
    :func:`hough_circles`, :func:`sphere_features`; None for a linear HDR one that does not
    clip, which is searched as a camera would have exposed it, :func:`exposed_like_a_camera`).
    ``extra``: circles ``(cx, cy, r)`` proposed before the Hough circles (the learned
    locator's, :mod:`relight.probe.locator`), screened and refined as they are.
    ``radius_bound``: ``(cx, cy, r) -> float | None``, the largest radius a chrome sphere
    whose circle is found at ``(cx, cy, r)`` likely has (the learned locator's,
    :meth:`relight.probe.locator.CentreMap.radius_bound`; None: no opinion), which chooses
    among its nested outlines (:func:`_outermost_outline`, :func:`_drop_inner_circles`).
    ``outline_check``: ``(n, 3) circles -> (n, 3) circles``, where the chrome sphere's circle
    lies seen from each (the learned outline check's, :mod:`relight.probe.outline_check`),
    a second start for a chrome outline's fit (:func:`_checked_outline`) and the judge
    between two nested chrome circles (:func:`_drop_inner_circles`)."""
    image, clip_level = detection_view(image, clip_level)
    smoothed = _edge_image(image)
    out: list[dict] = []
    refined: list[tuple] = []

    screens: dict[tuple, tuple | None] = {}   # a circle's screen, once: the clipped-spot order reads it too

    def screened_at(cx, cy, r):
        if (cx, cy, r) not in screens:
            try:
                screens[cx, cy, r] = _screen(smoothed, camera, cx, cy, r)
            except ProbeError:
                screens[cx, cy, r] = None
        return screens[cx, cy, r]

    def screen(c):
        found = screened_at(*c)
        return -1 if found is None else found[0]
    # an extra proposal comes first: Hough circles refined to the same place then add
    # nothing (proposed after them, or only where they left no candidate, it found fewer
    # spheres on the held-out sets: docs/probe-history.md, twelfth round)
    proposals = ([(*(float(v) for v in c), PROPOSAL_RADIUS_HYPOTHESES) for c in extra]
                 + [(*c, RADIUS_HYPOTHESES) for c in hough_circles(image, clip_level, screen)])
    for cx, cy, r, hypotheses in proposals:
        # Hough circles near one already refined to the same place add nothing
        if any(math.hypot(cx - c[0], cy - c[1]) < 0.05 * r and abs(r - c[2]) < 0.05 * r for c in refined):
            continue
        refined.append((cx, cy, r))
        # cheap screen: is the strongest nearby edge on this circle often enough? The
        # circle is tried as proposed and at a slightly smaller and larger radius (a chrome
        # sphere's rim is faint where it mirrors its surroundings, so the proposed radius is
        # often off); those screening well enough are refined, the best supported stays
        screened = []
        for k in hypotheses:
            found = screened_at(cx, cy, r * k)
            if found is not None:
                screened.append((*found, r * k))
        if not screened:
            continue
        # every radius that passes the screen is refined: the screen keeps the proposed
        # centre, which is off on a chrome sphere as its radius is (the rim is faint on
        # one side), so it cannot rank the radii; the refinements can (the former rule,
        # another radius only when it screens 10% better, left scene 9's sphere out: its
        # proposal 3.6 px off centre and 20% too large)
        for near, guess, rk in screened:
            if near < MIN_EDGE_SUPPORT * EDGE_ANGLES:
                continue
            try:
                sphere, support = _refine_proposal(image, camera, guess, smoothed, rk)
            except ProbeError:
                continue
            if support < MIN_EDGE_SUPPORT:
                continue
            circle = outline_circle(camera, sphere)
            refined.append(circle)
            f = sphere_features(image, camera, sphere, clip_level)
            out = _merge_candidate(out, {"sphere": sphere, "circle": circle, "edge_support": support, **f,
                                         "chrome": is_chrome(f), "diffuse": is_diffuse(f)})
    for c in out:     # the largest radius the learned locator allows a chrome sphere there, if any
        c["radius_bound"] = radius_bound(*c["circle"]) if radius_bound and c["chrome"] else None
    out = [{**_outermost_outline(image, camera, c, smoothed, clip_level, c["radius_bound"]),
            "radius_bound": c["radius_bound"]} if c["chrome"] else c for c in out]
    if outline_check is not None:
        out = [_checked_outline(image, camera, c, smoothed, clip_level, outline_check) if c["chrome"] else c
               for c in out]
    for c in out:     # does its brightest spot look like a small light's highlight?
        c["highlight"] = highlight_likelihood(image, camera, c["sphere"]) if c["chrome"] else -10.0
    out = _drop_inner_circles(out)
    out = _drop_clipped_surroundings(out)
    out.sort(key=lambda c: -c["edge_support"])
    return out


def _check_gap(circle, seen) -> float | None:
    """How far from ``circle`` the learned outline check, asked from it, puts the sphere's
    circle ``seen`` (:func:`_circle_gap`); None when it has no opinion (it returns a circle it
    cannot judge as it went in)."""
    if all(float(a) == float(b) for a, b in zip(circle, seen)):
        return None
    return _circle_gap(circle, seen)


def _check_prefers(a: dict, b: dict) -> bool:
    """Whether the learned outline check, seen from each of two chrome circles, puts the
    sphere nearer to ``a`` than to ``b`` by more than :data:`CHECK_PREFER`."""
    ga, gb = a.get("check_gap"), b.get("check_gap")
    return a["chrome"] and b["chrome"] and ga is not None and gb is not None and ga + CHECK_PREFER < gb


def _drop_inner_circles(out: list[dict]) -> list[dict]:
    """``out`` without the circles inside a better supported one: a highlight or a
    reflection on that sphere (mostly inside: the smaller circle reaches at most 10% of the
    larger radius beyond it, and is not clearly better supported, by 0.02); unless it is a
    chrome circle within the largest radius the learned locator allows there
    (``radius_bound``) and the larger one is not: that is the mirror's surroundings, its
    contact shadow or a lit patch beside it. When the learned outline check prefers the
    inner chrome circle to the outer one (:func:`_check_prefers`), the outer one goes
    instead: a sphere's cast shadow on the floor, a dark crescent beside its lower rim,
    draws with its upper rim a circle a few pixels larger and lower, as well supported
    (the largest automatic errors on the team-like sets, twenty-third round; the check's
    second start had found the sphere's own circle, and this rule dropped it:
    docs/probe-history.md, twenty-fourth round)."""
    def too_large(c, o):
        bound = c.get("radius_bound")
        return bound is not None and c["circle"][2] <= bound < o["circle"][2]

    def within(c, o):   # the smaller ``c`` lies inside ``o``, which is at least as well supported
        return (o is not c and c["circle"][2] < o["circle"][2]
                and math.hypot(c["circle"][0] - o["circle"][0], c["circle"][1] - o["circle"][1])
                + c["circle"][2] < o["circle"][2] * 1.1 and o["edge_support"] >= c["edge_support"] - 0.02)
    return [c for c in out
            if not any(within(c, o) and not too_large(c, o) and not _check_prefers(c, o) for o in out)
            and not any(within(i, c) and _check_prefers(i, c) for i in out)]


def _drop_clipped_surroundings(out: list[dict]) -> list[dict]:
    """``out`` without the circles that are chrome only by the clipped highlight's allowance
    (their contrast below :data:`CHROME_MIN_CONTRAST`) and hold a better supported chrome
    circle (mostly inside: reaching at most 10% of the larger radius beyond it): on a bright
    background any circle drawn around a clipped highlight passes that allowance, so such a
    circle is the smaller sphere's surroundings."""
    def holds(c, o):
        return (o is not c and o["chrome"] and o["circle"][2] < c["circle"][2]
                and o["edge_support"] > c["edge_support"]
                and math.hypot(c["circle"][0] - o["circle"][0], c["circle"][1] - o["circle"][1]) + o["circle"][2]
                < c["circle"][2] * 1.1)
    return [c for c in out if not (c["chrome"] and c["contrast"] < CHROME_MIN_CONTRAST
                                   and any(holds(c, o) for o in out))]


def _screen(smoothed: np.ndarray, camera: Camera, cx: float, cy: float, r: float) -> tuple[int, Sphere]:
    """A circle's cheap screen: on how many radial lines the strongest edge within
    :data:`SUPPORT_BAND_FRACTION` of the radius (at least 4 px) lies within 5% of the radius
    (at least 2 px) of it; and its sphere (ProbeError when it has none)."""
    trial = sphere_from_circle(camera, cx, cy, r)
    x, y, _ = edge_points(smoothed, camera, trial, max(4.0, SUPPORT_BAND_FRACTION * r), prior=False)
    return int((np.abs(_outline_distance(camera, trial, x, y)) <= max(2.0, 0.05 * r)).sum()), trial


def _merge_candidate(out: list[dict], cand: dict) -> list[dict]:
    """``out`` with ``cand`` added, unless a candidate of the same kind (chrome or not) of
    similar radius (0.7-1.4 times) within half a radius is at least as well supported;
    those it beats go. One of the other kind does not count: a chrome sphere's inner
    reflection disc (the dim open top of a room), uniform and often the stronger circle,
    fits a smooth shading and looks diffuse, and must not hide the sphere around it."""
    cx, cy, r = cand["circle"]
    same = [c for c in out if math.hypot(cx - c["circle"][0], cy - c["circle"][1]) < 0.5 * max(r, c["circle"][2])
            and 0.7 < r / c["circle"][2] < 1.4 and c["chrome"] == cand["chrome"]]
    if any(c["edge_support"] >= cand["edge_support"] for c in same):
        return out
    return [c for c in out if not any(c is d for d in same)] + [cand]


def _outermost_outline(image: np.ndarray, camera: Camera, cand: dict, smoothed: np.ndarray,
                       clip_level: float | None = None, bound: float | None = None) -> dict:
    """A chrome candidate's outline is the outermost circular edge around it: a mirror
    sphere's reflections (the horizon of a floor, a window, a bright wall) draw smaller,
    often stronger, near-concentric circles inside it, and its rim is faint where it
    mirrors what lies beside it, so a fit may lock onto an inner one. Larger concentric
    circles (:data:`GROW_RADII` times the radius; when none of them grows,
    :data:`GROW_FINE_RADII`) are refined; the largest whose edge
    support (the strongest edge within half the gap to the inner circle) reaches
    :data:`GROW_MIN_SUPPORT_RATIO` of the candidate's (and :data:`MIN_EDGE_SUPPORT`),
    which contains it and is still chrome, replaces it, and the search goes on from
    there (at most :data:`GROW_ROUNDS` times).

    With a ``bound`` (the largest radius the learned locator allows there) the outline is
    the largest of all those found (the candidate's, and every larger one that passed)
    within it, the candidate's when none is: outermost is sometimes too far, the mirror's
    own surroundings (a contact shadow, a lit patch beside it) drawing a larger circle
    still, the commonest wrong detection left (docs/probe-history.md, thirteenth round)."""
    chain = [cand]
    for _ in range(GROW_ROUNDS):
        grown = _grow_once(image, camera, chain[-1], smoothed)
        if not grown:
            break
        chain += grown
    if bound is None:
        best = chain[-1]
    else:
        best = ([cand] + [c for c in chain[1:] if c["circle"][2] <= bound])[-1]
    sphere = outer_rim_fit(smoothed, camera, best["sphere"])
    # (the fit to the outermost edges moves the outline by at most 15%; not past the bound,
    # unless the outline already lies beyond it)
    if sphere is not best["sphere"] and (bound is None or outline_circle(camera, sphere)[2] <= max(
            bound, best["circle"][2])):
        f = sphere_features(image, camera, sphere, clip_level)
        if is_chrome(f):
            best = {**best, **f, "sphere": sphere, "circle": outline_circle(camera, sphere), "chrome": True,
                    "diffuse": is_diffuse(f)}
    return best


def _circle_gap(a, b) -> float:
    """How far circle ``b`` is from ``a``: centre distance in ``a``'s radii plus the
    radius ratio's absolute log."""
    return math.hypot(b[0] - a[0], b[1] - a[1]) / a[2] + abs(math.log(b[2] / a[2]))


def _checked_outline(image: np.ndarray, camera: Camera, cand: dict, smoothed: np.ndarray,
                     clip_level: float | None, check) -> dict:
    """A chrome candidate, or the outline fitted from where the learned outline check puts
    the sphere when it puts it elsewhere (more than :data:`CHECK_MOVE` away, by
    :func:`_circle_gap`): fitted there on a narrow band (:func:`refine_sphere`, then
    :func:`outer_rim_fit`), it replaces the candidate when it is chrome, edge-supported and
    the check, asked again from it, finds it nearer to where it belongs than the candidate
    was (an edge fit started on the contact shadow's circle stays there; started from the
    sphere, it keeps to the sphere). It keeps the better of the two edge supports, the
    pair's evidence (as a grown outline keeps its inner circle's). Either way the one
    returned holds its ``check_gap`` (:func:`_check_gap`), which judges nested circles
    (:func:`_drop_inner_circles`); ``cand`` is given its own."""
    first = check([cand["circle"]])[0]
    gap = cand["check_gap"] = _check_gap(cand["circle"], first)
    if gap is not None:
        cand["check_circle"] = tuple(float(v) for v in first)
    if gap is None or gap <= CHECK_MOVE:
        return cand
    try:
        guess = sphere_from_circle(camera, *first)
        sphere, support = refine_sphere(image, camera, guess, smoothed, first_band_px=max(2.0, 0.1 * first[2]))
    except ProbeError:
        return cand
    sphere = outer_rim_fit(smoothed, camera, sphere)
    circle = outline_circle(camera, sphere)
    if support < MIN_EDGE_SUPPORT:
        return cand
    again = check([circle])[0]
    if _circle_gap(circle, again) >= gap:
        return cand
    f = sphere_features(image, camera, sphere, clip_level)
    if not is_chrome(f):
        return cand
    # the pair's evidence, as a grown outline's: the better supported of the two stays
    return {**cand, **f, "sphere": sphere, "circle": circle, "edge_support": max(support, cand["edge_support"]),
            "chrome": True, "diffuse": is_diffuse(f), "checked_from": cand["circle"],
            "check_gap": _check_gap(circle, again), "check_circle": tuple(float(v) for v in again)}


def outer_rim_fit(smoothed: np.ndarray, camera: Camera, sphere: Sphere) -> Sphere:
    """A chrome sphere's outline fitted to its outermost edges (:func:`_outer_rim_pass`),
    the fit repeated from its own outline until it settles (moves less than
    :data:`RIM_FIT_SETTLED_PX`; at most :data:`RIM_FIT_ROUNDS` passes): each pass searches
    the edges around the outline the last one found, and one pass started from an outline
    that inner edges pulled in and up ends part of the way. Settled, it is repeated with
    each edge at its own gradient's peak (:func:`edge_points` ``peak``): on the harder
    probe set's Cycles renders the outline's centre is 0.137 px from the truth at the
    median, 0.159 without that last step (docs/probe-history.md, twentieth round). The
    fitted outline states its centre's error from the points its last pass kept
    (:func:`outline_centre_sigma_px`). Returns ``sphere`` itself when neither first pass
    finds a fit, or the outline would end more than 15% of the radius from it (a
    different circle)."""
    cx0, cy0, r0 = outline_circle(camera, sphere)
    fitted, kept = sphere, None
    for peak in (False, True):
        for _ in range(RIM_FIT_ROUNDS):
            new, points = _outer_rim_pass(smoothed, camera, fitted, peak)
            if new is fitted:
                break
            a, b = outline_circle(camera, fitted), outline_circle(camera, new)
            fitted, kept = new, points
            if max(math.hypot(b[0] - a[0], b[1] - a[1]), abs(b[2] - a[2])) < RIM_FIT_SETTLED_PX:
                break
    cx, cy, r = outline_circle(camera, fitted)
    if kept is None or math.hypot(cx - cx0, cy - cy0) > 0.15 * r0 or abs(r - r0) > 0.15 * r0:
        return sphere
    return dataclasses.replace(fitted, outline_sigma_px=outline_centre_sigma_px(camera, fitted, *kept))


def _outer_rim_pass(smoothed: np.ndarray, camera: Camera, sphere: Sphere, peak: bool = False
                    ) -> tuple[Sphere, tuple[np.ndarray, np.ndarray] | None]:
    """One pass of :func:`outer_rim_fit`. Where a chrome sphere's rim mirrors what lies
    right beside it (the floor it stands on and its own contact shadow, below it) the
    rim shows no edge, and the strongest edge near it is a reflection inside (the
    floor's far edge, a lit patch), which pulls a symmetric fit in and up. The outline is
    first fitted to the edge points on or outside it; then edge points more than
    :data:`CHROME_INSIDE_PX` inside it are left out, those outside by the usual robust
    rule, and the outline refitted until the set of points settles (twice, the second
    time searching a narrower band around the new outline). Returns ``sphere`` itself
    when fewer than 30% of the radial lines would remain, or the outline would move or
    change its radius by more than 15% of the radius (a different circle). Also returns the
    edge points the fit kept (``None`` with ``sphere``)."""
    cx0, cy0, r0 = outline_circle(camera, sphere)
    fitted = sphere
    for band in (2.0, 1.5):
        x, y, _ = edge_points(smoothed, camera, fitted, band, peak=peak)
        if x.size < 0.3 * EDGE_ANGLES:
            return sphere, None
        keep = np.ones(x.size, bool)
        dist = _outline_distance(camera, fitted, x, y)
        if band == 2.0 and (dist >= -ON_OUTLINE_PX).sum() >= 0.3 * EDGE_ANGLES:
            # start from the points on or outside the outline: a symmetric fit that the inner
            # edges pulled in and up leaves them within a fraction of a pixel of it, the rim's
            # own points (at the sides) outside
            keep = dist >= -ON_OUTLINE_PX
            try:
                fitted = fit_sphere(camera, x[keep], y[keep], robust=False)
            except ProbeError:
                return sphere, None
        for _ in range(10):
            dist = _outline_distance(camera, fitted, x, y)
            kept = dist[keep]
            mad = 1.4826 * np.median(np.abs(kept - np.median(kept)))
            new = ((dist >= -CHROME_INSIDE_PX - ON_OUTLINE_PX)
                   & (dist <= max(REJECT_MIN_PX, REJECT_SIGMAS * mad) + ON_OUTLINE_PX))
            if new.sum() < 0.3 * EDGE_ANGLES:
                return sphere, None
            if np.array_equal(new, keep):
                break
            keep = new
            try:
                fitted = fit_sphere(camera, x[keep], y[keep], robust=False)
            except ProbeError:
                return sphere, None
    cx, cy, r = outline_circle(camera, fitted)
    if math.hypot(cx - cx0, cy - cy0) > 0.15 * r0 or abs(r - r0) > 0.15 * r0:
        return sphere, None
    return fitted, (x[keep], y[keep])


def _grow_once(image: np.ndarray, camera: Camera, cand: dict, smoothed: np.ndarray) -> list[dict]:
    """One round of :func:`_outermost_outline`: the larger outlines around ``cand`` that pass,
    smallest first (each at least 8% larger than the one before; empty when none does).
    A grown outline must pass the chrome test without the clipped highlight's allowance
    (:data:`CHROME_MIN_CLIPPED_CONTRAST`): its edge evidence is weaker (a narrow band), and
    any circle drawn around a clipped highlight on a bright background would pass it."""
    cx, cy, r = cand["circle"]
    grown: list[dict] = []
    for k in (*GROW_RADII, *GROW_FINE_RADII):
        if k in GROW_FINE_RADII and grown:
            break
        try:
            guess = sphere_from_circle(camera, cx, cy, r * k)
            sphere, _ = refine_sphere(image, camera, guess, smoothed, first_band_px=max(3.0, 0.12 * r * k))
        except ProbeError:
            continue
        c2 = outline_circle(camera, sphere)
        largest = grown[-1]["circle"][2] if grown else r
        if not (c2[2] > largest * 1.08 and math.hypot(c2[0] - cx, c2[1] - cy) + r <= c2[2] * 1.05):
            continue
        # its support: the strongest edge in a band reaching halfway to the inner circle
        # (the inner one may well be stronger: it is a reflection of something bright)
        band = max(2.0, 0.5 * (c2[2] - r))
        support = _edge_support(camera, sphere, *edge_points(smoothed, camera, sphere, band, prior=False)[:2])
        if support < max(MIN_EDGE_SUPPORT, GROW_MIN_SUPPORT_RATIO * cand["edge_support"]):
            continue
        f = sphere_features(image, camera, sphere)
        if is_chrome(f):   # the pair's evidence: the inner circle's support stays
            grown.append({"sphere": sphere, "circle": c2, "edge_support": cand["edge_support"], **f,
                          "chrome": True, "diffuse": is_diffuse(f)})
    return grown


def is_chrome(f: dict) -> bool:
    """A chrome sphere shows a compact highlight much brighter than the rest of it (a
    single pixel will do: a 10 px sphere's highlight is that small), and its pixels fit
    no smooth shading; or, the mirror of an evenly lit world, it is a flat disc
    (``flatness`` at most :data:`CHROME_FLAT`) around a highlight that one light on a
    diffuse sphere leaves unexplained (:data:`CHROME_FLAT_EXCESS`): a flat disc fits a
    smooth shading as well as a diffuse ball does, but a diffuse ball under a light shades
    across it, and one lit evenly shows no highlight (unless a hot pixel or a renderer's
    firefly lands on it: docs/probe-history.md, thirtieth round). A highlight that clips
    is only known to be at least the clip level: its contrast is then
    :data:`CHROME_MIN_CLIPPED_CONTRAST` or more over the median (a mirror of a bright room
    in 8-bit cannot show :data:`CHROME_MIN_CONTRAST`)."""
    bright = f["contrast"] >= CHROME_MIN_CONTRAST or (
        f.get("clipped", False) and f.get("clip_contrast", 0.0) >= CHROME_MIN_CLIPPED_CONTRAST)
    flat_mirror = f.get("flatness", 1.0) <= CHROME_FLAT and f["blob_excess"] >= CHROME_FLAT_EXCESS
    return (bright and f["blob_pixels"] >= 1
            and f["blob_fraction"] <= CHROME_MAX_BLOB_FRACTION and f["blob_excess"] >= CHROME_MIN_EXCESS
            and (f["residual"] >= CHROME_MIN_RESIDUAL or flat_mirror))


def is_diffuse(f: dict) -> bool:
    """A diffuse sphere's shading fits a smooth or one-light model, with no highlight."""
    return f["residual"] <= DIFFUSE_MAX_RESIDUAL and f["mean"] > 0.005 and not is_chrome(f)


def _pool(candidates: list[dict], kind: str, exclude) -> list[dict]:
    """Candidates of ``kind`` not overlapping an ``exclude`` circle; for chrome also those
    the rules call neither chrome nor diffuse where the learned locator puts at least
    :data:`LOCATOR_ADMIT` of its probability (a chrome sphere whose highlight test fails:
    a dim light, a highlight spread by a blurred lens)."""
    def of_kind(c):
        return c[kind] or (kind == "chrome" and not c["diffuse"] and c.get("locator", 0.0) >= LOCATOR_ADMIT)
    return [c for c in candidates if of_kind(c) and not any(
        math.hypot(c["circle"][0] - e[0], c["circle"][1] - e[1]) < c["circle"][2] + e[2] for e in exclude)]


def share_the_rest(candidates: list[dict]) -> None:
    """Give the circles the learned locator cannot judge (no ``locator`` probability: larger
    than it was trained on) what its map leaves over: one less the most it puts near any
    chrome candidate it judges (``locator_rest``, a prior for the pick, never an admission).
    Where it is sure the sphere is one of the small circles, a large one is unlikely to be it;
    where it puts little near any, a large circle keeps nearly the prior of a sure one."""
    judged = [c["locator"] for c in _pool(candidates, "chrome", ()) if "locator" in c]
    if not judged:
        return
    rest = 1.0 - max(judged)
    for c in candidates:
        if "locator" not in c:
            c["locator_rest"] = rest


def _pick_score(c: dict, kind: str) -> float:
    """How much a candidate looks like the ``kind`` sphere (:func:`pick_sphere`)."""
    if kind == "chrome":   # the clearest outline, a bright highlight that looks like a small
        # light's (:func:`relight.probe.geometry.highlight_likelihood`), a large sphere (a
        # chrome sphere's outline is often faint where it reflects what lies beside it, and
        # its reflections show smaller circles inside it)
        # (a clipped highlight's contrast is at least the clip level over the median: ``clip_contrast``);
        # with the learned locator's probability near its centre when it ran (``locator``)
        p = c.get("locator", c.get("locator_rest"))
        prior = LOCATOR_WEIGHT * math.log(max(p, LOCATOR_FLOOR)) if p is not None else 0.0
        return (prior + c["edge_support"]
                + 0.1 * min(math.log10(max(c["contrast"], c.get("clip_contrast", 0.0))), 3.0) / 3.0
                + PICK_HIGHLIGHT_WEIGHT * max(c.get("highlight", 0.0), -3.0)
                + PICK_RADIUS_WEIGHT * math.log(max(c["circle"][2], 1.0) / 20.0))
    # the clearest outline, the smoothest shading, and (slightly) the larger sphere
    return c["edge_support"] - 0.5 * c["residual"] + 0.05 * math.log(max(c["circle"][2], 1.0) / 20.0)


def pick_sphere(candidates: list[dict], kind: str, exclude: list[tuple] = ()) -> dict:
    """The best candidate of ``kind`` ("chrome" or "diffuse") not overlapping ``exclude``
    circles: the best edge support, nudged by the highlight's contrast and the radius
    (chrome) or by a smooth shading and (less) the radius (diffuse)."""
    pool = _pool(candidates, kind, exclude)
    if not pool:
        seen = ", ".join(f"({c['circle'][0]:.0f}, {c['circle'][1]:.0f}, r {c['circle'][2]:.0f})"
                         for c in candidates[:3]) or "none"
        raise ProbeError(f"no {kind} sphere found (circles seen: {seen}); give --{kind}-circle or --{kind}-mask")
    return max(pool, key=lambda c: _pick_score(c, kind))


def rival_sphere(candidates: list[dict], picked: dict, kind: str, exclude: list[tuple] = ()
                 ) -> tuple[dict | None, float]:
    """The runner-up to ``picked`` (:func:`pick_sphere`'s choice) that draws another circle
    (its centre more than a third of the radius away, or its radius 20% off), and by how
    much it scores less; ``(None, inf)`` when there is none. Within
    :data:`DETECTION_MARGIN` the detection is ambiguous: on 100 scenes of the harder probe
    set (Cycles PNG; the tuning 40 and a first held-out 60), 4 of the 11 chosen circles
    with a runner-up that close were wrong (errors of 39-137 deg), and 2 of the other 89
    erred by more than 20 deg (21 and 74); on a second held-out 60, made after the margin
    was chosen, it caught none of the 4 wrong circles (docs/probe.md, "Error budget")."""
    cx, cy, r = picked["circle"]
    others = [c for c in _pool(candidates, kind, exclude) if c is not picked and (
        math.hypot(c["circle"][0] - cx, c["circle"][1] - cy) > r / 3.0 or abs(math.log(c["circle"][2] / r)) > 0.2)]
    if not others:
        return None, math.inf
    best = max(others, key=lambda c: _pick_score(c, kind))
    return best, _pick_score(picked, kind) - _pick_score(best, kind)

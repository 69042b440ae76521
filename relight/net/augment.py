"""Camera-pipeline augmentation: a linear render turned into the 8-bit image a camera
might have written, at training time.

A render is scene-referred linear RGB; a photograph has gone through a camera: an
exposure, a tone curve, sensor noise, optics (blur, vignetting) and JPEG compression.
Applying these to the stored linear EXR when an image is read (instead of baking one
choice into the dataset's PNG) lets one render serve many pipelines, and keeps the label
true: none of them moves the light or changes its colour (every curve acts on the three
channels alike, and the white balance is left alone, since the light's colour is the label).

Each effect, drawn independently per image from ``numpy.random.Generator``:

* exposure: a gain of ``2 ** ev``, ``ev`` uniform in :attr:`PipelineAugment.exposure_ev`;
* sensor noise, Poisson-Gaussian (Foi et al. 2008): variance ``a * x + b`` per pixel, with
  ``a`` log-uniform in ``photon_a`` and ``b = read_sigma ** 2``;
* veiling glare (with probability ``glare_p``, 0 in ``"photo"``): light scattered in the
  lens and stray light in the scene, a smooth field added to the linear image, of the
  image's mean colour times ``g``, ``g`` log-uniform in ``glare``: a blend of a ramp of
  random direction and a broad Gaussian at a random place, at most 1; it lifts dark
  surroundings in a pattern unrelated to the light, and barely changes lit surfaces;
* vignetting: ``1 - v * (r / r_corner) ** 2``, ``v`` uniform in ``vignette``;
* blur: a Gaussian of ``sigma`` pixels (at network size) uniform in ``blur_px``;
* tone curve, one of: the sRGB transfer (:func:`relight.colour.srgb_encode`); a pure gamma
  ``x ** (1 / g)``, ``g`` in ``gamma``; a filmic curve (Hable's "Uncharted 2" operator,
  white point 11.2, exposure bias 2) followed by the sRGB transfer; with ``"linear"`` among
  ``tone_curves``, none at all (the code proportional to the light, as machine-vision and
  scientific cameras and photometric-stereo sets store it); then 8-bit quantisation;
* JPEG at a quality uniform in ``jpeg_quality`` (OpenCV's encoder), with probability
  ``jpeg_p``.

``AUGMENTS`` names the pipelines training can use: ``"photo"`` draws the first three curves
and no glare (the shipped photo model's recipe), ``"photo-linear"`` all four curves,
``"photo-glare"`` the photo pipeline with glare on half the images, ``"photo-srgb"`` the photo
pipeline with the sRGB curve only (a camera whose response is known; docs/photo.md, ninth round).

``PipelineAugment.none()`` is the identity pipeline: the sRGB transfer at exposure 1 and
8-bit quantisation, exactly how the dataset PNGs are written (:func:`relight.imageio.to_srgb8`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from relight import colour

__all__ = [
    "TONE_CURVES",
    "DISPLAY_CURVES",
    "HABLE_WHITE",
    "HABLE_EXPOSURE_BIAS",
    "AUGMENTS",
    "hable",
    "glare_field",
    "PipelineAugment",
]

TONE_CURVES = ("srgb", "gamma", "filmic", "linear")
DISPLAY_CURVES = TONE_CURVES[:3]   # the "photo" pipeline's: a display encoding after the camera
HABLE_WHITE = 11.2   # Hable's linear white point
HABLE_EXPOSURE_BIAS = 2.0   # the gain before the curve in Hable's sample code


def hable(x: np.ndarray) -> np.ndarray:
    """Hable's filmic curve (J. Hable, "Uncharted 2: HDR Lighting", GDC 2010), normalised so
    that :data:`HABLE_WHITE` maps to 1: ``f(x) / f(W)`` with
    ``f(x) = ((x (A x + C B) + D E) / (x (A x + B) + D F)) - E / F``,
    A = 0.15, B = 0.50, C = 0.10, D = 0.20, E = 0.02, F = 0.30."""
    a, b, c, d, e, f = 0.15, 0.50, 0.10, 0.20, 0.02, 0.30

    def curve(v):
        return (v * (a * v + c * b) + d * e) / (v * (a * v + b) + d * f) - e / f
    return curve(np.maximum(x, 0.0)) / curve(HABLE_WHITE)


def glare_field(shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """A smooth random field ``(H, W)`` in [0, 1]: a ramp of random direction blended with a
    broad Gaussian (sigma 0.3-1 of the half-size) at a random place, by a random weight."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    u, v = (xx + 0.5) / w * 2.0 - 1.0, (yy + 0.5) / h * 2.0 - 1.0
    theta = rng.uniform(0.0, 2.0 * np.pi)
    ramp = np.clip(0.5 + 0.5 * (np.cos(theta) * u + np.sin(theta) * v) / np.sqrt(2.0), 0.0, 1.0)
    cx, cy, sigma = rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(0.3, 1.0)
    blob = np.exp(-((u - cx) ** 2 + (v - cy) ** 2) / (2.0 * sigma ** 2))
    t = rng.uniform()
    return t * ramp + (1.0 - t) * blob


@dataclass(frozen=True)
class PipelineAugment:
    """Ranges of the camera-pipeline effects (see the module docstring)."""
    exposure_ev: tuple[float, float] = (-2.0, 2.0)
    photon_a: tuple[float, float] = (1e-4, 1e-2)
    read_sigma: tuple[float, float] = (0.0, 0.01)
    vignette: tuple[float, float] = (0.0, 0.4)
    blur_px: tuple[float, float] = (0.0, 1.0)
    tone_curves: tuple[str, ...] = DISPLAY_CURVES
    gamma: tuple[float, float] = (1.8, 2.6)
    jpeg_quality: tuple[int, int] = (40, 100)
    jpeg_p: float = 0.5
    glare: tuple[float, float] = (0.01, 0.5)
    glare_p: float = 0.0
    identity: bool = False

    def __post_init__(self):
        unknown = set(self.tone_curves) - set(TONE_CURVES)
        if unknown or not self.tone_curves:
            raise ValueError(f"tone_curves: expected some of {', '.join(TONE_CURVES)}, got {self.tone_curves}")
        if not 0.0 <= self.jpeg_p <= 1.0:
            raise ValueError(f"jpeg_p must be in [0, 1], got {self.jpeg_p}")
        if not 0.0 <= self.glare_p <= 1.0 or not 0.0 < self.glare[0] <= self.glare[1]:
            raise ValueError(f"glare_p must be in [0, 1] and glare 0 < lo <= hi, got {self.glare_p}, {self.glare}")
        if not 1 <= self.jpeg_quality[0] <= self.jpeg_quality[1] <= 100:
            raise ValueError(f"jpeg_quality: expected 1 <= lo <= hi <= 100, got {self.jpeg_quality}")

    @classmethod
    def none(cls) -> "PipelineAugment":
        """The identity pipeline (how the dataset PNGs are written)."""
        return cls(identity=True)

    def apply(self, linear: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """``(H, W, 3)`` linear RGB -> ``(H, W, 3)`` uint8 as a camera pipeline drawn from ``rng``."""
        x = np.asarray(linear, dtype=np.float64)
        if self.identity:
            return np.round(colour.srgb_encode(np.clip(x, 0.0, 1.0)) * 255.0).astype(np.uint8)
        x = x * 2.0 ** rng.uniform(*self.exposure_ev)
        a = float(np.exp(rng.uniform(np.log(self.photon_a[0]), np.log(self.photon_a[1]))))
        b = float(rng.uniform(*self.read_sigma)) ** 2
        x = np.maximum(x, 0.0)
        if self.glare_p > 0 and rng.uniform() < self.glare_p:   # drawn only when on: "photo" is unchanged
            x = x + glare_field(x.shape[:2], rng)[..., None] * x.mean(axis=(0, 1)) * float(
                np.exp(rng.uniform(np.log(self.glare[0]), np.log(self.glare[1]))))
        x = x + np.sqrt(a * x + b) * rng.standard_normal(x.shape)
        h, w = x.shape[:2]
        yy, xx = np.mgrid[0:h, 0:w]
        r2 = ((yy + 0.5 - h / 2) ** 2 + (xx + 0.5 - w / 2) ** 2) / ((h / 2) ** 2 + (w / 2) ** 2)
        x = x * (1.0 - rng.uniform(*self.vignette) * r2)[..., None]
        sigma = float(rng.uniform(*self.blur_px))
        if sigma > 0.05:
            from scipy.ndimage import gaussian_filter
            x = gaussian_filter(x, sigma=(sigma, sigma, 0), mode="nearest")
        curve = self.tone_curves[int(rng.integers(0, len(self.tone_curves)))]
        x = np.clip(x, 0.0, None)
        if curve == "srgb":
            y = colour.srgb_encode(np.clip(x, 0.0, 1.0))
        elif curve == "gamma":
            y = np.clip(x, 0.0, 1.0) ** (1.0 / rng.uniform(*self.gamma))
        elif curve == "linear":
            y = np.clip(x, 0.0, 1.0)
        else:
            y = colour.srgb_encode(np.clip(hable(x * HABLE_EXPOSURE_BIAS), 0.0, 1.0))
        out = np.round(np.clip(y, 0.0, 1.0) * 255.0).astype(np.uint8)
        if rng.uniform() < self.jpeg_p:
            import cv2
            q = int(rng.integers(self.jpeg_quality[0], self.jpeg_quality[1] + 1))
            ok, buf = cv2.imencode(".jpg", out[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, q])
            if ok:
                out = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1].copy()
        return out


def _photo_linear() -> PipelineAugment:
    return PipelineAugment(tone_curves=TONE_CURVES)


def _photo_glare() -> PipelineAugment:
    return PipelineAugment(glare_p=0.5)


def _photo_srgb() -> PipelineAugment:
    return PipelineAugment(tone_curves=("srgb",))


AUGMENTS = {"none": PipelineAugment.none, "photo": PipelineAugment,   # TrainConfig.augment -> pipeline
            "photo-linear": _photo_linear, "photo-glare": _photo_glare, "photo-srgb": _photo_srgb}

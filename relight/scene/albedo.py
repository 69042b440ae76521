"""Surface-colour priors: the albedos of walls, floor textures and objects.

In a scene lit by one light, a diffuse surface shows ``albedo x light colour``, so how
well the light's colour can be recovered from an image depends on the prior over
surface colours. The prior is a named generator setting (``--colour-prior``),
recorded in the dataset card, every scene file and every manifest record:

``hsv``
    relight's first prior: texture colours of one texture share a random hue
    (HSV, saturation up to 0.75, value 0.25-1 in sRGB, then linearised); object
    reflectances uniform in [0.1, 0.85] per channel.
``munsell``
    measured real surfaces: chips of the Munsell renotation "real" set (Newhall,
    Nickerson & Judd 1943; 2,734 colours, as shipped by colour-science), xyY under
    illuminant C, adapted to D65 (Bradford) and converted to linear Rec.709; chips
    outside the RGB gamut are dropped. Every colour, texture or object, is one chip
    drawn uniformly, independently of the others.
``mixture``
    each scene draws ``hsv`` or ``munsell`` with equal odds (the scene records which).
``pastel``
    the objects of ``--preset sid2-paper``: one flat pastel colour per part, hue uniform,
    sRGB saturation uniform in :data:`PASTEL_SATURATION` (0.23-0.40) and value
    :data:`PASTEL_VALUE` (0.87), then linearised (what is known of how the paper's group
    colours ShapeNet parts); textures as ``hsv``.

All albedos are linear RGB in [ALBEDO_MIN, ALBEDO_MAX] (textures) or [0, 1]
(objects); every random draw comes from the caller's ``numpy.random.Generator``.
"""
from __future__ import annotations

__all__ = [
    "PRIORS", "DEFAULT_PRIOR", "ALBEDO_MIN", "ALBEDO_MAX", "OBJECT_RANGE", "MUNSELL_Y_RANGE",
    "munsell_albedos", "hsv_texture_albedos", "texture_colours", "object_reflectance", "box_direction_logpdf",
    "CHROMA_BINS", "chromaticity", "chromaticity_log_density", "scaled_chromaticity_logpdf",
    "shared_hue_logpdf", "posterior_mean_light", "ideal_observer_errors", "scene_prior",
    "pastel_albedos",
]

import functools

import numpy as np

from relight.colour import luminance, srgb_decode

PRIORS: tuple[str, ...] = ("hsv", "munsell", "mixture", "pastel")
DEFAULT_PRIOR = "hsv"
ALBEDO_MIN = 0.05          # texture albedo range (linear)
ALBEDO_MAX = 0.9
OBJECT_RANGE = (0.1, 0.85)  # the hsv prior's object reflectance range, per channel
MUNSELL_Y_RANGE = (0.03, 0.9)  # luminous reflectance of the Munsell chips kept
PASTEL_SATURATION = (0.23, 0.40)   # the pastel prior's objects: sRGB HSV saturation ...
PASTEL_VALUE = 0.87                # ... and value


def _hsv_to_rgb(h: np.ndarray, s: np.ndarray, v: np.ndarray) -> np.ndarray:
    k = (np.array([5.0, 3.0, 1.0]) + h[:, None] * 6.0) % 6.0
    return v[:, None] - v[:, None] * s[:, None] * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)


def _round(colours: np.ndarray) -> list[list[float]]:
    return [[round(float(x), 4) for x in c] for c in colours]


@functools.lru_cache(maxsize=1)
def munsell_albedos() -> np.ndarray:
    """``(n, 3)`` linear Rec.709 reflectances of the in-gamut Munsell "real" chips
    with luminous reflectance in :data:`MUNSELL_Y_RANGE`."""
    import colour
    from colour.notation.datasets import MUNSELL_COLOURS_REAL
    xyY = np.array([c[1] for c in MUNSELL_COLOURS_REAL], dtype=np.float64)
    xyY[:, 2] /= 100.0
    xyz_c = colour.xyY_to_XYZ(xyY)
    observer = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]
    xyz_c_white = colour.xy_to_XYZ(observer["C"])
    xyz_d65_white = colour.xy_to_XYZ(observer["D65"])
    xyz = colour.chromatic_adaptation(xyz_c, xyz_c_white, xyz_d65_white, method="Von Kries",
                                      transform="Bradford")
    rgb = colour.XYZ_to_RGB(xyz, colour.RGB_COLOURSPACES["sRGB"], apply_cctf_encoding=False)
    keep = (rgb.min(1) >= 0.0) & (rgb.max(1) <= 1.0) \
        & (xyY[:, 2] >= MUNSELL_Y_RANGE[0]) & (xyY[:, 2] <= MUNSELL_Y_RANGE[1])
    return rgb[keep]


def hsv_texture_albedos(rng: np.random.Generator, n: int, base_hue: float) -> np.ndarray:
    """``(n, 3)`` linear albedos of one ``hsv`` texture whose colours share ``base_hue``
    (hue in [0, 1)): each colour's hue is the base plus N(0, 0.1), and with odds 0.4 a turn
    of 0.2-0.8; saturation 0-0.75 and value 0.25-1 (sRGB) each; colours 0 and 1 contrast in
    value. :func:`texture_colours` draws the base hue uniformly."""
    hue = (base_hue + rng.normal(0.0, 0.1, n) + (rng.random(n) < 0.4) * rng.uniform(0.2, 0.8, n)) % 1.0
    sat = rng.uniform(0.0, 0.75, n)
    val = rng.uniform(0.25, 1.0, n)
    if n > 1 and abs(val[0] - val[1]) < 0.25:
        val[1] = val[0] - 0.35 if val[0] > 0.6 else val[0] + 0.35
    lin = ALBEDO_MIN + (ALBEDO_MAX - ALBEDO_MIN) * srgb_decode(_hsv_to_rgb(hue, sat, val))
    return np.clip(lin, ALBEDO_MIN, ALBEDO_MAX)


def pastel_albedos(rng: np.random.Generator, n: int) -> np.ndarray:
    """``(n, 3)`` linear albedos of the ``pastel`` prior: hue uniform in [0, 1), sRGB
    saturation uniform in :data:`PASTEL_SATURATION`, value :data:`PASTEL_VALUE`, decoded
    from sRGB (three draws per colour: hue, saturation; the value is fixed)."""
    hue = rng.random(n)
    sat = rng.uniform(*PASTEL_SATURATION, n)
    return srgb_decode(_hsv_to_rgb(hue, sat, np.full(n, PASTEL_VALUE)))


def texture_colours(rng: np.random.Generator, n: int, prior: str = "hsv") -> list[list[float]]:
    """``n`` linear-RGB albedos for one texture; colours 0 and 1 contrast in value
    (``pastel`` textures are ``hsv`` ones)."""
    if prior in ("hsv", "pastel"):
        return _round(hsv_texture_albedos(rng, n, rng.random()))
    if prior == "munsell":
        table = munsell_albedos()
        idx = rng.integers(0, len(table), n)
        if n > 1:  # contrast: colour 1 at least 2x lighter or darker than colour 0
            lum = luminance(table)
            for _ in range(50):
                a, b = lum[idx[0]], lum[idx[1]]
                if max(a, b) >= 2.0 * min(a, b):
                    break
                idx[1] = rng.integers(0, len(table))
        return _round(np.clip(table[idx], ALBEDO_MIN, ALBEDO_MAX))
    raise ValueError(f"unknown colour prior {prior!r}; valid: hsv, munsell, pastel")


def object_reflectance(rng: np.random.Generator, prior: str = "hsv") -> tuple[float, float, float]:
    """Linear-RGB reflectance of one object."""
    if prior == "hsv":
        return tuple(float(np.round(c, 4)) for c in rng.uniform(*OBJECT_RANGE, 3))
    if prior == "munsell":
        table = munsell_albedos()
        return tuple(float(np.round(c, 4)) for c in table[int(rng.integers(0, len(table)))])
    if prior == "pastel":
        return tuple(float(np.round(c, 4)) for c in pastel_albedos(rng, 1)[0])
    raise ValueError(f"unknown colour prior {prior!r}; valid: hsv, munsell, pastel")


def box_direction_logpdf(u: np.ndarray, lights: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """``log p(u | l)``: the density of the direction ``u`` (N, 3) of ``a * l`` with ``a``
    uniform in the box ``[lo, hi]^3``, for each light ``l`` (M, 3); shape (N, M).

    In closed form: ``c = a * l`` has density ``1 / (V prod(l))`` on the box scaled by
    ``l``; along the ray ``c = s u`` that box holds ``s`` in ``[max_k lo l_k / u_k,
    min_k hi l_k / u_k]``, and ``p(u) = (s_hi^3 - s_lo^3) / (3 V prod(l))`` (up to the
    constant ``V``, the box volume). A shading factor scales ``c`` and leaves ``u``
    alone, so only the direction carries evidence: this is the likelihood of the ideal
    observer of ``benchmarks/bench_colour_floor.py`` (the hsv prior's objects)."""
    ratio = lights[None, :, :] / u[:, None, :]                  # (N, M, 3): l_k / u_k
    s_lo, s_hi = lo * ratio.max(-1), hi * ratio.min(-1)
    vol = np.clip(s_hi ** 3 - s_lo ** 3, 0.0, None) / 3.0
    return np.log(vol + 1e-30) - np.log(lights.prod(-1))[None, :]


CHROMA_BINS = 200   # bins per axis of the chromaticity grid (r / sum, g / sum, each in [0, 1])


def chromaticity(rgb) -> np.ndarray:
    """``(..., 3)`` RGB -> ``(..., 2)`` chromaticity ``(r, g) / (r + g + b)``."""
    c = np.asarray(rgb, dtype=np.float64)
    return c[..., :2] / c.sum(-1, keepdims=True)


def chromaticity_log_density(albedos: np.ndarray, bins: int = CHROMA_BINS, smooth_bins: float = 1.0) -> np.ndarray:
    """Log density ``(bins, bins)`` of the chromaticity of a prior's albedos, from draws
    ``(n, 3)``: a histogram on ``[0, 1]^2``, Gaussian-smoothed by ``smooth_bins`` bins and
    floored at 1e-6 of its peak (no candidate light is ruled out by an empty bin)."""
    from scipy.ndimage import gaussian_filter
    x = chromaticity(albedos)
    h, _, _ = np.histogram2d(x[:, 0], x[:, 1], bins=bins, range=[[0.0, 1.0], [0.0, 1.0]], density=True)
    h = gaussian_filter(h, smooth_bins)
    return np.log(np.maximum(h, 1e-6 * h.max()))


def scaled_chromaticity_logpdf(chrom: np.ndarray, lights: np.ndarray, log_density: np.ndarray) -> np.ndarray:
    """``log p(x | l)`` of the chromaticity ``x`` (N, 2) of ``a * l`` when the albedo's
    chromaticity has the density ``log_density`` (:func:`chromaticity_log_density`), for
    each light ``l`` (M, 3); shape (N, M). Any prior, where :func:`box_direction_logpdf`
    is the closed form of one.

    The albedo's chromaticity is that of ``v = x / l`` (x completed to three
    coordinates). The map from the albedo's chromaticity to the observed one is
    projective, ``a -> (l a) / (l . a)``, with Jacobian ``prod(l) / (l . a)^3 = prod(l)
    (sum v)^3``, so ``log p(x | l) = log p_a(v / sum v) - log prod(l) - 3 log sum v``;
    it does not change when ``l`` is scaled. A stack of densities ``(K, bins, bins)``
    (e.g. one per base hue of a texture) gives ``(K, N, M)``."""
    chrom = np.asarray(chrom, dtype=np.float64)
    chi = np.concatenate([chrom, 1.0 - chrom.sum(-1, keepdims=True)], -1)
    v = chi[:, None, :] / lights[None, :, :]
    total = v.sum(-1)
    bins = log_density.shape[-1]
    idx = np.clip((v[..., :2] / total[..., None] * bins).astype(np.int64), 0, bins - 1)
    return log_density[..., idx[..., 0], idx[..., 1]] - np.log(lights.prod(-1))[None, :] - 3.0 * np.log(total)


def shared_hue_logpdf(chrom: np.ndarray, lights: np.ndarray, by_hue: np.ndarray) -> np.ndarray:
    """``log p(x_1..x_n | l)`` (M,) of the colours of one ``hsv`` texture, which share a
    base hue: ``by_hue`` (K, bins, bins) holds the chromaticity log density given each of K
    base hues spread evenly over [0, 1) (:func:`hsv_texture_albedos`), and the base hue is
    integrated out (uniform prior)."""
    from scipy.special import logsumexp
    per_hue = scaled_chromaticity_logpdf(chrom, lights, by_hue).sum(1)      # (K, M)
    return logsumexp(per_hue, axis=0) - np.log(len(by_hue))


def posterior_mean_light(logp: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """The posterior-mean light colour (unit norm) from per-surface log-likelihoods
    ``logp`` (N, M) over ``candidates`` (M, 3) drawn from the light prior."""
    total = logp.sum(0)
    w = np.exp(total - total.max())
    mean = (w[:, None] * candidates / np.linalg.norm(candidates, axis=1, keepdims=True)).sum(0)
    return mean / np.linalg.norm(mean)


def ideal_observer_errors(n_surfaces: int, draws: int, candidates: np.ndarray,
                          rng: np.random.Generator) -> np.ndarray:
    """Colour error (degrees) of the ideal observer in ``draws`` scenes of ``n_surfaces``
    surfaces: each scene draws a light from the generator's prior and ``hsv`` object
    albedos (uniform in :data:`OBJECT_RANGE` per channel); the estimate is the posterior
    mean over ``candidates`` (lights drawn from the same prior) under
    :func:`box_direction_logpdf`. Its mean is the Bayes floor for N visible surfaces."""
    from relight.colour import sample_light_colour
    from relight.metrics import colour_error_deg
    lo, hi = OBJECT_RANGE
    errs = np.empty(draws)
    for i in range(draws):
        light = sample_light_colour(rng)[2]
        c = rng.uniform(lo, hi, (n_surfaces, 3)) * light
        logp = box_direction_logpdf(c / np.linalg.norm(c, axis=1, keepdims=True), candidates, lo, hi)
        errs[i] = colour_error_deg(posterior_mean_light(logp, candidates), light)
    return errs


def scene_prior(rng: np.random.Generator, prior: str) -> str:
    """The concrete prior of one scene (``mixture`` draws one; others draw nothing)."""
    if prior == "mixture":
        return ("hsv", "munsell")[int(rng.integers(0, 2))]
    if prior not in PRIORS:
        raise ValueError(f"unknown colour prior {prior!r}; valid: {', '.join(PRIORS)}")
    return prior

"""Light colour near the Planckian locus, and the sRGB image transfer functions.

Convention (``shared/conventions.md``):
    * A light's colour is a chromaticity near the Planckian locus, given by its
      correlated colour temperature ``cct_k`` (kelvin) and ``duv`` (signed distance
      from the locus in CIE 1960 uv, positive above it, i.e. toward green).
      Datasets sample CCT in :data:`CCT_RANGE_K` and ``|duv| <= DUV_MAX``.
    * Light RGB is *linear* (scene-referred) Rec.709/sRGB primaries, normalised to
      unit Euclidean norm; absolute strength is stored elsewhere. The conversion
      XYZ -> RGB uses the sRGB primaries matrix with *no* chromatic adaptation, so
      a 2856 K light is orange in RGB, not white.
    * One corner of the sampled range is outside the sRGB gamut (CCT < ~2535 K with
      Duv > ~+0.0094: blue < 0). Conversions return it exactly; sampling avoids it.
    * Gamma-encoded values only appear in images (:func:`srgb_encode` /
      :func:`srgb_decode`, the IEC 61966-2-1 piecewise curve).

The CCT/Duv maths is colour-science's (``"Ohno 2013"``, CIE 1931 2 degree
observer). ``colour`` is imported lazily (about 0.6 s without its plotting part), so
the sRGB curves stay cheap.

A second light-colour model, for ``relight generate --preset sid2-paper``: a colour
temperature alone (no Duv) in 100 K steps, turned into an RGB triplet by Tanner
Helland's kelvin-to-RGB approximation (:func:`kelvin_to_rgb_tanner_helland`), the
triplet used as it is (unit norm) as the light's linear colour in the renderer and in
the label, as the paper's research group makes its later datasets.
"""
from __future__ import annotations

import contextlib
import warnings

import numpy as np

__all__ = [
    "CCT_RANGE_K", "DUV_MAX", "CCT_VALID_K", "DUV_VALID_MAX",
    "cct_duv_to_xy", "xy_to_rgb", "cct_duv_to_rgb", "rgb_to_cct_duv", "rgb_to_cct_duv_near_locus",
    "sample_light_colour", "srgb_encode", "srgb_decode",
    "kelvin_to_rgb_tanner_helland", "LIGHT_COLOURS", "TANNER_HELLAND_RANGE_K", "CCT_STEP_K", "sample_cct_step_light",
    "REC709_LUMA", "luminance",
    "CCT_METHOD", "SRGB_LINEAR_KNEE", "SRGB_ENCODED_KNEE",
]

CCT_RANGE_K = (2500.0, 10000.0)  # sampling range of light CCTs, kelvin
DUV_MAX = 0.01                   # sampling range of |Duv|
CCT_VALID_K = (1000.0, 25000.0)  # accepted by the conversions (wider than sampled)
DUV_VALID_MAX = 0.05             # accepted |Duv|
CCT_METHOD = "Ohno 2013"
_MAX_DRAWS = 1000                # rejection-sampling bound of sample_light_colour

SRGB_LINEAR_KNEE = 0.0031308     # IEC 61966-2-1 break point, linear side
SRGB_ENCODED_KNEE = 0.04045      # the same break point, encoded side


def _colour():
    """colour-science, imported on first use, without its plotting subpackage.

    ``import colour`` (0.4) also imports ``colour.plotting`` and with it matplotlib:
    a third of its ~0.9 s, paid by the first image of every ``relight generate``. A
    placeholder stands in for ``colour.plotting`` during the import and is removed
    after it, so an explicit ``import colour.plotting`` later still loads the real one.
    """
    import sys
    if "colour" not in sys.modules and "colour.plotting" not in sys.modules:
        import types
        sys.modules["colour.plotting"] = types.ModuleType("colour.plotting")
        try:
            import colour  # noqa: PLC0415 (lazy)
        finally:
            del sys.modules["colour.plotting"]
    import colour  # noqa: PLC0415
    return colour


@contextlib.contextmanager
def _quiet():
    """Silence colour-science's own warnings, only inside the ``with`` block."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", _colour().utilities.ColourWarning)
        yield


def _check_cct_duv(cct_k, duv) -> tuple[np.ndarray, np.ndarray]:
    cct = np.asarray(cct_k, dtype=np.float64)
    d = np.asarray(duv, dtype=np.float64)
    if not np.all(np.isfinite(cct)) or np.any((cct < CCT_VALID_K[0]) | (cct > CCT_VALID_K[1])):
        raise ValueError(f"expected finite CCT in [{CCT_VALID_K[0]:g}, {CCT_VALID_K[1]:g}] K, "
                         f"got {cct.ravel()[:5]}")
    if not np.all(np.isfinite(d)) or np.any(np.abs(d) > DUV_VALID_MAX):
        raise ValueError(f"expected finite Duv with |Duv| <= {DUV_VALID_MAX:g}, got {d.ravel()[:5]}")
    return np.broadcast_arrays(cct, d)


def cct_duv_to_xy(cct_k, duv=0.0) -> np.ndarray:
    """CIE 1931 xy chromaticity of a (CCT, Duv) pair.

    Args:
        cct_k: correlated colour temperature in kelvin, [1000, 25000], any shape.
        duv: distance from the Planckian locus in CIE 1960 uv, [-0.05, 0.05],
            broadcast against ``cct_k``.

    Returns:
        ``(..., 2)`` xy (2 degree observer), via colour-science's Ohno 2013 method.
    """
    cct, d = _check_cct_duv(cct_k, duv)
    c = _colour()
    with _quiet():
        uv = c.temperature.CCT_to_uv(np.stack([cct, d], axis=-1), method=CCT_METHOD)
        return np.asarray(c.UCS_uv_to_xy(uv), dtype=np.float64)


def _xyz_to_rgb_matrix() -> np.ndarray:
    return np.asarray(_colour().RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB, dtype=np.float64)


def _rgb_to_xyz_matrix() -> np.ndarray:
    return np.asarray(_colour().RGB_COLOURSPACES["sRGB"].matrix_RGB_to_XYZ, dtype=np.float64)


def xy_to_rgb(xy) -> np.ndarray:
    """Linear Rec.709/sRGB RGB of a chromaticity, unit Euclidean norm.

    Args:
        xy: ``(..., 2)`` CIE 1931 xy with finite values and ``y > 0``.

    Returns:
        ``(..., 3)`` linear RGB (no chromatic adaptation: the colour of the light
        itself under sRGB primaries), normalised to norm 1. Components may be
        negative for chromaticities outside the sRGB gamut.
    """
    xy = np.asarray(xy, dtype=np.float64)
    if xy.shape[-1:] != (2,):
        raise ValueError(f"expected xy with last axis 2, got shape {xy.shape}")
    if not np.all(np.isfinite(xy)) or np.any(xy[..., 1] <= 0.0):
        raise ValueError("expected finite xy chromaticities with y > 0")
    x, y = xy[..., 0], xy[..., 1]
    xyz = np.stack([x / y, np.ones_like(x), (1.0 - x - y) / y], axis=-1)  # Y = 1
    rgb = xyz @ _xyz_to_rgb_matrix().T
    norm = np.linalg.norm(rgb, axis=-1, keepdims=True)
    if np.any(norm <= 0.0):
        raise ValueError("chromaticity maps to a zero RGB vector")
    return rgb / norm


def cct_duv_to_rgb(cct_k, duv=0.0) -> np.ndarray:
    """Linear RGB (unit norm, ``(..., 3)``) of a light of CCT ``cct_k`` (kelvin) and ``duv``.

    Within CCT in [2500, 10000] K and ``|duv| <= 0.01`` all components are > 0
    except in one corner outside the sRGB gamut: CCT below ~2535 K with Duv above
    ~+0.0094 gives a slightly negative blue (down to -0.004 at 2500 K, +0.01). The
    value is returned exactly (no gamut clipping); :func:`sample_light_colour`
    never draws it. Accepted inputs: CCT in [1000, 25000] K, ``|duv| <= 0.05`` (ValueError otherwise).
    """
    return xy_to_rgb(cct_duv_to_xy(cct_k, duv))


def rgb_to_cct_duv(rgb) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`cct_duv_to_rgb`, for reports.

    Args:
        rgb: ``(..., 3)`` linear sRGB, any positive scale (X+Y+Z must be > 0).

    Returns:
        ``(cct_k, duv)`` arrays of shape ``(...)``: RGB -> XYZ -> xy -> uv -> CCT, Duv
        with colour-science's Ohno 2013 method. Meaningful near the locus only.
    """
    rgb = np.asarray(rgb, dtype=np.float64)
    if rgb.shape[-1:] != (3,):
        raise ValueError(f"expected rgb with last axis 3, got shape {rgb.shape}")
    if not np.all(np.isfinite(rgb)):
        raise ValueError("expected finite rgb values")
    xyz = rgb @ _rgb_to_xyz_matrix().T
    total = xyz.sum(axis=-1)
    if np.any(total <= 0.0) or np.any(xyz[..., 1] <= 0.0):
        raise ValueError("expected rgb with positive luminance (X+Y+Z > 0 and Y > 0)")
    c = _colour()
    with _quiet():
        uv = c.xy_to_UCS_uv(xyz[..., :2] / total[..., None])
        out = np.asarray(c.temperature.uv_to_CCT(uv, method=CCT_METHOD), dtype=np.float64)
    return out[..., 0], out[..., 1]


def rgb_to_cct_duv_near_locus(rgb) -> tuple[np.ndarray, np.ndarray]:
    """:func:`rgb_to_cct_duv` where it is meaningful, NaN elsewhere: ``(cct_k, duv)``
    arrays of shape ``(...)`` for ``rgb`` ``(..., 3)`` (linear sRGB, any scale), NaN
    where the colour is far from the Planckian locus (``|duv| > DUV_VALID_MAX`` = 0.05,
    or CCT outside :data:`CCT_VALID_K` = [1000, 25000] K) or has no positive
    luminance (e.g. a grey-free saturated blue)."""
    rgb = np.asarray(rgb, dtype=np.float64)
    if rgb.shape[-1:] != (3,):
        raise ValueError(f"expected rgb with last axis 3, got shape {rgb.shape}")
    flat = rgb.reshape(-1, 3)
    cct, duv = np.full(len(flat), np.nan), np.full(len(flat), np.nan)
    xyz = np.where(np.isfinite(flat), flat, 0.0) @ _rgb_to_xyz_matrix().T
    ok = np.all(np.isfinite(flat), axis=1) & (xyz.sum(axis=1) > 0) & (xyz[:, 1] > 0)
    if np.any(ok):
        with warnings.catch_warnings():   # far colours make colour-science warn; they become NaN
            warnings.simplefilter("ignore")
            cct[ok], duv[ok] = rgb_to_cct_duv(flat[ok])
    far = ~(np.isfinite(cct) & np.isfinite(duv) & (np.abs(duv) <= DUV_VALID_MAX)
            & (cct >= CCT_VALID_K[0]) & (cct <= CCT_VALID_K[1]))
    cct[far], duv[far] = np.nan, np.nan
    return cct.reshape(rgb.shape[:-1]), duv.reshape(rgb.shape[:-1])


def sample_light_colour(rng: np.random.Generator) -> tuple[float, float, np.ndarray]:
    """Draw a light colour: ``(cct_k, duv, rgb)``.

    CCT is uniform in mireds (``1e6 / CCT``) over :data:`CCT_RANGE_K` (warm and cool
    lights balanced perceptually); Duv is uniform in ``[-DUV_MAX, DUV_MAX]``. Draws
    come in (mired, Duv) pairs; a pair whose RGB has a component <= 0 (the corner
    CCT < ~2535 K with Duv > ~+0.0094 lies just outside the sRGB gamut, about 0.03 %
    of draws) is rejected and redrawn, so ``rgb`` is always strictly positive and
    consistent with ``(cct_k, duv)``. ``rgb``: linear sRGB, unit norm, shape ``(3,)``.
    """
    lo_k, hi_k = CCT_RANGE_K
    for _ in range(_MAX_DRAWS):
        mired = rng.uniform(1e6 / hi_k, 1e6 / lo_k)
        cct_k = float(np.clip(1e6 / mired, lo_k, hi_k))
        duv = float(rng.uniform(-DUV_MAX, DUV_MAX))
        rgb = cct_duv_to_rgb(cct_k, duv)
        if np.all(rgb > 0.0):
            return cct_k, duv, rgb
    raise RuntimeError(f"no in-gamut light colour in {_MAX_DRAWS} draws")  # pragma: no cover


LIGHT_COLOURS = ("planckian", "tanner-helland")   # generator setting light_colour: the two models
TANNER_HELLAND_RANGE_K = (2000.0, 9900.0)   # --preset sid2-paper: the group's later sets' range ...
CCT_STEP_K = 100.0                          # ... in 100 K steps (80 temperatures)
TANNER_HELLAND_VALID_K = (1000.0, 40000.0)  # the range the approximation was fitted on


def kelvin_to_rgb_tanner_helland(kelvin) -> np.ndarray:
    """Tanner Helland's kelvin-to-RGB approximation: ``(..., 3)`` RGB in [0, 255].

    Published as "How to Convert Temperature (K) to RGB: Algorithm and Sample Code"
    (T. Helland, tannerhelland.com, 2012), a curve fit to Mitchell Charity's blackbody
    colour table (``bbr_color.txt``, CIE 1964 10 degree CMFs, sRGB primaries); fitted
    on 1000-40000 K. With ``t = kelvin / 100``:

    * red: 255 for ``t <= 66``, else ``329.698727446 (t - 60)^-0.1332047592``;
    * green: ``99.4708025861 ln t - 161.1195681661`` for ``t <= 66``, else
      ``288.1221695283 (t - 60)^-0.0755148492``;
    * blue: 255 for ``t >= 66``, 0 for ``t <= 19``, else
      ``138.5177312231 ln(t - 10) - 305.0447927307``;

    each clamped to [0, 255]. The published code divides by 100 in integers; for
    multiples of 100 K (the only ones relight draws) the two agree. Kelvin outside
    [1000, 40000] or non-finite: ValueError.

    >>> kelvin_to_rgb_tanner_helland(6600.0).tolist()
    [255.0, 255.0, 255.0]
    """
    k = np.asarray(kelvin, dtype=np.float64)
    if not np.all(np.isfinite(k)) or np.any((k < TANNER_HELLAND_VALID_K[0]) | (k > TANNER_HELLAND_VALID_K[1])):
        raise ValueError(f"expected kelvin in [{TANNER_HELLAND_VALID_K[0]:g}, {TANNER_HELLAND_VALID_K[1]:g}], "
                         f"got {k.ravel()[:5]}")
    t = k / 100.0
    hot = np.maximum(t - 60.0, 1e-9)        # only read where t > 66
    red = np.where(t <= 66.0, 255.0, 329.698727446 * hot ** -0.1332047592)
    green = np.where(t <= 66.0, 99.4708025861 * np.log(t) - 161.1195681661, 288.1221695283 * hot ** -0.0755148492)
    blue = np.where(t >= 66.0, 255.0, np.where(t <= 19.0, 0.0,
                                               138.5177312231 * np.log(np.maximum(t - 10.0, 1e-9)) - 305.0447927307))
    return np.clip(np.stack([red, green, blue], axis=-1), 0.0, 255.0)


def sample_cct_step_light(rng: np.random.Generator, range_k=TANNER_HELLAND_RANGE_K,
                          step_k: float = CCT_STEP_K) -> tuple[float, np.ndarray]:
    """Draw a light colour of ``--preset sid2-paper``: ``(kelvin, rgb)``, the temperature
    uniform over ``range_k`` (inclusive) in ``step_k`` steps (one integer draw: 2000,
    2100, ..., 9900 K by default) and ``rgb`` its Tanner-Helland triplet
    (:func:`kelvin_to_rgb_tanner_helland`) scaled to unit norm, shape ``(3,)``."""
    n = int(round((range_k[1] - range_k[0]) / step_k))
    kelvin = float(range_k[0] + step_k * int(rng.integers(0, n + 1)))
    rgb = kelvin_to_rgb_tanner_helland(kelvin)
    return kelvin, rgb / np.linalg.norm(rgb)
REC709_LUMA = np.array([0.2126, 0.7152, 0.0722])   # Y of the linear Rec.709 / sRGB primaries (ITU-R BT.709)


def luminance(rgb) -> np.ndarray:
    """Relative luminance ``Y`` of linear Rec.709 RGB: the one place its weights are written.

    Args:
        rgb: linear RGB, any shape ``(..., C)`` with ``C >= 3`` (channels past the third,
            e.g. alpha, are ignored); a list or an array of any float or integer type.

    Returns:
        ``Y = 0.2126 R + 0.7152 G + 0.0722 B``, float64 of shape ``rgb.shape[:-1]``
        (a 0-d array for one colour).

    >>> luminance(np.eye(3)).tolist()
    [0.2126, 0.7152, 0.0722]
    >>> float(luminance([0.5, 0.5, 0.5, 1.0]))    # grey: Y equals the channels; alpha ignored
    0.5
    """
    return np.asarray(rgb)[..., :3] @ REC709_LUMA


def _check_finite(values, what: str) -> np.ndarray:
    a = np.asarray(values, dtype=np.float64)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"expected finite {what} values")
    return a


def srgb_encode(linear) -> np.ndarray:
    """IEC 61966-2-1 sRGB encoding (linear -> display value), any shape.

    Input is clipped to [0, 1] first; output in [0, 1]. ``12.92 L`` for
    ``L <= 0.0031308``, else ``1.055 L^(1/2.4) - 0.055``. Non-finite input: ValueError.
    """
    lin = np.clip(_check_finite(linear, "linear"), 0.0, 1.0)
    p = np.power(np.maximum(lin, SRGB_LINEAR_KNEE), 1.0 / 2.4)
    high = p + 0.055 * (p - 1.0)  # = 1.055 p - 0.055, exactly 1 at p = 1
    return np.where(lin <= SRGB_LINEAR_KNEE, 12.92 * lin, high)


def srgb_decode(encoded) -> np.ndarray:
    """Inverse of :func:`srgb_encode` (display value -> linear), any shape.

    Input is clipped to [0, 1] first; ``E / 12.92`` for ``E <= 0.04045``, else
    ``((E + 0.055) / 1.055)^2.4``. Non-finite input: ValueError.
    """
    enc = np.clip(_check_finite(encoded, "encoded"), 0.0, 1.0)
    high = np.power((np.maximum(enc, SRGB_ENCODED_KNEE) + 0.055) / 1.055, 2.4)
    return np.where(enc <= SRGB_ENCODED_KNEE, enc / 12.92, high)

"""Procedural wall/floor albedo textures (pure numpy, never downloaded).

Conventions
-----------
* ``make_texture(params, size)`` returns a ``(size, size, 3)`` float32 image
  of **linear** RGB albedo (unitless reflectance) with values in [0, 1]; row 0
  is the top of the image (v = 1 - row/size if used as a texture), column 0 the
  left edge (u = col/size).
* Sampled colours are linear RGB in [ALBEDO_MIN, ALBEDO_MAX] = [0.05, 0.9], drawn
  from a surface-colour prior (:mod:`relight.scene.albedo`).
* Feature sizes are given in "features across the texture" (e.g. ``cells``
  checker squares per side), always a few to ~20, so patterns survive being
  seen small.  Pattern scales are independent of ``size`` (resolution).
* ``params`` fully determines the image: all randomness comes from
  ``np.random.default_rng(params["seed"])`` (phases, patch rectangles, noise
  lattices, dot jitter, per-tile variation), so the same params and size give
  bit-identical output.  The gradient and mosaic kinds do not use their seed.
* Everything is vectorised without BLAS calls (whose threads stall on a busy
  machine); make_texture(params, 256) takes about 1-3 ms.
"""
from __future__ import annotations

import functools
import json
__all__ = [
    "KINDS", "MOSAIC", "ALL_KINDS", "BACKGROUNDS", "MOSAIC_CELLS", "sample_texture_params", "make_texture",
    "background_library", "library_colours", "sample_background",
]

import math

import numpy as np

from relight.scene.albedo import ALBEDO_MAX, ALBEDO_MIN, texture_colours

KINDS: tuple[str, ...] = ("checker", "stripes", "patches", "noise", "gradient", "dots", "tiles")
MOSAIC = "mosaic"   # a grid of cells, each with its own colour from the prior (--backgrounds mosaic)
ALL_KINDS: tuple[str, ...] = KINDS + (MOSAIC,)
LIBRARY = "library"   # --backgrounds library: one of a closed set of LIBRARY_SIZE backgrounds per scene
UNSEEN = "unseen"     # --backgrounds unseen: backgrounds drawn like the library's, never one of its colours
BACKGROUNDS: tuple[str, ...] = ("patterns", MOSAIC, LIBRARY, UNSEEN)   # generator setting
MOSAIC_CELLS = (4, 16)   # rows and columns of a sampled mosaic (drawn independently)
LIBRARY_SIZE = 250        # backgrounds of the closed library (the paper group's ~250, shared by train and test)
LIBRARY_SEED = 30250      # the library's seed: background k is the k-th draw of default_rng(LIBRARY_SEED)
LIBRARY_KINDS: tuple[str, ...] = tuple(k for k in KINDS if k != "gradient")   # texture-like patterns
BACKGROUND_KEY = "background"   # texture params: "library:NNN" or "unseen" (make_texture ignores it)


# --------------------------------------------------------------------------- params
def _num(params: dict, key: str, lo: float, hi: float) -> float:
    kind = params.get("kind")
    try:
        x = float(params[key])
    except (KeyError, TypeError, ValueError):
        raise ValueError(f"texture {kind!r}: parameter {key!r} must be a number in [{lo}, {hi}]") from None
    if not lo <= x <= hi:
        raise ValueError(f"texture {kind!r}: parameter {key!r}={x} out of range, expected [{lo}, {hi}]")
    return x


def _int(params: dict, key: str, lo: int, hi: int) -> int:
    x = _num(params, key, lo, hi)
    if x != int(x):
        raise ValueError(f"texture {params.get('kind')!r}: parameter {key!r} must be an integer, got {x}")
    return int(x)


def _colours(params: dict, n_min: int, n_max: int) -> np.ndarray:
    try:
        col = np.asarray(params["colors"], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        col = None
    if col is None or col.ndim != 2 or col.shape[1] != 3 or not n_min <= len(col) <= n_max \
            or not np.all((col >= 0.0) & (col <= 1.0)):
        raise ValueError(f"texture {params.get('kind')!r}: 'colors' must be a list of {n_min}..{n_max} "
                         f"linear RGB triples in [0, 1], got {params.get('colors')!r}")
    return col.astype(np.float32)


def sample_texture_params(rng: np.random.Generator, kind: str | None = None, prior: str = "hsv") -> dict:
    """Random JSON-serialisable texture params; ``kind`` None picks one of KINDS (the
    patterns: 2-5 colours around one hue); colours from the surface-colour ``prior``
    (:mod:`relight.scene.albedo`). ``kind`` ``"mosaic"``: 4-16 x 4-16 cells, each colour drawn
    on its own (independent surfaces)."""
    if kind is None:
        kind = str(rng.choice(KINDS))
    if kind not in ALL_KINDS:
        raise ValueError(f"unknown texture kind {kind!r}, expected one of {ALL_KINDS}")
    p: dict = {"kind": kind, "seed": int(rng.integers(0, 2**31 - 1))}
    if kind == MOSAIC:
        rows, cols = (int(n) for n in rng.integers(MOSAIC_CELLS[0], MOSAIC_CELLS[1] + 1, 2))
        p.update(rows=rows, cols=cols,
                 colors=[texture_colours(rng, 1, prior)[0] for _ in range(rows * cols)])
        return p

    def _colours_of(n: int) -> list[list[float]]:
        return texture_colours(rng, n, prior)
    angle = float(rng.choice([0.0, 0.0, 90.0, rng.uniform(0.0, 180.0)]))
    if kind == "checker":
        p.update(cells=int(rng.integers(2, 13)), angle=angle, colors=_colours_of(2))
    elif kind == "stripes":
        p.update(count=int(rng.integers(2, 17)), angle=angle, duty=float(rng.uniform(0.2, 0.8)),
                 colors=_colours_of(int(rng.integers(2, 4))))
    elif kind == "patches":
        p.update(count=int(rng.integers(4, 21)), variation=float(rng.uniform(0.0, 0.15)),
                 colors=_colours_of(int(rng.integers(2, 6))))
    elif kind == "noise":
        scale = int(rng.integers(2, 9))  # finest octave has at most 32 lattice cells across
        p.update(scale=scale, octaves=int(rng.integers(1, 2 + int(math.log2(32 // scale)))),
                 persistence=float(rng.uniform(0.35, 0.65)),
                 colors=_colours_of(int(rng.integers(2, 4))))
    elif kind == "gradient":
        p.update(mode=str(rng.choice(["linear", "radial"])), angle=float(rng.uniform(0.0, 360.0)),
                 center=[float(x) for x in rng.uniform(0.0, 1.0, 2)],
                 colors=_colours_of(int(rng.integers(2, 4))))
    elif kind == "dots":
        radius = float(rng.uniform(0.15, 0.4))
        p.update(cells=int(rng.integers(3, 13)), radius=radius,
                 jitter=float(rng.uniform(0.0, 0.45 - radius)),
                 colors=_colours_of(int(rng.integers(2, 4))))
    else:
        rows = int(rng.integers(2, 13))
        p.update(rows=rows, cols=int(np.clip(round(rows * rng.uniform(0.3, 1.5)), 1, 12)),
                 offset=float(rng.choice([0.0, 0.5])), grout=float(rng.uniform(0.03, 0.12)),
                 variation=float(rng.uniform(0.0, 0.15)),
                 colors=_colours_of(int(rng.integers(2, 5))))
    return p


# --------------------------------------------------------------------------- backgrounds
def _draw_background(rng: np.random.Generator, tag: str) -> tuple[dict, dict]:
    """One background: a wall texture and a floor texture, each a pattern of
    :data:`LIBRARY_KINDS` (2-5 ``hsv`` colours around a hue), tagged ``tag``."""
    wall = sample_texture_params(rng, str(rng.choice(LIBRARY_KINDS)), "hsv")
    floor = sample_texture_params(rng, str(rng.choice(LIBRARY_KINDS)), "hsv")
    return {**wall, BACKGROUND_KEY: tag}, {**floor, BACKGROUND_KEY: tag}


@functools.lru_cache(maxsize=1)
def _library_json() -> tuple[str, ...]:
    rng = np.random.default_rng(LIBRARY_SEED)
    return tuple(json.dumps(_draw_background(rng, f"{LIBRARY}:{k:03d}")) for k in range(LIBRARY_SIZE))


def background_library() -> list[tuple[dict, dict]]:
    """The closed library of ``--backgrounds library`` (``--preset sid2-paper``): a list of
    :data:`LIBRARY_SIZE` ``(wall texture, floor texture)`` params, background ``k`` tagged
    ``"library:k"`` (three digits), drawn in order from ``default_rng(LIBRARY_SEED)``: the
    same on every machine and in every run (fresh copies each call)."""
    return [tuple(json.loads(s)) for s in _library_json()]


@functools.lru_cache(maxsize=1)
def library_colours() -> frozenset:
    """Every colour (rounded linear RGB triple) of the library's textures."""
    return frozenset(tuple(c) for s in _library_json() for t in json.loads(s) for c in t["colors"])


def sample_background(rng: np.random.Generator, mode: str) -> tuple[dict, dict]:
    """The ``(wall texture, floor texture)`` of one scene: ``library``, one of the
    library's backgrounds, uniformly (one integer draw); ``unseen``, a new background drawn
    as the library's are, redrawn while any of its colours is one of the library's (so an
    unseen background shares no surface colour with the library)."""
    if mode == LIBRARY:
        return background_library()[int(rng.integers(0, LIBRARY_SIZE))]
    if mode == UNSEEN:
        known = library_colours()
        for _ in range(1000):
            wall, floor = _draw_background(rng, UNSEEN)
            if not any(tuple(c) in known for t in (wall, floor) for c in t["colors"]):
                return wall, floor
        raise RuntimeError("no background outside the library in 1000 draws")  # pragma: no cover
    raise ValueError(f"unknown background mode {mode!r}; expected {LIBRARY!r} or {UNSEEN!r}")


# --------------------------------------------------------------------------- patterns
def _grid(size: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel-centre coordinates in [0, 1): x (1, size) along columns, y (size, 1) along rows."""
    c = ((np.arange(size, dtype=np.float32) + 0.5) / size)
    return c[None, :], c[:, None]


def _rotated(params: dict, size: int) -> tuple[np.ndarray, np.ndarray]:
    a = math.radians(_num(params, "angle", -3600.0, 3600.0))
    x, y = _grid(size)
    ca, sa = np.float32(math.cos(a)), np.float32(math.sin(a))
    return x * ca + y * sa, y * ca - x * sa


def _ramp(t: np.ndarray, col: np.ndarray) -> np.ndarray:
    """Piecewise-linear colour ramp through ``col`` for t in [0, 1]."""
    s = np.clip(t, 0.0, 1.0).astype(np.float32) * np.float32(len(col) - 1)
    out = np.broadcast_to(col[0], s.shape + (3,)).copy()
    for k in range(len(col) - 1):  # telescoping sum of per-segment lerps (no BLAS)
        out += np.clip(s - np.float32(k), 0.0, 1.0)[..., None] * (col[k + 1] - col[k])
    return out


def _checker(p: dict, size: int, rng: np.random.Generator) -> np.ndarray:
    n = _int(p, "cells", 1, 64)
    col = _colours(p, 2, 2)
    xr, yr = _rotated(p, size)
    ph = rng.random(2).astype(np.float32)
    idx = (np.floor(xr * n + ph[0]).astype(np.int64) + np.floor(yr * n + ph[1]).astype(np.int64)) & 1
    return col[idx]


def _stripes(p: dict, size: int, rng: np.random.Generator) -> np.ndarray:
    n = _int(p, "count", 1, 64)
    duty = _num(p, "duty", 0.05, 0.95)
    col = _colours(p, 2, 4)
    xr, _ = _rotated(p, size)
    s = np.broadcast_to(xr, (size, size)) * n + np.float32(rng.random())
    k = np.floor(s)
    idx = np.where(s - k < duty, 0, 1 + k.astype(np.int64) % (len(col) - 1))
    return col[idx]


def _patches(p: dict, size: int, rng: np.random.Generator) -> np.ndarray:
    m = _int(p, "count", 1, 64)
    var = _num(p, "variation", 0.0, 0.5)
    col = _colours(p, 2, 8)
    choice = rng.integers(1, len(col), m)
    rect_col = np.vstack([col[:1], col[choice] * rng.uniform(1 - var, 1 + var, (m, 1))])
    rect_col = np.clip(rect_col, ALBEDO_MIN, ALBEDO_MAX).astype(np.float32)
    corner = rng.random((m, 2))
    extent = rng.uniform(0.1, 0.45, (m, 2))
    idx = np.zeros((size, size), np.int64)
    for r in range(m):  # one slice assignment per rectangle (wraps around the edges)
        y0, x0 = (corner[r] * size).astype(int)
        h, w = np.maximum((extent[r] * size).astype(int), 1)
        idx[np.ix_(np.arange(y0, y0 + h) % size, np.arange(x0, x0 + w) % size)] = r + 1
    return rect_col[idx]


def _lattice(size: int, g: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Periodic lattice neighbours i0, i1 (size,) and smoothstep weight w of i1 for g cells."""
    t = (np.arange(size) + 0.5) / size * g
    i0 = np.floor(t).astype(np.int64)
    f = t - i0
    return i0 % g, (i0 + 1) % g, (f * f * (3.0 - 2.0 * f)).astype(np.float32)


def _noise(p: dict, size: int, rng: np.random.Generator) -> np.ndarray:
    g = _int(p, "scale", 1, 32)
    octaves = _int(p, "octaves", 1, 6)
    pers = _num(p, "persistence", 0.0, 1.0)
    col = _colours(p, 2, 4)
    f = np.zeros((size, size), np.float32)
    for o in range(octaves):  # fractal sum of periodic value noise (tileable)
        go = g * 2**o
        i0, i1, w = _lattice(size, go)
        lat = rng.random((go, go), dtype=np.float32)
        rows = lat[:, i0] * (1.0 - w) + lat[:, i1] * w  # separable: along x, then y
        f += np.float32(pers**o) * (rows[i0] * (1.0 - w)[:, None] + rows[i1] * w[:, None])
    lo, hi = f.min(), f.max()
    t = (f - lo) / (hi - lo) if hi > lo else np.zeros_like(f)
    return _ramp(t, col)


def _gradient(p: dict, size: int, rng: np.random.Generator) -> np.ndarray:
    mode = p.get("mode")
    col = _colours(p, 2, 4)
    if mode == "linear":
        xr, _ = _rotated(p, size)
        corners = [math.cos(math.radians(p["angle"])) * cx + math.sin(math.radians(p["angle"])) * cy
                   for cx in (0, 1) for cy in (0, 1)]
        t = (np.broadcast_to(xr, (size, size)) - min(corners)) / (max(corners) - min(corners))
    elif mode == "radial":
        try:
            cx, cy = (float(c) for c in p["center"])
        except (KeyError, TypeError, ValueError):
            raise ValueError("texture 'gradient': 'center' must be [x, y] in [0, 1]") from None
        if not (0 <= cx <= 1 and 0 <= cy <= 1):
            raise ValueError("texture 'gradient': 'center' must be [x, y] in [0, 1]")
        x, y = _grid(size)
        far = max(math.hypot(cx - a, cy - b) for a in (0, 1) for b in (0, 1))
        t = np.sqrt((x - np.float32(cx)) ** 2 + (y - np.float32(cy)) ** 2) / np.float32(far)
    else:
        raise ValueError(f"texture 'gradient': 'mode' must be 'linear' or 'radial', got {mode!r}")
    return _ramp(t, col)


def _dots(p: dict, size: int, rng: np.random.Generator) -> np.ndarray:
    n = _int(p, "cells", 1, 64)
    radius = _num(p, "radius", 0.02, 0.5)
    jitter = _num(p, "jitter", 0.0, 0.5 - radius)
    col = _colours(p, 2, 4)
    off = rng.uniform(-jitter, jitter, (n, n, 2)).astype(np.float32)
    choice = rng.integers(1, len(col), (n, n))
    x, y = _grid(size)
    gx, gy = x * n, y * n
    cx, cy = gx.astype(np.int64), gy.astype(np.int64)  # cell index (coordinates >= 0)
    dx = (gx - cx - 0.5) - off[cy, cx, 0]
    dy = (gy - cy - 0.5) - off[cy, cx, 1]
    idx = np.where(dx * dx + dy * dy < radius * radius, choice[cy, cx], 0)
    return col[idx]


def _tiles(p: dict, size: int, rng: np.random.Generator) -> np.ndarray:
    rows, cols = _int(p, "rows", 1, 64), _int(p, "cols", 1, 64)
    offset = _num(p, "offset", 0.0, 1.0)
    grout = _num(p, "grout", 0.0, 0.5)
    var = _num(p, "variation", 0.0, 0.5)
    col = _colours(p, 2, 8)  # colors[0] is the grout
    tile_col = col[rng.integers(1, len(col), (rows, cols))] * rng.uniform(1 - var, 1 + var, (rows, cols, 1))
    tile_col = np.clip(tile_col, ALBEDO_MIN, ALBEDO_MAX).astype(np.float32)
    x, y = _grid(size)
    gy = y * rows
    ry = gy.astype(np.int64)
    gx = x * cols + np.float32(offset) * (ry % 2)
    rx = np.floor(gx).astype(np.int64)
    gw = grout / max(rows, cols)  # grout line width in texture units, same in x and y
    is_grout = ((gy - ry) < gw * rows) | ((gx - rx) < gw * cols)
    return np.where(is_grout[..., None], col[0], tile_col[ry, rx % cols])


def _mosaic(p: dict, size: int, rng: np.random.Generator) -> np.ndarray:
    rows, cols = _int(p, "rows", 1, 64), _int(p, "cols", 1, 64)
    col = _colours(p, rows * cols, rows * cols)   # row-major, row 0 at the top
    x, y = _grid(size)
    return col.reshape(rows, cols, 3)[(y * rows).astype(np.int64), (x * cols).astype(np.int64)]


_PATTERNS = {"mosaic": _mosaic, "checker": _checker, "stripes": _stripes, "patches": _patches, "noise": _noise,
             "gradient": _gradient, "dots": _dots, "tiles": _tiles}


def make_texture(params: dict, size: int) -> np.ndarray:
    """Render ``params`` to a (size, size, 3) float32 linear-RGB albedo image in [0, 1].

    Raises ValueError for an unknown kind (listing ALL_KINDS), bad params or size.
    """
    if not isinstance(params, dict):
        raise ValueError(f"texture params must be a dict, got {type(params).__name__}")
    kind = params.get("kind")
    if kind not in ALL_KINDS:
        raise ValueError(f"unknown texture kind {kind!r}, expected one of {ALL_KINDS}")
    seed = params.get("seed")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"texture {kind!r}: 'seed' must be a non-negative int, got {seed!r}")
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or not 1 <= size <= 16384:
        raise ValueError(f"texture size must be an int in [1, 16384], got {size!r}")
    img = _PATTERNS[kind](params, int(size), np.random.default_rng(int(seed)))
    img = np.broadcast_to(img, (size, size, 3))
    return np.ascontiguousarray(np.clip(img, 0.0, 1.0), dtype=np.float32)

"""Procedural object meshes that all share ONE fixed grid topology (pure numpy).

Conventions
-----------
* Object space, units of metres, right-handed, **z up**.
* Every mesh is normalised: the bounding-box centre is at x = y = 0, the mesh
  rests on the floor (``min z == 0`` exactly) and the largest horizontal
  distance of any vertex from the z axis is exactly 1.0 m; the caller scales
  it to the wanted size.  The total height follows the proportions but is
  clamped to [MIN_HEIGHT, MAX_HEIGHT] m by scaling z alone.
* Topology: a (u, v) grid of ``n_u`` columns x ``n_v`` rows, vertex index
  ``j * n_u + i`` for column i and row j.  u goes counter-clockwise around the
  z axis (seen from above) and wraps (column n_u-1 joins column 0, no duplicate
  seam column); v goes from the bottom (row 0) to the top (row n_v-1) and does
  not wrap.  Each cell gives two triangles, wound counter-clockwise seen from
  outside, so face normals point outward.  ``grid_faces(n_u, n_v)`` is the
  same array for every family, so vertex buffers can be updated in place.
* Sphere-like families collapse row 0 and row n_v-1 to single points (poles;
  their degenerate triangles have zero area).  The torus uses its rows for
  the tube angle in [0, 2 pi] and its last row coincides with row 0.
* Capped shapes (revolved, extrusion, box, cylinder, cone) use the rows
  ``[centre, inset ring, edge ring, ...side..., edge ring, inset ring,
  centre]``; the inset ring lies on the flat cap ``BEVEL`` inside the edge,
  which keeps smooth-shaded caps nearly flat-looking.
* Vertex normals are area-weighted and shared between coincident vertices
  (poles, the torus seam), so pole normals point along the axis.
"""
from __future__ import annotations

__all__ = [
    "FAMILIES", "PRIMITIVE_KINDS", "OUTLINE_KINDS", "DEFAULT_NU", "DEFAULT_NV", "MIN_HEIGHT", "MAX_HEIGHT",
    "BEVEL", "Mesh", "grid_faces", "vertex_normals", "sample_shape_params", "make_mesh", "MAX_PARTS",
    "part_labels",
]

import math
from dataclasses import dataclass

import numpy as np

FAMILIES: tuple[str, ...] = ("superquadric", "torus", "revolved", "extrusion", "blob", "primitive")
PRIMITIVE_KINDS: tuple[str, ...] = ("box", "cylinder", "cone")
OUTLINE_KINDS: tuple[str, ...] = ("polygon", "star", "rounded")
DEFAULT_NU = 48
DEFAULT_NV = 24
MIN_HEIGHT = 0.3  # m, after normalisation to unit max radius
MAX_HEIGHT = 3.0  # m
BEVEL = 0.02  # cap inset ring distance, in units of the (pre-normalisation) outline radius


@dataclass(frozen=True, eq=False)
class Mesh:
    """Triangle mesh in object space (metres, z up, min z = 0).

    vertices (N, 3) float32, faces (F, 3) uint32 (counter-clockwise from
    outside), normals (N, 3) float32 unit length, uv (N, 2) float32 in [0, 1].
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    uv: np.ndarray


# --------------------------------------------------------------------------- topology
def grid_faces(n_u: int, n_v: int) -> np.ndarray:
    """(2 * n_u * (n_v - 1), 3) uint32 faces of the wrapped-in-u grid."""
    if n_u < 3 or n_v < 2:
        raise ValueError(f"expected n_u >= 3 and n_v >= 2, got n_u={n_u}, n_v={n_v}")
    i = np.arange(n_u)
    j = np.arange(n_v - 1)[:, None]
    a = j * n_u + i
    b = j * n_u + (i + 1) % n_u
    c, d = b + n_u, a + n_u
    tris = np.stack([np.stack([a, b, c], -1), np.stack([a, c, d], -1)], axis=2)
    return tris.reshape(-1, 3).astype(np.uint32)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals, (N, 3) float32, never NaN.

    Vertices at the same position (within 1e-6 of the mesh extent) share the
    sum of their face contributions, so a collapsed pole ring gets the ring
    average (along the pole axis) and a closed seam is shaded smoothly.  A
    vertex with no usable faces gets the direction from the vertex centroid.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    n = len(v)
    if n == 0:
        return np.zeros((0, 3), np.float32)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # |fn| = 2 * area
    acc = np.zeros((n, 3))
    for k in range(3):
        for c in range(3):
            acc[:, c] += np.bincount(f[:, k], weights=fn[:, c], minlength=n)
    extent = max(float(np.ptp(v, axis=0).max()), 1e-12)
    keys = np.round(v / (extent * 1e-6)).astype(np.int64)
    _, inv = np.unique(keys, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    if inv.max() + 1 < n:  # some vertices coincide: share their sums
        grp = np.stack([np.bincount(inv, weights=acc[:, c]) for c in range(3)], -1)
        acc = grp[inv]
    length = np.linalg.norm(acc, axis=1)
    bad = length <= 1e-12 * extent * extent
    if bad.any():
        fallback = v[bad] - v.mean(axis=0)
        fl = np.linalg.norm(fallback, axis=1)
        fallback[fl <= 0] = (0.0, 0.0, 1.0)
        acc[bad], length[bad] = fallback, np.where(fl > 0, fl, 1.0)
    return (acc / length[:, None]).astype(np.float32)


# --------------------------------------------------------------------------- params
def _num(params: dict, key: str, lo: float, hi: float, what: str) -> float:
    if key not in params:
        raise ValueError(f"{what}: missing parameter {key!r}, expected a number in [{lo}, {hi}]")
    try:
        x = float(params[key])
    except (TypeError, ValueError):
        raise ValueError(f"{what}: parameter {key!r} must be a number in [{lo}, {hi}], "
                         f"got {params[key]!r}") from None
    if not lo <= x <= hi:
        raise ValueError(f"{what}: parameter {key!r}={x} out of range, expected [{lo}, {hi}]")
    return x


def _choice(params: dict, key: str, options: tuple[str, ...], what: str) -> str:
    val = params.get(key)
    if val not in options:
        raise ValueError(f"{what}: parameter {key!r}={val!r}, expected one of {options}")
    return val


def _array(params: dict, key: str, shape_last: int | None, lo: float, hi: float,
           n_min: int, n_max: int, what: str) -> np.ndarray:
    try:
        arr = np.asarray(params[key], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        raise ValueError(f"{what}: parameter {key!r} must be a list of numbers") from None
    ok = arr.ndim == (1 if shape_last is None else 2) and n_min <= len(arr) <= n_max
    if shape_last is not None:
        ok = ok and arr.shape[-1] == shape_last
    if not ok or not np.all((arr >= lo) & (arr <= hi)):
        inner = "numbers" if shape_last is None else f"[{shape_last} numbers]"
        raise ValueError(f"{what}: parameter {key!r} must be {n_min}..{n_max} {inner} "
                         f"with values in [{lo}, {hi}], got {params[key]!r}")
    return arr


def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi))


def sample_shape_params(family: str, rng: np.random.Generator) -> dict:
    """Random JSON-serialisable parameters (with random proportions) for ``family``."""
    if family not in FAMILIES:
        raise ValueError(f"unknown shape family {family!r}, expected one of {FAMILIES}")
    p: dict = {"family": family}
    if family == "superquadric":
        p["e1"], p["e2"] = (float(math.exp(rng.uniform(math.log(0.2), math.log(2.0)))) for _ in range(2))
        p["axes"] = [1.0, _u(rng, 0.5, 1.0), _u(rng, 0.3, 1.5)]
    elif family == "torus":
        p.update(major_radius=1.0, minor_radius=_u(rng, 0.2, 0.6), standing=bool(rng.random() < 0.3))
    elif family == "revolved":
        k = int(rng.integers(3, 8))
        p.update(radii=[_u(rng, 0.25, 1.0) for _ in range(k)], height=_u(rng, 0.6, 3.0))
    elif family == "extrusion":
        kind = str(rng.choice(OUTLINE_KINDS))
        p.update(outline=kind, height=_u(rng, 0.2, 2.0), aspect=_u(rng, 0.6, 1.0),
                 rotation=_u(rng, 0.0, 2 * math.pi))
        if kind == "polygon":
            p["radii"] = [_u(rng, 0.7, 1.0) for _ in range(int(rng.integers(3, 9)))]
        elif kind == "star":
            p.update(points=int(rng.integers(4, 9)), inner=_u(rng, 0.4, 0.8))
        else:
            ks = rng.choice(np.arange(2, 6), size=int(rng.integers(1, 4)), replace=False)
            p["harmonics"] = [[int(k), _u(rng, 0.05, 0.2), _u(rng, 0.0, 2 * math.pi)] for k in ks]
    elif family == "blob":
        bumps = []
        for _ in range(int(rng.integers(2, 6))):
            d = rng.normal(size=3)
            d /= np.linalg.norm(d)
            bumps.append([float(x) for x in d] + [_u(rng, 2.0, 8.0), _u(rng, -0.25, 0.5)])
        neg = sum(min(b[4], 0.0) for b in bumps)
        if neg < -0.6:  # keep the radius positive: 1 + sum(negative amplitudes) >= 0.4
            for b in bumps:
                b[4] = b[4] * 0.6 / -neg if b[4] < 0 else b[4]
        p.update(bumps=bumps, axes=[_u(rng, 0.7, 1.1), _u(rng, 0.7, 1.1), _u(rng, 0.6, 1.4)])
    else:
        kind = str(rng.choice(PRIMITIVE_KINDS))
        p["kind"] = kind
        if kind == "box":
            p["size"] = [1.0, _u(rng, 0.4, 1.0), _u(rng, 0.3, 2.0)]
        else:
            p.update(radius=1.0, height=_u(rng, 0.3, 2.5) if kind == "cylinder" else _u(rng, 0.6, 2.5))
    return p


# --------------------------------------------------------------------------- builders
def _spow(x: np.ndarray, e: float) -> np.ndarray:
    return np.sign(x) * np.abs(x) ** e


def _sphere_dirs(n_u: int, n_v: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """cos/sin of longitude (n_u,) and latitude (n_v,) with exact poles."""
    om = 2 * np.pi * np.arange(n_u) / n_u
    eta = -np.pi / 2 + np.pi * np.arange(n_v) / (n_v - 1)
    ce, se = np.cos(eta), np.sin(eta)
    ce[[0, -1]], se[0], se[-1] = 0.0, -1.0, 1.0
    return np.cos(om), np.sin(om), ce, se


def _superquadric(p: dict, n_u: int, n_v: int) -> np.ndarray:
    what = "superquadric"
    e1, e2 = _num(p, "e1", 0.1, 4.0, what), _num(p, "e2", 0.1, 4.0, what)
    ax, ay, az = _array(p, "axes", None, 0.05, 20.0, 3, 3, what)
    co, so, ce, se = _sphere_dirs(n_u, n_v)
    fe = _spow(ce, e1)[:, None]
    x = ax * fe * _spow(co, e2)
    y = ay * fe * _spow(so, e2)
    z = np.broadcast_to(az * _spow(se, e1)[:, None], x.shape)
    return np.stack([x, y, z], -1)


def _torus(p: dict, n_u: int, n_v: int) -> np.ndarray:
    big = _num(p, "major_radius", 1e-3, 1e3, "torus")
    small = _num(p, "minor_radius", 1e-4, 1e3, "torus")
    if small >= 0.95 * big:
        raise ValueError(f"torus: expected minor_radius < 0.95 * major_radius, got {small} >= {0.95 * big}")
    th = 2 * np.pi * np.arange(n_u) / n_u
    ph = 2 * np.pi * np.arange(n_v) / (n_v - 1)
    ring = (big + small * np.cos(ph))[:, None]
    x, y = ring * np.cos(th), ring * np.sin(th)
    z = np.broadcast_to(small * np.sin(ph)[:, None], x.shape)
    pts = np.stack([x, y, z], -1)
    pts[-1] = pts[0]  # closed seam: last row == first row exactly
    if bool(p.get("standing", False)):  # rotate +90 deg about x (keeps orientation)
        pts = np.stack([pts[..., 0], -pts[..., 2], pts[..., 1]], -1)
    return pts


def _capped(outline: np.ndarray, side_s: np.ndarray, side_z: np.ndarray, top_cap: bool = True) -> np.ndarray:
    """Sweep a CCW outline (n_u, 2) scaled by s over rows with flat cap(s).

    Rows: bottom centre, bottom inset, side rows (side_s, side_z), and if
    ``top_cap`` top inset + top centre; otherwise the last side row is the apex.
    """
    inset = lambda s: max(s - BEVEL, 0.5 * s)  # noqa: E731
    s = [0.0, inset(side_s[0]), *side_s]
    z = [side_z[0], side_z[0], *side_z]
    if top_cap:
        s += [inset(side_s[-1]), 0.0]
        z += [side_z[-1], side_z[-1]]
    s, z = np.asarray(s), np.asarray(z)
    xy = s[:, None, None] * outline[None, :, :]
    return np.concatenate([xy, np.broadcast_to(z[:, None, None], xy.shape[:2] + (1,))], -1)


def _catmull_rom(values: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Smooth uniform Catmull-Rom interpolation of values at knots k/(K-1)."""
    k = len(values)
    padded = np.concatenate([[2 * values[0] - values[1]], values, [2 * values[-1] - values[-2]]])
    x = np.clip(t, 0.0, 1.0) * (k - 1)
    i = np.minimum(np.floor(x).astype(int), k - 2)
    f = x - i
    p0, p1, p2, p3 = padded[i], padded[i + 1], padded[i + 2], padded[i + 3]
    return 0.5 * (2 * p1 + (p2 - p0) * f + (2 * p0 - 5 * p1 + 4 * p2 - p3) * f ** 2
                  + (3 * p1 - p0 - 3 * p2 + p3) * f ** 3)


def _revolved(p: dict, n_u: int, n_v: int) -> np.ndarray:
    radii = _array(p, "radii", None, 0.05, 1.0, 2, 16, "revolved")
    h = _num(p, "height", 0.05, 10.0, "revolved")
    t = np.linspace(0.0, 1.0, n_v - 4)
    side_s = np.maximum(_catmull_rom(radii, t), 0.05)
    th = 2 * np.pi * np.arange(n_u) / n_u
    circle = np.stack([np.cos(th), np.sin(th)], -1)
    return _capped(circle, side_s, h * t)


def _resample_polygon(corners: np.ndarray, n: int) -> np.ndarray:
    """n points along a closed polygon, uniform by arc length, keeping every corner if n allows."""
    nxt = np.roll(corners, -1, axis=0)
    seg = np.linalg.norm(nxt - corners, axis=1)
    if n < len(corners):
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        closed = np.vstack([corners, corners[:1]])
        s = np.arange(n) / n * cum[-1]
        return np.stack([np.interp(s, cum, closed[:, c]) for c in range(2)], -1)
    quota = seg / seg.sum() * n
    counts = np.maximum(1, np.floor(quota).astype(int))
    while counts.sum() < n:
        counts[np.argmax(quota - counts)] += 1
    while counts.sum() > n:
        counts[np.argmax(np.where(counts > 1, counts - quota, -np.inf))] -= 1
    parts = [corners[k] + (nxt[k] - corners[k]) * (np.arange(c) / c)[:, None] for k, c in enumerate(counts)]
    return np.concatenate(parts)


def _outline(p: dict, n_u: int) -> np.ndarray:
    """CCW star-shaped outline (n_u, 2) for the extrusion family, max radius ~1."""
    what = "extrusion"
    kind = _choice(p, "outline", OUTLINE_KINDS, what)
    rot = _num(p, "rotation", -100.0, 100.0, what)
    if kind == "rounded":
        harm = _array(p, "harmonics", 3, -100.0, 100.0, 1, 8, what)
        if np.any(harm[:, 0] < 1) or np.abs(harm[:, 1]).sum() > 0.7:
            raise ValueError(f"{what}: harmonics need k >= 1 and sum(|amplitude|) <= 0.7")
        th = 2 * np.pi * np.arange(n_u) / n_u
        rho = 1.0 + sum(a * np.cos(k * th + ph) for k, a, ph in harm)
        pts = rho[:, None] * np.stack([np.cos(th + rot), np.sin(th + rot)], -1)
    else:
        if kind == "polygon":
            rho = _array(p, "radii", None, 0.2, 1.0, 3, 16, what)
        else:
            k = int(_num(p, "points", 3, 16, what))
            inner = _num(p, "inner", 0.2, 0.95, what)
            rho = np.tile([1.0, inner], k)
        th = rot + 2 * np.pi * np.arange(len(rho)) / len(rho)
        pts = _resample_polygon(rho[:, None] * np.stack([np.cos(th), np.sin(th)], -1), n_u)
    aspect = _num(p, "aspect", 0.2, 1.0, what)
    pts = pts * np.array([1.0, aspect])
    return pts / np.hypot(pts[:, 0], pts[:, 1]).max()


def _extrusion(p: dict, n_u: int, n_v: int) -> np.ndarray:
    h = _num(p, "height", 0.05, 10.0, "extrusion")
    outline = _outline(p, n_u)
    return _capped(outline, np.ones(n_v - 4), np.linspace(0.0, h, n_v - 4))


def _blob(p: dict, n_u: int, n_v: int) -> np.ndarray:
    bumps = _array(p, "bumps", 5, -50.0, 50.0, 0, 16, "blob")
    axes = _array(p, "axes", None, 0.05, 20.0, 3, 3, "blob")
    if len(bumps) and (np.any((bumps[:, 3] < 0.1) | (bumps[:, 3] > 50)) or
                       1.0 + np.minimum(bumps[:, 4], 0).sum() < 0.2 or
                       np.any(np.linalg.norm(bumps[:, :3], axis=1) < 1e-6)):
        raise ValueError("blob: each bump must be [dx, dy, dz, kappa in [0.1, 50], amplitude] "
                         "with a non-zero direction and 1 + sum(negative amplitudes) >= 0.2")
    co, so, ce, se = _sphere_dirs(n_u, n_v)
    d = np.stack([ce[:, None] * co, ce[:, None] * so, np.broadcast_to(se[:, None], (n_v, n_u))], -1)
    r = np.ones((n_v, n_u))
    for bx, by, bz, kappa, amp in bumps:
        c = np.array([bx, by, bz]) / math.sqrt(bx * bx + by * by + bz * bz)
        r += amp * np.exp(kappa * (d @ c - 1.0))
    return d * r[..., None] * axes


def _primitive(p: dict, n_u: int, n_v: int) -> np.ndarray:
    kind = _choice(p, "kind", PRIMITIVE_KINDS, "primitive")
    th = 2 * np.pi * np.arange(n_u) / n_u
    circle = np.stack([np.cos(th), np.sin(th)], -1)
    if kind == "box":
        sx, sy, sz = _array(p, "size", None, 0.01, 100.0, 3, 3, "primitive box")
        m = max(sx, sy) / 2
        rect = np.array([[1, -1], [1, 1], [-1, 1], [-1, -1]]) * [sx / 2 / m, sy / 2 / m]
        return _capped(_resample_polygon(rect, n_u), np.ones(n_v - 4), np.linspace(0, sz / m, n_v - 4))
    r = _num(p, "radius", 0.01, 100.0, f"primitive {kind}")
    h = _num(p, "height", 0.01, 100.0, f"primitive {kind}") / r
    if kind == "cylinder":
        return _capped(circle, np.ones(n_v - 4), np.linspace(0.0, h, n_v - 4))
    t = np.linspace(0.0, 1.0, n_v - 2)  # cone: edge ring ... apex (last row, a pole)
    return _capped(circle, 1.0 - t, h * t, top_cap=False)


_BUILDERS = {"superquadric": _superquadric, "torus": _torus, "revolved": _revolved,
             "extrusion": _extrusion, "blob": _blob, "primitive": _primitive}


def _normalise(pts: np.ndarray) -> np.ndarray:
    """Centre bbox in xy, unit max radius, min z = 0, height clamped; float32."""
    p = np.array(pts, dtype=np.float64).reshape(-1, 3)
    if not np.all(np.isfinite(p)):
        raise ValueError("parameters produced non-finite vertices")
    p[:, :2] -= 0.5 * (p[:, :2].min(axis=0) + p[:, :2].max(axis=0))
    rmax = np.hypot(p[:, 0], p[:, 1]).max()
    if rmax <= 1e-9:
        raise ValueError("parameters produced a mesh with zero horizontal extent")
    p /= rmax
    p[:, 2] -= p[:, 2].min()
    h = p[:, 2].max()
    if h <= 1e-9:
        raise ValueError("parameters produced a flat mesh")
    p[:, 2] *= min(max(h, MIN_HEIGHT), MAX_HEIGHT) / h
    out = p.astype(np.float32)
    out[:, 2] -= out[:, 2].min()
    return out


def make_mesh(family: str, params: dict, n_u: int = DEFAULT_NU, n_v: int = DEFAULT_NV) -> Mesh:
    """Build the normalised mesh (metres, z up, min z = 0, max radius 1 m).

    ``params`` (e.g. from :func:`sample_shape_params`) fully determines the
    result: identical params give bit-identical arrays.  Raises ValueError for
    an unknown family, bad params or a grid smaller than 3 x 6.
    """
    if family not in FAMILIES:
        raise ValueError(f"unknown shape family {family!r}, expected one of {FAMILIES}")
    if not isinstance(params, dict):
        raise ValueError(f"{family}: params must be a dict, got {type(params).__name__}")
    if params.get("family", family) != family:
        raise ValueError(f"params are for family {params['family']!r}, expected {family!r}")
    if int(n_u) != n_u or int(n_v) != n_v or n_u < 3 or n_v < 6:
        raise ValueError(f"expected integers n_u >= 3 and n_v >= 6, got n_u={n_u}, n_v={n_v}")
    n_u, n_v = int(n_u), int(n_v)
    pts = _BUILDERS[family](params, n_u, n_v)
    vertices = _normalise(pts)
    faces = grid_faces(n_u, n_v)
    uu, vv = np.meshgrid(np.arange(n_u) / n_u, np.arange(n_v) / (n_v - 1))
    uv = np.stack([uu.ravel(), vv.ravel()], -1).astype(np.float32)
    return Mesh(vertices, faces, vertex_normals(vertices, faces), uv)


MAX_PARTS = 32   # independently coloured parts per object (ObjectSpec.part_reflectances)


def part_labels(mesh: Mesh, n_parts: int) -> np.ndarray:
    """Split a mesh's faces into ``n_parts`` compact patches: ``(F,)`` int labels in
    ``[0, n_parts)``, every label used.

    The paper's objects carry one random colour per mesh part ("for each mesh texture in
    each object"); procedural meshes have no parts, so they are cut into Voronoi cells
    of their face centroids (object space) around seeds picked by farthest-point sampling
    from the highest face. Deterministic: the same mesh and count give the same labels.
    """
    n_faces = len(mesh.faces)
    if not 1 <= n_parts <= MAX_PARTS:
        raise ValueError(f"n_parts: expected 1..{MAX_PARTS}, got {n_parts}")
    if n_parts == 1 or n_faces <= 1:
        return np.zeros(n_faces, np.int64)
    n_parts = min(n_parts, n_faces)
    centroids = mesh.vertices.astype(np.float64)[mesh.faces.astype(np.int64)].mean(1)
    seeds = [int(np.argmax(centroids[:, 2]))]
    dist = np.linalg.norm(centroids - centroids[seeds[0]], axis=1)
    for _ in range(n_parts - 1):
        seeds.append(int(np.argmax(dist)))
        dist = np.minimum(dist, np.linalg.norm(centroids - centroids[seeds[-1]], axis=1))
    d2 = ((centroids[:, None, :] - centroids[seeds][None, :, :]) ** 2).sum(-1)
    labels = np.argmin(d2, axis=1)
    labels[seeds] = np.arange(n_parts)   # a seed always belongs to its own cell
    return labels

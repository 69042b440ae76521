"""The shadow term of compare: how well the cast shadows under a prediction match the
true light's, from exact ray tests (no Monte Carlo noise).

For every pixel the camera ray through its centre finds the visible surface point x
and its shading normal n (turned toward the camera). A light is a set of directions
with weights: a point light one direction toward its position (shadow ray up to it), a
map :data:`SHADOW_DIRECTIONS` directions drawn from its pixels in proportion to
luminance x solid angle by systematic resampling (deterministic), each of equal weight,
shadow rays to infinity. The **occluded fraction** of x is

    s(x) = 1 - sum_k w_k max(0, n.d_k) V_k(x) / sum_k w_k max(0, n.d_k)

(V_k = 0 when the ray toward d_k hits one of the scene's **objects** first: the room's
walls, which stand between a distant light and the scene but not between it and the
dataset's point light inside the room, are not occluders here): 1 in a hard cast shadow,
0 where lit, in between in a penumbra; 0 where no direction reaches the surface from
its front (attached shadow) and on pixels that see no surface. The score is the soft
IoU of the two occluded-fraction images, ``sum min(s_a, s_b) / sum max(s_a, s_b)``:
the IoU of the shadow masks when both lights are points, lower when one shadow is
soft; 1 when neither light casts a shadow in view.
"""
from __future__ import annotations

import numpy as np

from relight import backend, frames
from relight.verify.envmap import LUMINANCE

__all__ = [
    "SHADOW_DIRECTIONS",
    "RAY_EPSILON_M",
    "surface_points",
    "object_cylinders",
    "occluded_fraction",
    "occluded_fraction_reference",
    "envmap_directions",
    "soft_iou",
    "point_shadow",
    "envmap_shadow",
    "direction_shadow",
]

SHADOW_DIRECTIONS = 64      # directions drawn from a map
RAY_EPSILON_M = 1e-3        # shadow rays start this far off the surface (scene in metres)


def surface_points(scene, res: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(points (P, 3), normals (P, 3), valid (P,))`` of the camera rays through the
    pixel centres of a square ``res`` image (row-major from the top-left pixel); normals
    are the shading normals turned toward the camera."""
    mi = backend.mitsuba()
    dr = backend.drjit()
    sensor = scene.sensors()[0]
    j, i = np.meshgrid(np.arange(res), np.arange(res))
    pos = mi.Point2f(((j.ravel() + 0.5) / res).astype(np.float32), ((i.ravel() + 0.5) / res).astype(np.float32))
    n = res * res
    ray, _ = sensor.sample_ray(0.0, dr.full(mi.Float, 0.5, n), pos, dr.full(mi.Point2f, 0.5, n))
    si = scene.ray_intersect(ray)
    nrm = _rows(si.sh_frame.n)
    ng = _rows(si.n)
    d = _rows(ray.d)
    p = _rows(si.p)
    valid = np.array(si.is_valid(), dtype=bool)
    flip = np.where(np.sum(ng * d, axis=1) > 0, -1.0, 1.0)[:, None]   # face the camera
    nrm = nrm * flip
    nrm = np.where(np.sum(nrm * ng * flip, axis=1, keepdims=True) > 0, nrm, ng * flip)
    return p, nrm, valid


def _rows(v) -> np.ndarray:
    a = np.array(v, dtype=np.float64)
    return a if a.ndim == 2 and a.shape[1] == 3 else a.reshape(3, -1).T


def object_cylinders(spec) -> np.ndarray:
    """``(n, 3)``: ``(x_m, y_m, radius_m)`` of the vertical cylinder around each object of
    a scene spec (its mesh's horizontal radius is ``size_m``); a shadow ray's first hit
    inside one of them is an object."""
    return np.array([[o.position_m[0], o.position_m[1], o.size_m * (1.0 + 1e-3) + 1e-3]
                     for o in spec.objects], np.float64).reshape(-1, 3)


def occluded_fraction(scene, points, normals, valid, directions, weights, positions=None,
                      occluders=None) -> np.ndarray:
    """``(P,)`` occluded fraction s(x) (module docstring) for lights along unit
    ``directions`` (K, 3) with ``weights`` (K,), or toward point ``positions`` (K, 3);
    ``occluders``: :func:`object_cylinders` (None: every surface occludes). All K x P
    shadow rays are traced in one Dr.Jit launch; :func:`occluded_fraction_reference` is
    the same in plain numpy."""
    mi = backend.mitsuba()
    dr = backend.drjit()
    n_p, n_k = len(points), len(weights)
    vec = lambda cls, a: cls(*[np.ascontiguousarray(a[:, i], np.float32) for i in range(3)])
    idx = dr.arange(mi.UInt32, n_k * n_p)
    k = idx // n_p
    p = idx - k * n_p
    x = dr.gather(mi.Point3f, vec(mi.Point3f, np.asarray(points)), p)
    n = dr.gather(mi.Vector3f, vec(mi.Vector3f, np.asarray(normals)), p)
    live = dr.gather(mi.Bool, mi.Bool(np.asarray(valid, bool)), p)
    w = dr.gather(mi.Float, mi.Float(np.asarray(weights, np.float32)), k)
    if positions is not None:
        to = dr.gather(mi.Point3f, vec(mi.Point3f, np.asarray(positions, np.float64)), k) - x
        dist = dr.norm(to)
        d = to / dr.maximum(dist, 1e-12)
        maxt = dist * (1.0 - 1e-6)
    else:
        d = dr.gather(mi.Vector3f, vec(mi.Vector3f, np.asarray(directions, np.float64)), k)
        maxt = dr.full(mi.Float, dr.largest(mi.Float), n_k * n_p)
    cos = dr.maximum(dr.dot(n, d), 0.0)
    live = live & (cos > 0)
    scale = 1.0 + dr.maximum(dr.maximum(dr.abs(x.x), dr.abs(x.y)), dr.abs(x.z))
    ray = mi.Ray3f(x + n * (RAY_EPSILON_M * scale), d)
    ray.maxt = maxt
    if occluders is None:
        blocked = scene.ray_test(ray, live)
    else:
        si = scene.ray_intersect(ray, live)
        inside = dr.full(mi.Bool, False, n_k * n_p)
        for cx, cy, r in np.asarray(occluders, np.float64):   # opaque: no kernel per scene
            cx, cy, r2 = (dr.opaque(mi.Float, float(v)) for v in (cx, cy, r * r))
            inside |= dr.square(si.p.x - cx) + dr.square(si.p.y - cy) <= r2
        blocked = si.is_valid() & inside
    lit = dr.select(live, w * cos, 0.0)
    den = dr.zeros(mi.Float, n_p)
    num = dr.zeros(mi.Float, n_p)
    dr.scatter_reduce(dr.ReduceOp.Add, den, lit, p)
    dr.scatter_reduce(dr.ReduceOp.Add, num, dr.select(blocked, 0.0, lit), p)
    den, num = np.array(den, np.float64), np.array(num, np.float64)
    return np.where(den > 0, 1.0 - num / np.where(den > 0, den, 1.0), 0.0)


def _unblocked(scene, origins: np.ndarray, directions: np.ndarray, maxt: np.ndarray | None,
               occluders: np.ndarray | None) -> np.ndarray:
    """True where the ray reaches its end (or infinity) without hitting an occluder
    (any surface, or with ``occluders`` (n, 3) cylinders only a hit inside one)."""
    mi = backend.mitsuba()
    o = mi.Point3f(*[origins[:, k].astype(np.float32) for k in range(3)])
    d = mi.Vector3f(*[directions[:, k].astype(np.float32) for k in range(3)])
    ray = mi.Ray3f(o, d)
    if maxt is not None:
        ray.maxt = mi.Float(maxt.astype(np.float32))
    if occluders is None:
        return ~np.array(scene.ray_test(ray), dtype=bool)
    si = scene.ray_intersect(ray)
    hit = np.array(si.is_valid(), dtype=bool)
    p = _rows(si.p)
    inside = np.zeros(len(p), bool)
    for x, y, r in occluders:
        inside |= np.hypot(p[:, 0] - x, p[:, 1] - y) <= r
    return ~(hit & inside)


def occluded_fraction_reference(scene, points, normals, valid, directions, weights, positions=None,
                                occluders=None) -> np.ndarray:
    """:func:`occluded_fraction` in plain numpy, one shadow ray per (direction, pixel):
    the readable version, kept to test the fast one."""
    k_n = len(weights)
    if positions is not None:
        to = np.asarray(positions, np.float64)[:, None, :] - points[None, :, :]      # (K, P, 3)
        dist = np.linalg.norm(to, axis=2)
        d = to / np.maximum(dist, 1e-12)[..., None]
    else:
        d = np.broadcast_to(np.asarray(directions, np.float64)[:, None, :], (k_n,) + points.shape)
        dist = None
    cos = np.clip(np.einsum("kpc,pc->kp", d, normals), 0.0, None)                 # (K, P)
    live = valid[None, :] & (cos > 0)
    vis = np.zeros(cos.shape)
    if live.any():
        kk, pp = np.nonzero(live)
        offset = RAY_EPSILON_M * (1.0 + np.abs(points[pp]).max(axis=1))[:, None]
        maxt = None if dist is None else dist[kk, pp] * (1.0 - 1e-6)
        vis[kk, pp] = _unblocked(scene, points[pp] + normals[pp] * offset, d[kk, pp], maxt, occluders)
    w = np.asarray(weights, np.float64)[:, None]
    den = (w * cos).sum(axis=0)
    num = (w * cos * vis).sum(axis=0)
    return np.where(den > 0, 1.0 - num / np.where(den > 0, den, 1.0), 0.0)


def envmap_directions(image: np.ndarray, rotation: np.ndarray, n: int = SHADOW_DIRECTIONS):
    """``(directions (n, 3) world, weights (n,))`` drawn from a map's pixels in proportion
    to luminance x solid angle (systematic resampling: deterministic); ``rotation``
    takes map-frame directions to the world (:func:`relight.frames.envmap_rotation`)."""
    img = np.asarray(image, np.float64)
    h, w = img.shape[:2]
    power = ((img @ LUMINANCE) * frames.equirect_solid_angles(h, w)).reshape(-1)
    cdf = np.cumsum(power)
    picks = np.searchsorted(cdf, (np.arange(n) + 0.5) / n * cdf[-1])
    picks = np.minimum(picks, len(cdf) - 1)
    dirs = frames.equirect_pixel_directions(h, w).reshape(-1, 3)[picks] @ np.asarray(rotation).T
    return dirs, np.full(n, 1.0 / n)


def soft_iou(s_a: np.ndarray, s_b: np.ndarray) -> float:
    """``sum min / sum max`` of two occluded-fraction images (1 when both are empty)."""
    a, b = np.asarray(s_a, np.float64), np.asarray(s_b, np.float64)
    den = float(np.maximum(a, b).sum())
    return 1.0 if den == 0 else float(np.minimum(a, b).sum() / den)


def point_shadow(scene, surface, position_m, occluders=None) -> np.ndarray:
    """Occluded fraction under a point light at ``position_m`` (world, metres)."""
    points, normals, valid = surface
    return occluded_fraction(scene, points, normals, valid, None, np.ones(1),
                             positions=np.asarray(position_m, np.float64)[None, :], occluders=occluders)


def envmap_shadow(scene, surface, image, rotation, n: int = SHADOW_DIRECTIONS, occluders=None) -> np.ndarray:
    """Occluded fraction under a map (``rotation``: map frame to world)."""
    points, normals, valid = surface
    dirs, weights = envmap_directions(image, rotation, n)
    return occluded_fraction(scene, points, normals, valid, dirs, weights, occluders=occluders)


def direction_shadow(scene, surface, to_light, occluders=None) -> np.ndarray:
    """Occluded fraction under a distant light toward unit ``to_light`` (world)."""
    points, normals, valid = surface
    d = np.asarray(to_light, np.float64)
    return occluded_fraction(scene, points, normals, valid, (d / np.linalg.norm(d))[None, :], np.ones(1),
                             occluders=occluders)



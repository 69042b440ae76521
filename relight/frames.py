"""The coordinate conventions of relight: the one module that owns them.

Everything here follows ``shared/conventions.md``:

Convention:
    * World frame: right-handed, +Z up, floor is z = 0, scene centre at the origin.
    * Spherical position (r, pan, tilt):
      ``p = r (cos tilt cos pan, cos tilt sin pan, sin tilt)``.
      pan is the azimuth, counter-clockwise seen from above, from +X toward +Y;
      tilt is the elevation above the floor (0 = horizon, 90 = zenith).
    * The camera sits at pan_c (0 in our datasets), looks at the origin with up +Z,
      so with pan_c = 0 its right-hand side is +Y.
    * ``pan_rel = wrap360(pan_l - pan_c)``: 0 front (camera side), 90 camera's right,
      180 back light, 270 left.
    * Camera frame (used for photographs, e.g. sphere data): x to the image right,
      y to the image top, z toward the camera (from the scene).
    * Mitsuba sensor frame: +X left, +Y up, +Z forward (the viewing direction).
    * ``to_light`` vectors point from the scene toward the light; Mitsuba's
      ``directional`` emitter ``direction`` is the way light travels. Only
      :func:`travel_direction` flips between the two.
    * Environment maps (equirectangular, ``W == 2 H``): their own frame, the camera and
      world frames of a map and Mitsuba's ``envmap`` frame are in the section
      "environment maps" at the end of this module (docs/conventions.md defines them).

Angles are degrees at every public edge; radians stay inside the maths.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = [
    "wrap360", "wrap180", "spherical_to_cartesian", "cartesian_to_spherical",
    "direction", "pan_rel_deg", "encode_y", "decode_y", "camera_basis",
    "camera_position", "camera_to_world", "world_to_camera", "camera_to_world_vector",
    "mitsuba_sensor_to_world", "travel_direction", "tangent_basis", "Y_SIZE",
    "PHOTO_CAMERA_TILT_DEG", "ENVMAP_FRAMES", "equirect_to_direction", "direction_to_equirect",
    "equirect_pixel_directions", "equirect_solid_angles", "envmap_rotation", "envmap_to_world",
    "world_to_envmap", "mitsuba_envmap_to_world", "rotation_about",
    "pan_from_rel", "tangent_move", "rotation_z", "frame_z_to", "perpendicular_pair", "sensor_frame",
    "fold_over_zenith", "camera_to_pan_tilt", "upright_rectangle_to_world",
    "TARGET_FRAMES", "check_target_frame", "target_tilt_deg", "y_to_target", "target_to_y",
]

Y_SIZE = 7  # the paper's target vector: pan sin/cos, tilt sin/cos, r, g, b
PHOTO_CAMERA_TILT_DEG = 45.0  # assumed camera tilt of a photograph (the paper's choice)


def wrap360(angle_deg):
    """Wrap degrees into [0, 360).

    >>> float(wrap360(-90)), float(wrap360(360)), float(wrap360(725))
    (270.0, 0.0, 5.0)
    """
    a = np.mod(np.asarray(angle_deg, dtype=np.float64), 360.0)
    # np.mod(-1e-20, 360) returns 360.0 in floating point: fold it back to 0.
    return np.where(a >= 360.0, 0.0, a)


def wrap180(angle_deg):
    """Wrap degrees into [-180, 180).

    >>> float(wrap180(270)), float(wrap180(180)), float(wrap180(-190))
    (-90.0, -180.0, 170.0)
    """
    return wrap360(np.asarray(angle_deg, dtype=np.float64) + 180.0) - 180.0


def spherical_to_cartesian(r_m, pan_deg, tilt_deg) -> np.ndarray:
    """Position of spherical coordinates in the world frame.

    Args:
        r_m: radius in metres, any broadcastable shape.
        pan_deg: azimuth in degrees, counter-clockwise from +X toward +Y.
        tilt_deg: elevation in degrees above the floor plane (90 = zenith).

    Returns:
        Array of shape ``broadcast(...) + (3,)`` in metres.

    Pan 90 points along +Y, tilt 90 straight up:

    >>> (np.round(spherical_to_cartesian(2.0, 90.0, 0.0), 12) + 0.0).tolist()
    [0.0, 2.0, 0.0]
    >>> (np.round(spherical_to_cartesian(3.0, 45.0, 90.0), 12) + 0.0).tolist()
    [0.0, 0.0, 3.0]
    >>> spherical_to_cartesian([1.0, 2.0], 0.0, 0.0).shape
    (2, 3)
    """
    pan_rad = np.radians(np.asarray(pan_deg, dtype=np.float64))
    tilt_rad = np.radians(np.asarray(tilt_deg, dtype=np.float64))
    r = np.asarray(r_m, dtype=np.float64)
    return np.stack(np.broadcast_arrays(
        r * np.cos(tilt_rad) * np.cos(pan_rad),
        r * np.cos(tilt_rad) * np.sin(pan_rad),
        r * np.sin(tilt_rad)), axis=-1)


def direction(pan_deg, tilt_deg) -> np.ndarray:
    """Unit vector toward (pan, tilt), world frame; shape ``(..., 3)``.

    >>> (np.round(direction(90, 0), 12) + 0.0).tolist()
    [0.0, 1.0, 0.0]
    >>> (np.round(direction(180, 60), 12) + 0.0).tolist()   # (-cos 60, 0, sin 60)
    [-0.5, 0.0, 0.866025403784]
    """
    return spherical_to_cartesian(1.0, pan_deg, tilt_deg)


def tangent_basis(pan_deg: float, tilt_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents of the sphere at ``direction(pan, tilt)``, world frame.

    Returns ``(e_pan, e_tilt)``: ``e_pan`` points toward increasing pan (horizontal,
    counter-clockwise seen from above), ``e_tilt`` toward increasing tilt (up, toward the
    zenith). ``d(direction)/d(pan_rad) = cos(tilt) e_pan`` and
    ``d(direction)/d(tilt_rad) = e_tilt``. Defined at the zenith too (pan picks the frame).

    At (pan 0, tilt 0), i.e. on +X, increasing pan goes toward +Y and increasing tilt up:

    >>> e_pan, e_tilt = tangent_basis(0.0, 0.0)
    >>> (e_pan + 0.0).tolist(), (e_tilt + 0.0).tolist()
    ([0.0, 1.0, 0.0], [0.0, 0.0, 1.0])
    """
    p, t = np.radians(float(pan_deg)), np.radians(float(tilt_deg))
    e_pan = np.array([-np.sin(p), np.cos(p), 0.0])
    e_tilt = np.array([-np.sin(t) * np.cos(p), -np.sin(t) * np.sin(p), np.cos(t)])
    return e_pan, e_tilt


def cartesian_to_spherical(p) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`spherical_to_cartesian`.

    Args:
        p: ``(..., 3)`` positions in metres (world frame).

    Returns:
        ``(r_m, pan_deg in [0, 360), tilt_deg in [-90, 90])``. At the poles pan is 0.

    >>> r, pan, tilt = cartesian_to_spherical([0.0, -2.0, 2.0])
    >>> round(float(r), 9), float(pan), float(tilt)   # r = 2 sqrt(2)
    (2.828427125, 270.0, 45.0)
    """
    p = np.asarray(p, dtype=np.float64)
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    r = np.sqrt(x * x + y * y + z * z)
    pan_deg = wrap360(np.degrees(np.arctan2(y, x)))
    tilt_deg = np.degrees(np.arctan2(z, np.hypot(x, y)))
    return r, pan_deg, tilt_deg


def pan_rel_deg(pan_l_deg, pan_c_deg=0.0):
    """Light pan relative to the camera, ``wrap360(pan_l - pan_c)`` in [0, 360).

    >>> float(pan_rel_deg(30.0, 300.0)), float(pan_rel_deg(90.0))
    (90.0, 90.0)
    """
    return wrap360(np.asarray(pan_l_deg, dtype=np.float64) - pan_c_deg)


def pan_from_rel(pan_rel, pan_c_deg=0.0):
    """World pan of a light at ``pan_rel`` relative to a camera at ``pan_c_deg``:
    ``wrap360(pan_c + pan_rel)`` in [0, 360), the inverse of :func:`pan_rel_deg`.

    >>> float(pan_from_rel(90.0, 300.0)), float(pan_rel_deg(pan_from_rel(250.0, 170.0), 170.0))
    (30.0, 250.0)
    """
    return wrap360(np.asarray(pan_c_deg, dtype=np.float64) + pan_rel)


def tangent_move(pan_deg: float, tilt_deg: float, du_deg: float, dv_deg: float) -> tuple[float, float]:
    """Move a direction by arc steps: ``du`` along increasing pan (horizontal), ``dv``
    along increasing tilt (toward the zenith), both in degrees of arc, along the
    geodesic of length ``|(du, dv)|``; returns ``(pan_deg in [0, 360), tilt_deg in
    [-90, 90])``. Regular at the zenith (there the pan we came with is kept).

    On the horizon a pan step is a plain pan change; 20 degrees of arc up from tilt 80
    cross the zenith and come down on the other side (pan + 180, tilt 80):

    >>> [round(x, 9) for x in tangent_move(10.0, 0.0, 5.0, 0.0)]
    [15.0, 0.0]
    >>> [round(x, 9) for x in tangent_move(0.0, 80.0, 0.0, 20.0)]
    [180.0, 80.0]
    """
    d = direction(pan_deg, tilt_deg)
    e_pan, e_tilt = tangent_basis(pan_deg, tilt_deg)
    step = np.radians(du_deg) * e_pan + np.radians(dv_deg) * e_tilt
    angle = float(np.linalg.norm(step))
    moved = d if angle == 0 else d * np.cos(angle) + step / angle * np.sin(angle)
    _, pan, tilt = cartesian_to_spherical(moved)
    if abs(float(tilt)) > 89.9999:
        pan = pan_deg
    return float(pan), float(tilt)


def rotation_z(angle_deg: float) -> np.ndarray:
    """3x3 rotation about +Z by ``angle_deg`` (counter-clockwise seen from above, i.e.
    toward increasing pan): ``rotation_z(a) @ direction(p, t) == direction(p + a, t)``.

    >>> bool(np.allclose(rotation_z(30.0) @ direction(10.0, 20.0), direction(40.0, 20.0)))
    True
    """
    a = math.radians(float(angle_deg))
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def frame_z_to(d) -> np.ndarray:
    """3x3 rotation taking local +Z to the unit vector along ``d`` (columns: x, y, z of
    the local frame in world coordinates; x and y any orthonormal pair).

    >>> m = frame_z_to([0.0, 3.0, 0.0])
    >>> (np.round(m[:, 2], 12) + 0.0).tolist(), bool(np.allclose(m.T @ m, np.eye(3)))
    ([0.0, 1.0, 0.0], True)
    """
    d = np.asarray(d, dtype=np.float64)
    d = d / np.linalg.norm(d)
    helper = np.array([1.0, 0.0, 0.0]) if abs(d[2]) > 0.9 else np.array([0.0, 0.0, 1.0])
    x = np.cross(helper, d)
    x /= np.linalg.norm(x)
    y = np.cross(d, x)
    return np.stack([x, y, d], axis=1)


def perpendicular_pair(axis) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors ``(e1, e2)`` that complete the unit vector ``axis`` to a
    right-handed orthonormal frame ``(e1, e2, axis)``: ``e1 = axis x h / |axis x h|``
    with the helper ``h`` = +Y (+X when ``axis`` is within 26 degrees of +-Y), and
    ``e2 = axis x e1``. Used to walk a cone or a circle around ``axis``.

    Args:
        axis: a unit 3-vector (any frame; the pair is in the same frame).

    Returns:
        ``(e1, e2)``, float64 unit 3-vectors, each orthogonal to ``axis`` and to the other.

    >>> e1, e2 = perpendicular_pair([0.0, 0.0, 1.0])
    >>> (e1 + 0.0).tolist(), (e2 + 0.0).tolist()
    ([-1.0, 0.0, 0.0], [0.0, -1.0, 0.0])
    """
    a = np.asarray(axis, dtype=np.float64)
    e1 = np.cross(a, [0.0, 1.0, 0.0] if abs(a[1]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(a, e1)


def sensor_frame(forward, up) -> np.ndarray:
    """3x3 rotation of a Mitsuba sensor (local +X left, +Y up, +Z forward) looking along
    the unit vector ``forward``, its up as close to ``up`` as orthogonality allows.

    Args:
        forward: unit 3-vector, world frame: the viewing direction.
        up: 3-vector, world frame, not parallel to ``forward``.

    Returns:
        ``(3, 3)`` float64 whose columns are the sensor's left, up and forward in world
        coordinates (the upper-left block of a Mitsuba ``to_world``).

    A sensor looking along -X with up +Z has its left at -Y, as
    :func:`mitsuba_sensor_to_world` of a level camera on +X:

    >>> m = sensor_frame([-1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    >>> (m[:, 0] + 0.0).tolist(), (m[:, 1] + 0.0).tolist()
    ([0.0, -1.0, 0.0], [0.0, 0.0, 1.0])
    """
    fwd = np.asarray(forward, np.float64)
    left = np.cross(up, fwd)
    left /= np.linalg.norm(left)
    return np.stack([left, np.cross(fwd, left), fwd], axis=1)


def encode_y(pan_l_deg, tilt_l_deg, rgb, tilt_c_deg, pan_c_deg=0.0) -> np.ndarray:
    """The paper's 7-vector ``[sin(pan_c-pan_l), cos(pan_c-pan_l), sin(tilt_c-tilt_l),
    cos(tilt_c-tilt_l), r, g, b]``.

    Args:
        pan_l_deg, tilt_l_deg: light pan and tilt in degrees (world frame), shape (...).
        rgb: ``(..., 3)`` linear RGB, stored as given (datasets store unit norm).
        tilt_c_deg, pan_c_deg: camera tilt and pan in degrees.

    Returns:
        ``(..., 7)`` float64.

    A light 90 deg to the camera's right and 15 deg above its tilt of 45:
    sin(-90) = -1, cos(-90) = 0, sin(-15), cos(-15), then the colour.

    >>> (np.round(encode_y(90.0, 60.0, [1.0, 0.0, 0.0], tilt_c_deg=45.0), 6) + 0.0).tolist()
    [-1.0, 0.0, -0.258819, 0.965926, 1.0, 0.0, 0.0]
    """
    dpan_rad = np.radians(np.asarray(pan_c_deg, dtype=np.float64) - pan_l_deg)
    dtilt_rad = np.radians(np.asarray(tilt_c_deg, dtype=np.float64) - tilt_l_deg)
    rgb = np.asarray(rgb, dtype=np.float64)
    angles = np.stack(np.broadcast_arrays(np.sin(dpan_rad), np.cos(dpan_rad),
                                          np.sin(dtilt_rad), np.cos(dtilt_rad)), axis=-1)
    if rgb.shape[-1:] != (3,):
        raise ValueError(f"expected rgb with last axis 3, got shape {rgb.shape}")
    lead = np.broadcast_shapes(angles.shape[:-1], rgb.shape[:-1])
    return np.concatenate([np.broadcast_to(angles, lead + (4,)),
                           np.broadcast_to(rgb, lead + (3,))], axis=-1)


def fold_over_zenith(pan_deg, tilt_deg):
    """The same direction with tilt in [-90, 90]: a tilt past the zenith (> 90) becomes
    ``180 - tilt`` seen from the other side (pan + 180), and past the nadir likewise.

    >>> fold_over_zenith(10.0, 108.8)
    (190.0, 71.2)
    >>> fold_over_zenith(350.0, -100.0)
    (170.0, -80.0)
    """
    pan = np.asarray(pan_deg, dtype=np.float64)
    tilt = wrap180(np.asarray(tilt_deg, dtype=np.float64))
    over, under = tilt > 90.0, tilt < -90.0
    flip = over | under
    tilt = np.where(over, 180.0 - tilt, np.where(under, -180.0 - tilt, tilt))
    pan = wrap360(np.where(flip, pan + 180.0, pan))
    if pan.ndim == 0:
        return round(float(pan), 10), round(float(tilt), 10)
    return pan, tilt


def decode_y(y, tilt_c_deg, pan_c_deg=0.0):
    """Decode a 7-vector (``(..., 7)``) into light angles and colour.

    The sin/cos pairs need not be normalised (a network's raw output is fine).

    Returns:
        ``(pan_l_deg in [0, 360), tilt_l_deg in [-90, 90], rgb (..., 3))``. With
        ``pan_c = 0`` the returned pan equals ``pan_rel``. A tilt past the zenith is
        folded over it (:func:`fold_over_zenith`), as the conventions require.

    The inverse of :func:`encode_y`, even from unnormalised sin/cos pairs:

    >>> pan, tilt, rgb = decode_y([-2.0, 0.0, -0.5, 0.5, 1.0, 0.0, 0.0], tilt_c_deg=45.0)
    >>> float(pan), float(tilt), rgb.tolist()
    (90.0, 90.0, [1.0, 0.0, 0.0])
    """
    y = np.asarray(y, dtype=np.float64)
    if y.shape[-1] != Y_SIZE:
        raise ValueError(f"expected a 7-vector (last axis 7), got shape {y.shape}")
    pan_l = pan_c_deg - np.degrees(np.arctan2(y[..., 0], y[..., 1]))
    tilt_l = np.asarray(tilt_c_deg, dtype=np.float64) - np.degrees(np.arctan2(y[..., 2], y[..., 3]))
    pan_l, tilt_l = fold_over_zenith(pan_l, tilt_l)
    return np.asarray(pan_l, dtype=np.float64), np.asarray(tilt_l, dtype=np.float64), y[..., 4:7]


# --- the network's target frame ----------------------------------------------------------
#
# A network may learn the paper's 7-vector as it is (``"world"``: the light relative to the
# camera in the world's spherical coordinates, decoded with the camera's tilt) or the light
# in the camera frame (``"camera"``): the paper's encoding of the same camera-frame
# direction for a *level* camera (tilt 0, pan 0), where the world frame and the camera
# frame differ only by naming the axes (camera x = world +Y, y = +Z, z = +X). A camera-frame
# target is decoded with tilt 0 into the camera-frame direction, which the camera's tilt
# (given, predicted or assumed) then turns into the world. Mirroring the image negates
# camera x, i.e. the pan of the level camera: ``flip_y`` holds in both frames. Datasets
# and predictions files always store the paper's y (docs/conventions.md).
TARGET_FRAMES = ("world", "camera")


def check_target_frame(frame: str) -> None:
    """ValueError unless ``frame`` is one of :data:`TARGET_FRAMES`."""
    if frame not in TARGET_FRAMES:
        raise ValueError(f"target frame must be one of {', '.join(TARGET_FRAMES)}, got {frame!r}")


def target_tilt_deg(camera_tilt_deg, frame: str):
    """The camera tilt a target of ``frame`` decodes with (:func:`decode_y`): the camera's
    own (``"world"``), or 0 (``"camera"``: a level camera), shaped like ``camera_tilt_deg``.

    >>> float(target_tilt_deg(30.0, "world")), target_tilt_deg([30.0, 45.0], "camera").tolist()
    (30.0, [0.0, 0.0])
    """
    check_target_frame(frame)
    tilt = np.asarray(camera_tilt_deg, dtype=np.float64)
    return tilt if frame == "world" else np.zeros_like(tilt)


def _turn_by_camera_tilt(d, tilt_c_deg, sign: float) -> np.ndarray:
    """World directions ``d`` ``(..., 3)`` turned about world +Y (the camera's x axis at pan
    0) so that a camera at ``tilt_c_deg`` becomes level (``sign`` +1) or back (-1)."""
    t = np.radians(sign * np.asarray(tilt_c_deg, dtype=np.float64))
    c, s = np.cos(t), np.sin(t)
    d = np.asarray(d, dtype=np.float64)
    return np.stack(np.broadcast_arrays(c * d[..., 0] + s * d[..., 2], d[..., 1],
                                        -s * d[..., 0] + c * d[..., 2]), axis=-1)


def y_to_target(y, camera_tilt_deg, frame: str) -> np.ndarray:
    """The network target in ``frame`` of the paper's 7-vectors ``y`` ``(..., 7)`` of cameras
    at pan 0 and tilt ``camera_tilt_deg`` (degrees, broadcast): ``"world"`` gives ``y``
    itself (a copy), ``"camera"`` the paper's encoding, for a level camera, of the light's
    camera-frame direction (``world_to_camera`` of the light, read as pan and tilt of a
    camera at tilt 0); the colour is kept.

    A light at the camera (pan_rel 0, tilt = the camera's 30) is straight ahead of a level
    camera: pan 0, tilt 0.

    >>> y = encode_y(0.0, 30.0, [1.0, 0.0, 0.0], tilt_c_deg=30.0)
    >>> (np.round(y_to_target(y, 30.0, "camera"), 12) + 0.0).tolist()
    [0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0]
    """
    check_target_frame(frame)
    y = np.asarray(y, dtype=np.float64)
    if frame == "world":
        return np.array(y, copy=True)
    pan, tilt, rgb = decode_y(y, camera_tilt_deg)
    level = _turn_by_camera_tilt(direction(pan, tilt), camera_tilt_deg, +1.0)
    _, pan0, tilt0 = cartesian_to_spherical(level)
    return encode_y(pan0, tilt0, rgb, tilt_c_deg=0.0)


def target_to_y(target, camera_tilt_deg, frame: str) -> np.ndarray:
    """The paper's 7-vectors of network outputs ``target`` ``(..., 7)`` in ``frame`` (raw:
    the sin/cos pairs need not be normalised) for cameras at pan 0 and tilt
    ``camera_tilt_deg``: the inverse of :func:`y_to_target`. ``"world"`` gives the outputs
    themselves (a copy); ``"camera"`` a paper's y with unit sin/cos pairs, colour kept.

    >>> y = encode_y(250.0, 20.0, [0.0, 1.0, 0.0], tilt_c_deg=40.0)
    >>> bool(np.allclose(target_to_y(y_to_target(y, 40.0, "camera"), 40.0, "camera"), y))
    True
    """
    check_target_frame(frame)
    target = np.asarray(target, dtype=np.float64)
    if frame == "world":
        return np.array(target, copy=True)
    pan0, tilt0, rgb = decode_y(target, 0.0)
    world = _turn_by_camera_tilt(direction(pan0, tilt0), camera_tilt_deg, -1.0)
    _, pan, tilt = cartesian_to_spherical(world)
    return encode_y(pan, tilt, rgb, tilt_c_deg=camera_tilt_deg)


def camera_position(tilt_c_deg, r_c_m=20.0, pan_c_deg=0.0) -> np.ndarray:
    """Camera centre in metres (world frame): spherical (r_c, pan_c, tilt_c).

    >>> (np.round(camera_position(30.0, r_c_m=2.0), 12) + 0.0).tolist()   # (2 cos 30, 0, 2 sin 30)
    [1.732050807569, 0.0, 1.0]
    """
    return spherical_to_cartesian(r_c_m, pan_c_deg, tilt_c_deg)


def camera_basis(tilt_c_deg, pan_c_deg=0.0):
    """World-frame unit vectors ``(right, up, forward)`` of a camera looking at the origin.

    ``forward`` points from the camera to the origin, ``up`` is +Z made orthogonal to
    it, ``right = forward x up``. Tilts of exactly +-90 (looking straight down) are
    degenerate and rejected.

    A level camera on +X looks along -X; its right-hand side is +Y:

    >>> right, up, forward = camera_basis(0.0)
    >>> (right + 0.0).tolist(), (up + 0.0).tolist(), (forward + 0.0).tolist()
    ([0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0])
    """
    if abs(float(tilt_c_deg)) >= 90.0:
        raise ValueError(f"camera tilt must be in (-90, 90) degrees, got {tilt_c_deg}")
    forward = -direction(pan_c_deg, tilt_c_deg)
    world_up = np.array([0.0, 0.0, 1.0])
    right = np.cross(forward, world_up)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    return right, up, forward


def world_to_camera(v_world, tilt_c_deg, pan_c_deg=0.0) -> np.ndarray:
    """Rotate world vectors ``(..., 3)`` into the camera frame (x right, y up, z toward camera).

    For a level camera on +X: world +Y is the image's right, +X points toward the camera.

    >>> (np.round(world_to_camera([[0, 1, 0], [1, 0, 0]], 0.0), 12) + 0.0).tolist()
    [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    """
    right, up, forward = camera_basis(tilt_c_deg, pan_c_deg)
    rot = np.stack([right, up, -forward])  # rows: camera axes in world coordinates
    return np.asarray(v_world, dtype=np.float64) @ rot.T


def camera_to_world_vector(v_cam, tilt_c_deg, pan_c_deg=0.0) -> np.ndarray:
    """Inverse of :func:`world_to_camera` (a rotation: its transpose).

    >>> v = np.array([0.3, -0.2, 0.9])
    >>> bool(np.allclose(camera_to_world_vector(world_to_camera(v, 35.0, 20.0), 35.0, 20.0), v))
    True
    """
    right, up, forward = camera_basis(tilt_c_deg, pan_c_deg)
    rot = np.stack([right, up, -forward])
    return np.asarray(v_cam, dtype=np.float64) @ rot


def camera_to_world(tilt_c_deg, r_c_m=20.0, pan_c_deg=0.0) -> np.ndarray:
    """4x4 camera-frame (x right, y up, z toward camera) to world matrix.

    The camera-frame origin maps to the camera position:

    >>> (np.round(camera_to_world(0.0, r_c_m=20.0) @ [0, 0, 0, 1], 12) + 0.0).tolist()
    [20.0, 0.0, 0.0, 1.0]
    """
    right, up, forward = camera_basis(tilt_c_deg, pan_c_deg)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2] = right, up, -forward
    m[:3, 3] = camera_position(tilt_c_deg, r_c_m, pan_c_deg)
    return m


def upright_rectangle_to_world(pan_deg: float, distance_m: float, half_width_m: float,
                               height_m: float) -> np.ndarray:
    """4x4 matrix placing Mitsuba's ``rectangle`` ([-1, 1]^2, normal +z) upright on the
    floor: its centre line at horizontal distance ``distance_m`` from the origin toward pan
    ``pan_deg``, its normal toward the origin, ``2 * half_width_m`` wide, ``height_m`` tall
    (a room's wall, a studio backdrop).

    >>> m = upright_rectangle_to_world(180.0, 5.0, 2.0, 3.0)
    >>> (np.round(m @ [0, 0, 0, 1], 12) + 0.0).tolist(), (np.round(m[:3, 2], 12) + 0.0).tolist()
    ([-5.0, 0.0, 1.5, 1.0], [1.0, 0.0, 0.0])
    """
    outward = rotation_z(pan_deg)[:, 0]
    inward, up = -outward, np.array([0.0, 0.0, 1.0])
    m = np.eye(4)
    m[:3, 0] = np.cross(up, inward) * half_width_m   # local x; x * y = z holds: tangent x up = inward
    m[:3, 1] = up * height_m / 2.0
    m[:3, 2] = inward
    m[:3, 3] = outward * distance_m + up * height_m / 2.0
    return m


def mitsuba_sensor_to_world(tilt_c_deg, r_c_m=20.0, pan_c_deg=0.0) -> np.ndarray:
    """4x4 ``to_world`` of a Mitsuba sensor (local +X left, +Y up, +Z forward).

    Equal to Mitsuba's ``look_at(origin=camera, target=0, up=+Z)``.

    Local +Z (forward) of a level camera on +X is world -X, local +X (left) world -Y:

    >>> m = mitsuba_sensor_to_world(0.0)
    >>> (m[:3, 2] + 0.0).tolist(), (m[:3, 0] + 0.0).tolist()
    ([-1.0, 0.0, 0.0], [0.0, -1.0, 0.0])
    """
    right, up, forward = camera_basis(tilt_c_deg, pan_c_deg)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2] = -right, up, forward
    m[:3, 3] = camera_position(tilt_c_deg, r_c_m, pan_c_deg)
    return m


def travel_direction(to_light) -> np.ndarray:
    """The way light travels (Mitsuba ``directional`` emitter ``direction``) from a
    ``to_light`` vector (scene toward light). The single place the sign flips.

    >>> travel_direction([0.0, 0.0, 1.0]).tolist()   # light overhead travels down
    [-0.0, -0.0, -1.0]
    """
    return -np.asarray(to_light, dtype=np.float64)


def camera_to_pan_tilt(to_light_cam, camera_tilt_deg: float) -> tuple[float, float]:
    """``(pan_rel_deg, tilt_deg)`` of a camera-frame direction for a camera at pan 0 and
    the given tilt (the conventions' world frame: pan_rel 90 = camera's right)."""
    world = camera_to_world_vector(np.asarray(to_light_cam, np.float64), camera_tilt_deg)
    _, pan_deg, tilt_deg = cartesian_to_spherical(world)
    return float(pan_deg), float(tilt_deg)


# --- environment maps (equirectangular) ------------------------------------------------
#
# Convention (docs/conventions.md, "Environment-map predictions"):
#   * A map is ``(H, W, 3)``, ``W == 2 H``; u = (column + 0.5) / W runs left to right,
#     v = (row + 0.5) / H top to bottom; pixel centres at +0.5.
#   * Its own frame is a camera frame (x right, y up, z toward the viewer's back):
#     ``phi = 360 (u - 0.5)`` degrees of azimuth from the viewing direction (-z) toward
#     the right (+x), ``theta = 90 - 180 v`` degrees of elevation above the x-z plane
#     (+y = up = the image's up):
#     ``d = (cos theta sin phi, sin theta, -cos theta cos phi)``.
#     The centre column (u = 0.5) looks along the viewing direction, u = 0.75 to the
#     right, u = 0.25 to the left, the side columns (u = 0, 1) behind; the top row is up.
#   * ``envmap_frame = "camera"``: that frame is the image's camera frame (this module's
#     camera frame: x image right, y image up, z toward the camera).
#     ``envmap_frame = "world"``: that frame is the camera frame of a level camera at
#     pan 0 (x = world +Y, y = world +Z, z = world +X): v = 0 is the zenith, the centre
#     column looks toward pan 180 (-X) and pan = wrap360(-360 u), tilt = 90 - 180 v.
ENVMAP_FRAMES = ("camera", "world")


def equirect_to_direction(u, v) -> np.ndarray:
    """Unit vectors ``(..., 3)`` in the map's own frame of map coordinates ``u, v`` in
    [0, 1] (u left to right, v top to bottom; see the convention above).

    The centre of the map looks along -z (forward), u = 0.75 along +x (right), v = 0 up:

    >>> (np.round(equirect_to_direction([0.5, 0.75, 0.3], [0.5, 0.5, 0.0]), 12) + 0.0).tolist()
    [[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    """
    phi_rad = 2.0 * np.pi * (np.asarray(u, dtype=np.float64) - 0.5)
    theta_rad = np.pi * (0.5 - np.asarray(v, dtype=np.float64))
    phi_rad, theta_rad = np.broadcast_arrays(phi_rad, theta_rad)
    return np.stack([np.cos(theta_rad) * np.sin(phi_rad), np.sin(theta_rad),
                     -np.cos(theta_rad) * np.cos(phi_rad)], axis=-1)


def direction_to_equirect(d) -> tuple[np.ndarray, np.ndarray]:
    """Map coordinates ``(u in [0, 1), v in [0, 1])`` of directions ``(..., 3)`` (any
    length) in the map's own frame: the inverse of :func:`equirect_to_direction`.

    >>> u, v = direction_to_equirect([[1.0, 0.0, 0.0], [0.0, 0.0, 2.0]])
    >>> u.tolist(), v.tolist()
    ([0.75, 0.0], [0.5, 0.5])
    """
    d = np.asarray(d, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    phi_rad = np.arctan2(d[..., 0], -d[..., 2])
    u = np.mod(phi_rad / (2.0 * np.pi) + 0.5, 1.0)
    u = np.where(u >= 1.0, 0.0, u)
    v = np.arccos(np.clip(d[..., 1], -1.0, 1.0)) / np.pi
    return u, v


def equirect_pixel_directions(height: int, width: int) -> np.ndarray:
    """``(height, width, 3)`` unit vectors of the pixel centres of a map, in its own frame."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    return equirect_to_direction(u[None, :], v[:, None])


def equirect_solid_angles(height: int, width: int) -> np.ndarray:
    """``(height, 1)`` solid angle (steradians) of one pixel of each row of an
    equirectangular map: ``(2 pi / W) (cos(pi i / H) - cos(pi (i + 1) / H))``; the whole
    map sums to 4 pi exactly.

    >>> bool(np.isclose(equirect_solid_angles(8, 16).sum() * 16, 4 * np.pi))
    True
    """
    edges = np.cos(np.pi * np.arange(height + 1) / height)
    return ((2.0 * np.pi / width) * (edges[:-1] - edges[1:]))[:, None]


def envmap_rotation(frame: str, camera_tilt_deg: float = 0.0, camera_pan_deg: float = 0.0) -> np.ndarray:
    """3x3 rotation from a map's own frame to the world frame.

    ``frame = "camera"``: the image's camera (tilt and pan in degrees; columns right, up,
    toward the camera, as :func:`camera_to_world_vector`); ``"world"``: a level camera at
    pan 0 whatever the arguments.

    A world map's centre column looks toward -X (pan 180), its top row at the zenith:

    >>> rot = envmap_rotation("world")
    >>> (np.round(rot @ equirect_to_direction(0.5, 0.5), 12) + 0.0).tolist()
    [-1.0, 0.0, 0.0]
    """
    if frame not in ENVMAP_FRAMES:
        raise ValueError(f"envmap frame must be one of {', '.join(ENVMAP_FRAMES)}, got {frame!r}")
    if frame == "world":
        camera_tilt_deg, camera_pan_deg = 0.0, 0.0
    right, up, forward = camera_basis(camera_tilt_deg, camera_pan_deg)
    return np.stack([right, up, -forward], axis=1)


def envmap_to_world(d_map, frame: str, camera_tilt_deg: float = 0.0, camera_pan_deg: float = 0.0) -> np.ndarray:
    """World-frame directions ``(..., 3)`` of map-frame directions (see :func:`envmap_rotation`)."""
    return np.asarray(d_map, dtype=np.float64) @ envmap_rotation(frame, camera_tilt_deg, camera_pan_deg).T


def world_to_envmap(d_world, frame: str, camera_tilt_deg: float = 0.0, camera_pan_deg: float = 0.0) -> np.ndarray:
    """Map-frame directions ``(..., 3)`` of world directions: the inverse of :func:`envmap_to_world`."""
    return np.asarray(d_world, dtype=np.float64) @ envmap_rotation(frame, camera_tilt_deg, camera_pan_deg)


# Mitsuba's ``envmap`` emitter reads local direction ``m`` at
# ``u = atan2(m_x, -m_z) / (2 pi)``, ``v = acos(m_y) / pi`` (pixel centres at +0.5, local
# +Y up). Our map frame at the same (u, v) is ``(-m_x, m_y, -m_z)``: a half turn about y.
MITSUBA_ENVMAP_LOCAL = np.diag([-1.0, 1.0, -1.0])


def mitsuba_envmap_to_world(frame: str, camera_tilt_deg: float = 0.0, camera_pan_deg: float = 0.0) -> np.ndarray:
    """4x4 ``to_world`` of Mitsuba's ``envmap`` emitter that shows a map of the given frame
    (pixels unchanged) in the world frame.

    The centre pixel of a world map seen from the world: Mitsuba's local direction of
    u = v = 0.5 is +Z, which must land on world -X:

    >>> m = mitsuba_envmap_to_world("world")
    >>> (np.round(m[:3, :3] @ [0.0, 0.0, 1.0], 12) + 0.0).tolist()
    [-1.0, 0.0, 0.0]
    """
    m = np.eye(4)
    m[:3, :3] = envmap_rotation(frame, camera_tilt_deg, camera_pan_deg) @ MITSUBA_ENVMAP_LOCAL
    return m


def rotation_about(axis, angle_deg: float) -> np.ndarray:
    """3x3 rotation by ``angle_deg`` about ``axis`` (any length), right-handed
    (Rodrigues): counter-clockwise seen from the tip of the axis.

    >>> bool(np.allclose(rotation_about([0, 0, 2], 30.0), rotation_z(30.0)))
    True
    """
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a)
    t = math.radians(float(angle_deg))
    k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + math.sin(t) * k + (1.0 - math.cos(t)) * (k @ k)

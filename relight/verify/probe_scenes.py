"""Validation renders for the sphere procedure: a chrome and a gray sphere seen by a
perspective camera, lit by a small spherical area light whose direction is known.

A point or directional light would be invisible in a perfect mirror, so the light is a
sphere of angular radius :data:`LIGHT_ANGULAR_RADIUS_DEG` placed
:data:`LIGHT_DISTANCE_RADII` chrome radii away from the chrome sphere (the direction from
any point of the chrome sphere to the light's centre is within 0.06 deg of the truth).

The scene is built directly in the camera frame of ``shared/conventions.md`` (x image
right, y image up, z toward the camera; the camera at the origin looks along -z), so the
true ``to_light_camera`` is the unit vector from the chrome sphere's centre to the light.
A scene is front lit when the light is on the camera's side of the chrome sphere
(``to_light . to_camera > 0``) and back lit otherwise; back lights stay within
:data:`MAX_VIEW_LIGHT_ANGLE_DEG` of the direction to the camera, beyond which the
highlight falls within a few pixels of the sphere's rim.

Clutter (optional): boxes and cylinders of random colours on the ground near the spheres
(never hiding them), and a dim emitting panel (a "window") whose reflection in the chrome
sphere is a bright patch that is not the light.
"""
from __future__ import annotations

__all__ = [
    "LIGHT_ANGULAR_RADIUS_DEG", "LIGHT_DISTANCE_RADII", "LIGHT_IRRADIANCE", "GRAY_ALBEDO", "SKY_RADIANCE",
    "GROUND_ALBEDO", "WINDOW_RADIANCE", "MAX_VIEW_LIGHT_ANGLE_DEG", "MIN_LIGHT_ELEVATION_DEG", "FOV_RANGE_DEG",
    "RADIUS_PX_RANGE", "FIREFLY_RATIO", "DEPTH_RANGE", "ProbeScene", "sample_probe_scene", "remove_fireflies",
    "render_probe_scene",
    "specular_point", "check_chrome_radius", "sample_room_scene", "room_sphere_camera", "room_circle", "room_sphere", "render_room_mitsuba", "CYCLES_PIXEL_FILTERS", "render_room_cycles", "main",
]

import math
import os
from dataclasses import dataclass

import numpy as np

from relight import backend, render

LIGHT_ANGULAR_RADIUS_DEG = 2.0
LIGHT_DISTANCE_RADII = 1000.0
LIGHT_IRRADIANCE = 4.0          # W/m^2 at the spheres: the gray sphere's lit side near 0.6
GRAY_ALBEDO = 0.5
SKY_RADIANCE = 0.08
GROUND_ALBEDO = 0.35
WINDOW_RADIANCE = 0.9           # "bright surroundings": clearly visible, below the light
MAX_VIEW_LIGHT_ANGLE_DEG = 140.0
MIN_LIGHT_ELEVATION_DEG = 10.0  # above the ground plane (camera-frame y)
FOV_RANGE_DEG = (20.0, 60.0)
RADIUS_PX_RANGE = (40.0, 80.0)  # chrome sphere radius in pixels
FIREFLY_RATIO = 3.0
DEPTH_RANGE = (4.0, 10.0)       # sphere distances, in chrome-sphere-free units


@dataclass(frozen=True)
class ProbeScene:
    """One validation scene with its truth (camera frame, pixels per the conventions)."""
    width: int
    height: int
    fov_deg: float
    chrome: Sphere                   # true chrome sphere (camera frame, scene units)
    gray: Sphere
    to_light: tuple[float, float, float]
    front: bool
    clutter: tuple                   # (kind, centre, size, rgb) of each clutter object
    window: tuple | None             # (centre, normal, size) of the emitting panel

    @property
    def camera(self) -> Camera:
        from relight.probe.geometry import Camera
        return Camera.from_fov(self.width, self.height, self.fov_deg)

    def circle(self, which: str = "chrome") -> tuple[float, float, float]:
        """The circle closest to a sphere's image outline (what a person would mark)."""
        from relight.probe.geometry import outline_circle
        return outline_circle(self.camera, getattr(self, which))

    def truth(self) -> dict:
        return {"to_light_camera": list(self.to_light), "front": self.front, "fov_deg": self.fov_deg,
                "chrome_circle": list(self.circle("chrome")), "gray_circle": list(self.circle("gray"))}


def _place_sphere(rng, camera: Camera, radius_px: float, taken: list) -> Sphere | None:
    from relight.probe.geometry import Sphere
    for _ in range(200):
        x = rng.uniform(radius_px * 1.3 + 4, camera.width - radius_px * 1.3 - 4)
        y = rng.uniform(radius_px * 1.3 + 4, camera.height - radius_px * 1.3 - 4)
        if any(math.hypot(x - tx, y - ty) < (radius_px + tr) * 1.35 + 8 for tx, ty, tr in taken):
            continue
        _, d = camera.rays(np.array(x), np.array(y))
        depth = rng.uniform(*DEPTH_RANGE)
        centre = d * depth
        cos_t = abs(d[2])
        radius = depth * math.sin(math.atan(radius_px * cos_t / camera.focal_px))
        taken.append((x, y, radius_px))
        return Sphere(tuple(centre.tolist()), float(radius))
    return None


def _sample_light(rng, chrome: Sphere, front: bool) -> np.ndarray:
    to_camera = -chrome.c / np.linalg.norm(chrome.c)
    for _ in range(10000):
        l = rng.normal(size=3)
        l /= np.linalg.norm(l)
        if math.degrees(math.asin(l[1])) < MIN_LIGHT_ELEVATION_DEG:
            continue
        cos_v = float(l @ to_camera)
        if (cos_v > 0) != front or math.degrees(math.acos(cos_v)) > MAX_VIEW_LIGHT_ANGLE_DEG:
            continue
        return l
    raise RuntimeError("could not sample a light direction")


def sample_probe_scene(seed: int, width: int = 640, height: int = 480, clutter: bool = False,
                 front: bool | None = None, fov_deg: float | None = None) -> ProbeScene:
    """A random validation scene: FOV uniform in :data:`FOV_RANGE_DEG`, the two spheres
    anywhere in the frame (chrome radius in :data:`RADIUS_PX_RANGE` pixels), the light
    in front (``front``) or behind (random if ``None``)."""
    from relight.probe.geometry import Camera
    rng = np.random.default_rng(seed)
    fov = float(fov_deg if fov_deg is not None else rng.uniform(*FOV_RANGE_DEG))
    camera = Camera.from_fov(width, height, fov)
    taken: list = []
    scale = min(width, height) / 480.0
    chrome = _place_sphere(rng, camera, rng.uniform(*RADIUS_PX_RANGE) * scale, taken)
    gray = _place_sphere(rng, camera, rng.uniform(*RADIUS_PX_RANGE) * scale, taken)
    if chrome is None or gray is None:
        raise RuntimeError("could not place the spheres")
    front = bool(rng.random() < 0.5) if front is None else bool(front)
    light = _sample_light(rng, chrome, front)
    items, window = [], None
    if clutter:
        ground_y = min(chrome.c[1] - chrome.radius, gray.c[1] - gray.radius) - 0.3
        for _ in range(int(rng.integers(4, 8))):
            for _try in range(50):
                x, y = rng.uniform(20, width - 20), rng.uniform(height * 0.3, height - 10)
                if any(math.hypot(x - tx, y - ty) < tr * 1.6 + 30 * scale for tx, ty, tr in taken):
                    continue
                _, d = camera.rays(np.array(x), np.array(y))
                depth = rng.uniform(DEPTH_RANGE[0] * 1.2, DEPTH_RANGE[1] * 1.5)
                p = d * depth
                size = float(rng.uniform(0.3, 0.9))
                if p[1] - size < ground_y:     # stand it on the ground
                    p[1] = ground_y + size
                centre = tuple(p.tolist())
                # keep the spheres' outlines clear: no object between camera and sphere
                if any(_occludes(centre, size * 1.8, s) for s in (chrome, gray)):
                    continue
                items.append((str(rng.choice(["cube", "cylinder"])), centre, size,
                              tuple(rng.uniform(0.05, 0.85, 3).tolist())))
                taken.append((x, y, 25 * scale))
                break
        depth = DEPTH_RANGE[1] * 2
        side = rng.choice([-1.0, 1.0])
        window = ((side * depth * 0.8, depth * 0.35, -depth * 0.2), (-side, 0.0, 0.3), depth * 0.25)
    return ProbeScene(width, height, fov, chrome, gray, tuple(light.tolist()), front,
                      tuple(items), window)


def _occludes(centre, radius: float, sphere: Sphere) -> bool:
    """Whether a ball of ``radius`` at ``centre`` overlaps the cone from the camera to
    ``sphere`` (widened by 30%), or sits too close to it."""
    c = np.asarray(centre, np.float64)
    s = sphere.c
    if np.linalg.norm(c - s) < radius + sphere.radius * 1.5:
        return True
    a = s / np.linalg.norm(s)
    along = c @ a
    if along <= 0:
        return False
    off = np.linalg.norm(c - along * a)
    cone = along * math.tan(math.asin(min(sphere.radius / np.linalg.norm(s), 0.999)) * 1.3)
    return off < cone + radius and along < np.linalg.norm(s) + sphere.radius + radius


def _scene_dict(scene: ProbeScene, spp: int) -> dict:
    mi = backend.mitsuba()
    t = mi.ScalarTransform4f
    chrome, gray = scene.chrome, scene.gray
    light_distance = LIGHT_DISTANCE_RADII * chrome.radius
    light_radius = light_distance * math.tan(math.radians(LIGHT_ANGULAR_RADIUS_DEG))
    sin_a = math.sin(math.radians(LIGHT_ANGULAR_RADIUS_DEG))
    radiance = LIGHT_IRRADIANCE / (math.pi * sin_a * sin_a)
    light_centre = chrome.c + light_distance * np.asarray(scene.to_light)
    to_world = np.diag([-1.0, 1.0, -1.0, 1.0])     # Mitsuba sensor: +X left, +Y up, +Z forward
    d = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 6, "hide_emitters": True},
        "sensor": render.sensor(scene.width, scene.fov_deg, to_world=t(to_world), height=scene.height,
                                rfilter="gaussian"),
        "chrome": {"type": "sphere", "center": list(chrome.centre), "radius": chrome.radius,
                   "bsdf": {"type": "conductor", "material": "Cr"}},
        "gray": {"type": "sphere", "center": list(gray.centre), "radius": gray.radius,
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [GRAY_ALBEDO] * 3}}},
        "light": {"type": "sphere", "center": light_centre.tolist(), "radius": light_radius,
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [radiance] * 3}}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [SKY_RADIANCE] * 3}},
    }
    if scene.clutter or scene.window is not None:
        ground_y = min(chrome.c[1] - chrome.radius, gray.c[1] - gray.radius) - 0.3
        d["ground"] = {"type": "rectangle",
                       "to_world": t().translate([0.0, ground_y, 0.0]) @ t().rotate([1, 0, 0], -90)
                       @ t().scale([500.0, 500.0, 1.0]),
                       "bsdf": {"type": "diffuse", "reflectance": {
                           "type": "checkerboard", "color0": {"type": "rgb", "value": [GROUND_ALBEDO] * 3},
                           "color1": {"type": "rgb", "value": [GROUND_ALBEDO * 0.4] * 3},
                           "to_uv": t().scale([400.0, 400.0, 1.0])}}}
    for i, (kind, centre, size, rgb) in enumerate(scene.clutter):
        if kind == "cube":
            to_world = t().translate(list(centre)) @ t().rotate([0, 1, 0], 37.0 * i) @ t().scale([size] * 3)
        else:   # a vertical cylinder of radius 0.6 size and height 2 size
            to_world = (t().translate(list(centre)) @ t().rotate([1, 0, 0], 90)
                        @ t().scale([size * 0.6, size * 0.6, 2 * size]) @ t().translate([0, 0, -0.5]))
        d[f"clutter{i}"] = {"type": kind, "to_world": to_world,
                            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(rgb)}}}
    if scene.window is not None:
        centre, normal, size = scene.window
        d["window"] = {"type": "rectangle",
                       "to_world": t().look_at(origin=list(centre),
                                               target=(np.asarray(centre) + np.asarray(normal)).tolist(),
                                               up=[0, 1, 0]) @ t().scale([size, size * 0.7, 1.0]),
                       "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [WINDOW_RADIANCE] * 3}}}
    return d


def remove_fireflies(image: np.ndarray, ratio: float = FIREFLY_RATIO) -> np.ndarray:
    """Replace isolated path-tracing outliers (a pixel ``ratio`` times brighter than every
    one of its 8 neighbours) by their neighbours' median; blobs of 2+ pixels stay.

    Caustic paths (diffuse surface, chrome sphere, light) cannot be sampled toward the
    light, so a few such pixels remain at any practical sample count; a camera has none.
    """
    from scipy import ndimage
    img = np.asarray(image, np.float32)
    lum = img.mean(-1)
    footprint = np.ones((3, 3), bool)
    footprint[1, 1] = False
    neighbour_max = ndimage.maximum_filter(lum, footprint=footprint, mode="nearest")
    bad = lum > ratio * neighbour_max + 1e-3
    if not bad.any():
        return img
    out = img.copy()
    for c in range(img.shape[2]):
        med = ndimage.median_filter(img[..., c], footprint=footprint, mode="nearest")
        out[..., c] = np.where(bad, med, img[..., c])
    return out


def render_probe_scene(scene: ProbeScene, spp: int = 64, seed: int = 0) -> np.ndarray:
    """Linear RGB ``(height, width, 3)`` float32 render of a validation scene, with
    isolated fireflies removed (:func:`remove_fireflies`)."""
    mi = backend.mitsuba()
    loaded = mi.load_dict(_scene_dict(scene, spp))
    image = render.render_scene(loaded, spp, seed)[..., :3]
    return remove_fireflies(image)


# --------------------------------------------------------------------------- the harder set: rooms
# A chrome and a gray sphere of 10-40 px radius resting on the textured floor of a
# relight room (walls, clutter objects from the generator's shape families, a coloured
# diffuse ball: another ball in view), lit by a small spherical light inside the room,
# so floor and walls near the light are bright and their grazing reflections clip in
# 8-bit. One JSON file (``relight.probe-scene/v1``) holds the room as a relight scene file
# (``"scene"``, built for Cycles by :func:`relight.scene.blender.export_blender`) plus the
# spheres and the light; Mitsuba and Cycles render the same file. This module's room
# part imports only numpy and relight's numpy-only parts at module level, so that it
# runs in the bpy environment.

PROBE_SCENE_FORMAT = "relight.probe-scene/v1"
ROOM_RES_CHOICES = (128, 256, 256, 384, 512)
ROOM_RADIUS_PX = (10.0, 40.0)        # chrome sphere radius in pixels (at most ROOM_MAX_RADIUS_SHARE of the image side)
ROOM_MAX_RADIUS_SHARE = 0.15         # a larger chrome sphere leaves no room beside it for the gray one and the ball
ROOM_FOV_DEG = (20.0, 60.0)
ROOM_LIGHT_ANGULAR_RADIUS_DEG = (2.0, 4.0)   # the light as seen from the chrome sphere (a 3-25 cm lamp)
ROOM_IRRADIANCE = (3.0, 6.0)         # W/m^2 from the light at the chrome sphere
CHROME_REFLECTANCE = 0.6             # a perfect mirror times this (Cr is 0.55-0.65)
ROOM_SPP = 64
ROOM_MAX_VIEW_LIGHT_ANGLE_DEG = 120.0   # back light: beyond this, a 10 px sphere's highlight lies within a pixel of its rim
ROOM_SKY_RADIANCE = 0.06             # a dim constant sky above the open room (fill light)


def _ray_floor(origin, direction, height: float):
    """Point where a world ray meets the plane z = ``height`` (None if it does not)."""
    if direction[2] >= -1e-6:
        return None
    t = (height - origin[2]) / direction[2]
    return origin + t * direction if t > 0 else None


def _pixel_ray_world(cam_spec, res: int, x: float, y: float) -> np.ndarray:
    from relight import frames
    f = 0.5 * res / math.tan(math.radians(cam_spec.fov_deg) / 2.0)
    d_cam = np.array([x - res / 2.0, -(y - res / 2.0), -f])
    d = frames.camera_to_world_vector(d_cam / np.linalg.norm(d_cam), cam_spec.tilt_deg, cam_spec.pan_deg)
    return np.asarray(d, np.float64)


def _project_world(cam_spec, res: int, p) -> tuple[np.ndarray, float]:
    """Pixel (x, y) of a world point and its distance from the camera."""
    from relight import frames
    q = frames.world_to_camera(np.asarray(p, np.float64) - cam_spec.position_m, cam_spec.tilt_deg,
                               cam_spec.pan_deg)
    f = 0.5 * res / math.tan(math.radians(cam_spec.fov_deg) / 2.0)
    return np.array([res / 2.0 + f * q[0] / -q[2], res / 2.0 - f * q[1] / -q[2]]), float(np.linalg.norm(q))


def _place_ball(rng, cam_spec, res: int, radius_px: float, taken: list, lower: float = 0.35):
    """A ball resting on the floor whose image has about ``radius_px`` pixels radius,
    clear of the image border and of ``taken`` image circles: ``(centre_m, radius_m)``."""
    f = 0.5 * res / math.tan(math.radians(cam_spec.fov_deg) / 2.0)
    origin = cam_spec.position_m
    margin = radius_px * 1.4 + 3
    for _ in range(400):
        x = rng.uniform(margin, res - margin)
        y = rng.uniform(max(margin, lower * res), res - margin)
        d = _pixel_ray_world(cam_spec, res, x, y)
        radius = 0.1
        centre = None
        for _it in range(6):   # the ray meets the plane of centres z = R; R follows the distance
            p = _ray_floor(origin, d, radius)
            if p is None:
                break
            dist = float(np.linalg.norm(p - origin))
            radius = dist * math.sin(math.atan(radius_px / f))
            centre = p
        if centre is None or not 0.02 < radius < 2.0:
            continue
        xy, _ = _project_world(cam_spec, res, centre)
        if any(math.hypot(xy[0] - tx, xy[1] - ty) < (radius_px + tr) * 1.25 + 4 for tx, ty, tr in taken):
            continue
        taken.append((float(xy[0]), float(xy[1]), radius_px))
        return centre, radius
    return None


def _blocked(a, b, blockers) -> bool:
    """Whether the segment from ``a`` to ``b`` passes through a blocker: ``(centre,
    radius, 0)`` a ball, ``(foot, radius, height)`` a vertical cylinder standing at
    ``foot`` (a clutter object's bounds)."""
    t = np.linspace(0.0, 1.0, 400)[:, None]
    pts = np.asarray(a, np.float64) + t * (np.asarray(b, np.float64) - np.asarray(a, np.float64))
    for centre, radius, height in blockers:
        c = np.asarray(centre, np.float64)
        if height == 0.0:
            if (np.linalg.norm(pts - c, axis=1) < radius * 1.02).any():
                return True
        elif ((np.hypot(pts[:, 0] - c[0], pts[:, 1] - c[1]) < radius) & (pts[:, 2] < height)).any():
            return True
    return False


def specular_point(centre, radius: float, eye, light) -> np.ndarray:
    """The point of a mirror sphere where ``light`` (a point) reflects toward ``eye``: the
    normal there bisects the unit directions to both (fixed point iteration, then Newton-free
    refinement; converges for a sphere small against both distances)."""
    c, e, l = (np.asarray(v, np.float64) for v in (centre, eye, light))
    n = (e - c) / np.linalg.norm(e - c) + (l - c) / np.linalg.norm(l - c)
    n /= np.linalg.norm(n)
    for _ in range(200):
        p = c + radius * n
        n_new = (e - p) / np.linalg.norm(e - p) + (l - p) / np.linalg.norm(l - p)
        n_new /= np.linalg.norm(n_new)
        if np.linalg.norm(n_new - n) < 1e-15:
            break
        n = n_new
    return c + radius * n


def check_chrome_radius(chrome_radius_px, res: int | None = None) -> None:
    """Raise ``ValueError`` (one line) unless ``chrome_radius_px`` (``(lo, hi)`` pixels, or
    None) has ``0 < lo <= hi`` and ``hi`` at most :data:`ROOM_MAX_RADIUS_SHARE` of the image
    side ``res`` (of the smallest drawn side, :data:`ROOM_RES_CHOICES`, if None): a larger
    chrome sphere leaves no room beside it for the other two."""
    if chrome_radius_px is None:
        return
    lo, hi = chrome_radius_px
    if not 0 < lo <= hi:
        raise ValueError(f"a chrome radius range must be LO-HI with 0 < LO <= HI, got {lo:g}-{hi:g}")
    side = res or min(ROOM_RES_CHOICES)
    if hi > ROOM_MAX_RADIUS_SHARE * side:
        raise ValueError(f"a chrome radius of {hi:g} px is more than {100 * ROOM_MAX_RADIUS_SHARE:g}% of the image "
                         f"side ({side} px): the spheres would not fit beside each other")


def sample_room_scene(seed: int, res: int | None = None, fov_deg: float | None = None,
                      chrome_radius_px: tuple[float, float] | None = None) -> dict:
    """A random probe scene of the harder set (a ``relight.probe-scene/v1`` dict, with
    its truth): image ``res`` (square; random among :data:`ROOM_RES_CHOICES` if None),
    field of view ``fov_deg`` (uniform in :data:`ROOM_FOV_DEG` if None), chrome sphere
    radius uniform in ``chrome_radius_px`` (``(lo, hi)`` pixels, ``hi`` at most
    :data:`ROOM_MAX_RADIUS_SHARE` of the image side, of the smallest drawn side if ``res``
    is None; :data:`ROOM_RADIUS_PX` within that if None). With all three None a seed gives
    the scene it always gave. A draw whose spheres or light cannot be placed is drawn
    again (another stream)."""
    check_chrome_radius(chrome_radius_px, res)
    for attempt in range(50):
        try:
            return _sample_room_scene(np.random.default_rng([10_000 + seed, attempt]), seed, res, fov_deg,
                                      chrome_radius_px)
        except _Unplaceable:
            continue
    raise RuntimeError(f"probe scene {seed}: could not place the spheres")


class _Unplaceable(Exception):
    pass


def _sample_room_scene(rng, seed: int, res: int | None, fov_deg: float | None = None,
                       chrome_radius_px: tuple[float, float] | None = None) -> dict:
    from relight import frames
    from relight.scene import albedo, shapes, textures
    from relight.scene.spec import CameraSpec, LightSpec, ObjectSpec, RenderSpec, RoomSpec, SceneSpec
    res = int(res or rng.choice(ROOM_RES_CHOICES))
    fov = float(np.round(rng.uniform(*ROOM_FOV_DEG), 2) if fov_deg is None else fov_deg)
    cam = CameraSpec(tilt_deg=float(np.round(rng.uniform(10.0, 35.0), 2)),
                     r_m=float(np.round(rng.uniform(3.0, 7.0), 3)), pan_deg=0.0, fov_deg=fov)
    lo, hi = chrome_radius_px or (ROOM_RADIUS_PX[0], min(ROOM_RADIUS_PX[1], ROOM_MAX_RADIUS_SHARE * res))
    r_px = float(rng.uniform(lo, hi))
    taken: list = []
    chrome = _place_ball(rng, cam, res, r_px, taken)
    gray = _place_ball(rng, cam, res, r_px * rng.uniform(0.8, 1.25), taken)
    ball = _place_ball(rng, cam, res, r_px * rng.uniform(0.7, 1.4), taken, lower=0.2)
    if chrome is None or gray is None or ball is None:
        raise _Unplaceable
    prior = "hsv"
    inradius = float(cam.r_m * math.cos(math.radians(cam.tilt_deg)) + rng.uniform(1.5, 4.0))
    n_walls = int(rng.integers(4, 7))
    room = RoomSpec(n_walls=n_walls, inradius_m=round(inradius, 3), height_m=3.0,
                    rotation_deg=float(np.round(rng.uniform(0, 360.0 / n_walls), 3)),
                    wall_textures=tuple(textures.sample_texture_params(rng, None, prior) for _ in range(n_walls)),
                    floor_texture=textures.sample_texture_params(rng, None, prior), texture_res=128)
    objects = []
    for _ in range(int(rng.integers(2, 4))):
        placed = _place_ball(rng, cam, res, r_px * rng.uniform(1.0, 2.0), taken, lower=0.15)
        if placed is None:
            continue
        (px, py, _), size = placed[0], placed[1]
        family = str(shapes.FAMILIES[int(rng.integers(0, len(shapes.FAMILIES)))])
        objects.append(ObjectSpec(family=family, params=shapes.sample_shape_params(family, rng),
                                  position_m=(float(px), float(py)), yaw_deg=float(rng.uniform(0, 360)),
                                  size_m=float(size), reflectance=albedo.object_reflectance(rng, prior),
                                  roughness=0.0))
    # the light: above the floor, inside the room, 1-3.5 m from the chrome sphere
    c_centre, c_radius = chrome
    eye = cam.position_m
    to_cam = (eye - c_centre) / np.linalg.norm(eye - c_centre)
    front = bool(seed % 2 == 0)
    for _ in range(5000):
        el = math.radians(rng.uniform(10.0, 75.0))
        az = rng.uniform(0, 2 * math.pi)
        l = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        cos_v = float(l @ to_cam)
        if (cos_v > 0) != front or math.degrees(math.acos(cos_v)) > ROOM_MAX_VIEW_LIGHT_ANGLE_DEG:
            continue
        dist = rng.uniform(1.0, 3.5)
        pos = c_centre + dist * l
        if np.linalg.norm(pos[:2]) > inradius * math.cos(math.pi / n_walls) - 0.3 or pos[2] > 2.8:
            continue
        break
    else:
        raise _Unplaceable
    spot = specular_point(c_centre, c_radius, eye, pos)
    blockers = [(gray[0], gray[1], 0.0), (ball[0], ball[1], 0.0)] + [
        (np.array([o.position_m[0], o.position_m[1], 0.0]), o.size_m * 1.15, o.size_m * 3.0) for o in objects]
    if _blocked(spot, pos, blockers) or _blocked(eye, spot, blockers):
        raise _Unplaceable     # the light's reflection would be hidden: no truth to measure
    ang = math.radians(rng.uniform(*ROOM_LIGHT_ANGULAR_RADIUS_DEG))
    light_radius = float(dist * math.tan(ang))
    power = float(rng.uniform(*ROOM_IRRADIANCE) * 4 * math.pi * dist ** 2)
    # the room's point light stays off (strength tiny); the probe light replaces it
    light = LightSpec(r_m=1.0, pan_deg=0.0, tilt_deg=45.0, rgb=(1.0, 1.0, 1.0), strength=1e-9)
    spec = SceneSpec(id=f"probe{seed:03d}", camera=cam, light=light, room=room, objects=tuple(objects),
                     render=RenderSpec(res=res, spp=ROOM_SPP, max_depth=5, seed=seed))
    to_light_world = (pos - spot) / np.linalg.norm(pos - spot)
    to_light = frames.world_to_camera(to_light_world, cam.tilt_deg, cam.pan_deg)
    centre_dir = frames.world_to_camera((pos - c_centre) / np.linalg.norm(pos - c_centre), cam.tilt_deg,
                                        cam.pan_deg)
    ball_rgb = tuple(float(v) for v in rng.uniform(0.1, 0.8, 3))
    d = {"format": PROBE_SCENE_FORMAT, "id": spec.id, "scene": spec.to_dict(),
         "chrome": {"centre_m": c_centre.tolist(), "radius_m": float(c_radius), "reflectance": CHROME_REFLECTANCE},
         "gray": {"centre_m": gray[0].tolist(), "radius_m": float(gray[1]), "albedo": GRAY_ALBEDO},
         "balls": [{"centre_m": ball[0].tolist(), "radius_m": float(ball[1]), "albedo": list(ball_rgb)}],
         "light": {"position_m": pos.tolist(), "radius_m": light_radius, "power_w": power},
         "sky_radiance": ROOM_SKY_RADIANCE}
    d["truth"] = {"to_light_camera": [float(v) for v in to_light],
                  "to_light_from_centre_camera": [float(v) for v in centre_dir],
                  "front": front, "fov_deg": fov, "res": res,
                  "chrome_circle": list(room_circle(d, "chrome")), "gray_circle": list(room_circle(d, "gray")),
                  "ball_circles": [list(room_circle(d, "balls", 0))]}
    return d


def room_sphere_camera(d: dict, which: str, index: int = 0):
    """``(centre, radius)`` of a sphere of a probe-scene dict in the camera frame (metres)."""
    from relight import frames
    from relight.scene.spec import CameraSpec
    cam = CameraSpec(**d["scene"]["camera"])
    s = d[which][index] if which == "balls" else d[which]
    c = frames.world_to_camera(np.asarray(s["centre_m"]) - cam.position_m, cam.tilt_deg, cam.pan_deg)
    return np.asarray(c, np.float64), float(s["radius_m"])


def room_circle(d: dict, which: str, index: int = 0) -> tuple[float, float, float]:
    """The circle closest to a sphere's image outline in a probe-scene dict."""
    from relight.probe.geometry import Camera, Sphere, outline_circle
    c, r = room_sphere_camera(d, which, index)
    res = d["scene"]["render"]["res"]
    camera = Camera.from_fov(res, res, d["scene"]["camera"]["fov_deg"])
    n = float(np.linalg.norm(c))
    return tuple(float(v) for v in outline_circle(camera, Sphere(tuple((c / n).tolist()), r / n)))


def room_sphere(d: dict, which: str):
    """The true :class:`relight.probe.geometry.Sphere` (unit-distance scale) of a probe scene."""
    from relight.probe.geometry import Sphere
    c, r = room_sphere_camera(d, which)
    n = float(np.linalg.norm(c))
    return Sphere(tuple((c / n).tolist()), r / n)


def _probe_spheres(d: dict):
    """``(name, centre, radius, kind, rgb)`` of each sphere a probe scene adds to the room."""
    out = [("chrome", d["chrome"]["centre_m"], d["chrome"]["radius_m"], "mirror",
            [d["chrome"]["reflectance"]] * 3),
           ("gray", d["gray"]["centre_m"], d["gray"]["radius_m"], "diffuse", [d["gray"]["albedo"]] * 3)]
    for i, b in enumerate(d.get("balls", [])):
        out.append((f"ball{i}", b["centre_m"], b["radius_m"], "diffuse", b["albedo"]))
    return out


def render_room_mitsuba(d: dict, spp: int | None = None) -> np.ndarray:
    """Mitsuba render (linear RGB, float32) of a probe-scene dict: the room as
    :mod:`relight.scene.build` makes it (objects Lambert), plus the spheres and the
    spherical light and a dim constant sky (the room has no ceiling)."""
    from relight import frames
    from relight.scene import build
    from relight.scene.spec import SceneSpec
    mi = backend.mitsuba()
    t = mi.ScalarTransform4f
    spec = SceneSpec.from_dict(d["scene"])
    cam, room = spec.camera, spec.room

    def bitmap(params, to_uv=None):
        b = {"type": "bitmap", "data": mi.TensorXf(build.texture(params, room.texture_res)), "raw": True,
             "filter_type": "bilinear", "wrap_mode": "repeat"}
        if to_uv is not None:
            b["to_uv"] = to_uv
        return b

    scene = {"type": "scene", "integrator": {"type": "path", "max_depth": spec.render.max_depth},
             "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [d["sky_radiance"]] * 3}},
             "sensor": render.sensor(spec.render.res, cam.fov_deg, to_world=t(
                 frames.mitsuba_sensor_to_world(cam.tilt_deg, cam.r_m, cam.pan_deg))),
             "floor": {"type": "rectangle",
                       "to_world": t().scale([build.FLOOR_HALF_SIZE_M, build.FLOOR_HALF_SIZE_M, 1.0]),
                       "bsdf": {"type": "diffuse", "reflectance": bitmap(room.floor_texture, mi.ScalarTransform3f()
                                .scale(2.0 * build.FLOOR_HALF_SIZE_M / build.FLOOR_TILE_M))}}}
    for k in range(room.n_walls):
        scene[f"wall{k}"] = {"type": "rectangle", "to_world": t(build.wall_to_world(
            k, room.n_walls, room.inradius_m, room.height_m, room.rotation_deg)),
            "bsdf": {"type": "diffuse", "reflectance": bitmap(room.wall_textures[k])}}
    for i, obj in enumerate(spec.objects):
        mesh = build.object_mesh(obj)
        v, n = build._object_vertices(obj, mesh)
        m = mi.Mesh(f"obj{i}", len(v), len(mesh.faces), has_vertex_normals=True)
        p = mi.traverse(m)
        p["vertex_positions"] = mi.Float(v.ravel())
        p["vertex_normals"] = mi.Float(n.ravel())
        p["faces"] = mi.UInt32(mesh.faces.astype(np.uint32).ravel())
        p.update()
        m.set_bsdf(mi.load_dict({"type": "diffuse", "reflectance": {"type": "rgb", "value": list(obj.reflectance)}}))
        scene[f"obj{i}"] = m
    for name, centre, radius, kind, rgb in _probe_spheres(d):
        bsdf = ({"type": "conductor", "material": "none", "specular_reflectance": {"type": "rgb", "value": rgb}}
                if kind == "mirror" else {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(rgb)}})
        scene[name] = {"type": "sphere", "center": list(centre), "radius": radius, "bsdf": bsdf}
    lt = d["light"]
    radiance = lt["power_w"] / (4 * math.pi ** 2 * lt["radius_m"] ** 2)
    scene["probe_light"] = {"type": "sphere", "center": lt["position_m"], "radius": lt["radius_m"],
                            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [radiance] * 3}}}
    loaded = mi.load_dict(scene)
    # no firefly removal: a highlight of one pixel is what a small sphere shows
    return render.render_scene(loaded, spp or spec.render.spp, spec.render.seed)[..., :3]


CYCLES_PIXEL_FILTERS = {"box": ("BOX", 1.0), "blackman-harris": ("BLACKMAN_HARRIS", 1.5)}   # name: (Cycles' filter, width px)


def render_room_cycles(d: dict, spp: int | None = None, threads: int | None = 1,
                       pixel_filter: str = "box") -> np.ndarray:
    """Cycles render (linear RGB, float32) of a probe-scene dict, in the bpy environment:
    the room by :func:`relight.scene.blender.export_blender`, then the spheres (Cycles point
    clouds, which it renders as exact spheres; the chrome one a Glossy BSDF of roughness
    0) and the light (a point light of the light's radius, so a sphere, seen in the
    mirror through multiple importance sampling), glossy bounces allowed. ``pixel_filter``
    (:data:`CYCLES_PIXEL_FILTERS`): a box one pixel wide, as Mitsuba's (export_blender's
    default), or Blackman-Harris 1.5 px, Blender's own default."""
    import tempfile

    import bpy

    from relight.scene import blender
    from relight.scene.spec import SceneSpec
    spec = SceneSpec.from_dict(d["scene"])
    scene = blender.export_blender(spec, spp=spp, threads=threads)
    c = scene.cycles
    c.pixel_filter_type, c.filter_width = CYCLES_PIXEL_FILTERS[pixel_filter]
    c.max_bounces = spec.render.max_depth
    c.diffuse_bounces = spec.render.max_depth - 2
    c.glossy_bounces = 2
    for name, centre, radius, kind, rgb in _probe_spheres(d):
        mat = bpy.data.materials.new(name)
        nt = mat.node_tree
        nt.nodes.clear()
        if kind == "mirror":
            bsdf = nt.nodes.new("ShaderNodeBsdfGlossy")
            bsdf.inputs["Roughness"].default_value = 0.0
        else:
            bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")
            bsdf.inputs["Roughness"].default_value = 0.0
        bsdf.inputs["Color"].default_value = (*[float(v) for v in rgb], 1.0)
        out = nt.nodes.new("ShaderNodeOutputMaterial")
        out.target = "CYCLES"
        nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
        me = bpy.data.meshes.new(name)
        me.from_pydata([tuple(float(v) for v in centre)], [], [])
        me.update()
        ob = bpy.data.objects.new(name, me)
        ng = bpy.data.node_groups.new(name + "_points", "GeometryNodeTree")
        ng.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
        ng.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
        gin, gout = ng.nodes.new("NodeGroupInput"), ng.nodes.new("NodeGroupOutput")
        pts = ng.nodes.new("GeometryNodeMeshToPoints")
        pts.inputs["Radius"].default_value = float(radius)
        setm = ng.nodes.new("GeometryNodeSetMaterial")
        setm.inputs["Material"].default_value = mat
        ng.links.new(gin.outputs[0], pts.inputs["Mesh"])
        ng.links.new(pts.outputs[0], setm.inputs["Geometry"])
        ng.links.new(setm.outputs[0], gout.inputs[0])
        ob.modifiers.new("points", "NODES").node_group = ng
        scene.collection.objects.link(ob)
    lt = d["light"]
    light = bpy.data.objects["light"]
    light.location = tuple(float(v) for v in lt["position_m"])
    light.data.energy = float(lt["power_w"])
    light.data.color = (1.0, 1.0, 1.0)
    light.data.shadow_soft_size = float(lt["radius_m"])
    light.data.cycles.use_multiple_importance_sampling = True
    world = scene.world.node_tree.nodes["Background"]
    world.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    world.inputs["Strength"].default_value = float(d["sky_radiance"])
    with tempfile.TemporaryDirectory(prefix="relight-probe-") as tmp:
        out = os.path.join(tmp, "render.exr")
        scene.render.filepath = out
        with blender._quiet_stdout():
            bpy.ops.render.render(write_still=True, scene=scene.name)
        img = bpy.data.images.load(out, check_existing=False)
        h, w = img.size[1], img.size[0]
        pixels = np.empty(h * w * img.channels, np.float32)
        img.pixels.foreach_get(pixels)
        image = pixels.reshape(h, w, img.channels)[::-1, :, :3].copy()
        bpy.data.images.remove(img)
    return image


def main(argv: list[str] | None = None) -> int:
    """``python -m relight.verify.probe_scenes cycles SCENE.json ...`` (in the bpy
    environment): render each probe scene with Cycles to ``SCENE.cycles.exr`` beside it,
    skipping those already there."""
    import argparse
    import json
    import sys
    ap = argparse.ArgumentParser(prog="python -m relight.verify.probe_scenes")
    ap.add_argument("what", choices=["cycles"])
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--spp", type=int, default=None)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--pixel-filter", choices=sorted(CYCLES_PIXEL_FILTERS), default="box")
    args = ap.parse_args(argv)
    from relight.children import die_with_parent
    from relight.fileio import atomic_write
    die_with_parent()      # started by bench_probe.py: ends with it
    for path in args.scenes:
        out = path[:-len(".json")] + ".cycles.exr"
        if os.path.exists(out):
            continue
        with open(path) as f:
            d = json.load(f)
        image = render_room_cycles(d, spp=args.spp, threads=args.threads, pixel_filter=args.pixel_filter)

        def save(tmp, image=image):
            with open(tmp, "wb") as f:
                np.save(f, image)
        atomic_write(out[:-4] + ".npy", save)
        sys.stdout.write(f"{out[:-4]}.npy\n")
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

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
]

import math
from dataclasses import dataclass

import numpy as np

from relight import backend, render
from relight.probe.geometry import Camera, Sphere, outline_circle

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
        return Camera.from_fov(self.width, self.height, self.fov_deg)

    def circle(self, which: str = "chrome") -> tuple[float, float, float]:
        """The circle closest to a sphere's image outline (what a person would mark)."""
        return outline_circle(self.camera, getattr(self, which))

    def truth(self) -> dict:
        return {"to_light_camera": list(self.to_light), "front": self.front, "fov_deg": self.fov_deg,
                "chrome_circle": list(self.circle("chrome")), "gray_circle": list(self.circle("gray"))}


def _place_sphere(rng, camera: Camera, radius_px: float, taken: list) -> Sphere | None:
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

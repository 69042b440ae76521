"""MID-like scenes (the paper's Experiment 2 on synthetic data whose light is known).

The Multi-Illumination dataset (Murmann et al. 2019) photographs indoor scenes with a
chrome and a gray sphere in view while a flash mounted just above the camera is turned
to a fixed set of directions, mostly at walls and ceiling, so that much of the light
reaching the scene has bounced. This module samples and renders such scenes:

* **Room** (world frame of the conventions: +Z up, floor z = 0): a box of
  :data:`ROOM_HALF_M` half-widths and :data:`CEILING_M` height, walls and ceiling of
  random pale colours, a darker floor.
* **Camera**: near the +X wall at :data:`CAMERA_HEIGHT_M`, pan 0 (looking along -X, so
  its right-hand side is +Y as in the conventions), pitched down by its tilt
  (:data:`CAMERA_TILT_DEG`), so ``relight.frames.camera_basis(tilt)`` is its frame.
* **Clutter**: 3-6 procedural objects of :mod:`relight.scene.shapes` on the floor in view.
* **Probes**: a chrome and a gray (albedo :data:`GRAY_ALBEDO`) sphere resting on the
  floor at random places in view, of :data:`SPHERE_RADIUS_FRACTION` of the image width
  in radius, never hidden by clutter.
* **Flash**: a disk emitter of radius :data:`FLASH_RADIUS_M` (Lambertian, one-sided: no
  light behind it) of one colour in every room (:data:`FLASH_CCT_K`, on the Planckian
  locus), :data:`FLASH_OFFSET_M` above the camera, turned to the 25 directions of
  :data:`FLASH_DIRECTIONS` relative to the camera (yaw to the camera's right, elevation
  above the horizon), plus the *reference* pose (the flash along the camera's optical
  axis, the paper's reference image). ``MidConfig.snoot_m`` > 0 puts it in a black tube
  of that length (0.12 m: no direct light beyond ~40 deg off its axis); the default is
  a bare flash.
* **Rendering**: the image by light tracing (Mitsuba ``ptracer``, ``spp`` light paths a
  pixel: a room lit by a flash bouncing off walls is what it does well, where a path
  tracer stays noisy at hundreds of samples), except the chrome sphere, which light
  tracing cannot see: its pixels are the path-traced probe photograph averaged down.
  The probe photograph (what the sphere procedure measures) is rendered at
  ``probe_zoom`` x the resolution, only around the two spheres.

**Physical ground truth** (:func:`physical_truth`): the incident radiance ``L(w)`` at a
sphere's centre in the scene *without the two spheres* is the flash seen directly
(closed form: its radiance times the disk's projected solid angle, if not occluded)
plus everything else (a cube map of :data:`CUBE_RES` pixels a face rendered there with
emitters hidden). The **dominant direction** is the centre of the brightest cap of
:data:`CAP_DEG` radius: the cap maximising the luminance integral ``int_cap L dw``,
refined as the radiance-weighted mean direction inside it. The light's **colour** is
the irradiance-weighted colour ``int L dw`` over all directions at the gray sphere's
centre (unit norm). Both are the light *arriving at the spheres*, which after bounces
is not the flash's direction.
"""
from __future__ import annotations

__all__ = [
    "ROOM_HALF_M", "CEILING_M", "CAMERA_HEIGHT_M", "CAMERA_TILT_DEG", "CAMERA_WALL_GAP_M", "FOV_DEG",
    "GRAY_ALBEDO", "SPHERE_RADIUS_FRACTION", "SPHERE_DISTANCE_M", "FLASH_OFFSET_M", "FLASH_RADIUS_M",
    "SNOOT_LENGTH_M", "SNOOT_RADIUS_M", "FLASH_CCT_K", "FLASH_INTENSITY_W_SR", "CUBE_RES", "CAP_DEG",
    "EXPOSURE_KEY", "REFERENCE", "FLASH_DIRECTIONS", "MidConfig", "split_of_scene", "MidScene", "flash_axis",
    "reference_axis", "camera_camera_frame", "probe_camera", "probe_sphere", "sample_mid_scene",
    "flash_radiance", "backend_mi", "CUBE_AXES", "cube_directions", "MidRenderer", "circle_overlap",
    "dominant_direction", "physical_truth",
]

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from relight import frames
from relight.colour import luminance
from relight.errors import ConfigError

ROOM_HALF_M = (2.0, 3.5)           # half-widths of the room along x and y
CEILING_M = (2.4, 3.2)
CAMERA_HEIGHT_M = (1.2, 1.7)
CAMERA_TILT_DEG = (12.0, 30.0)     # pitched down (the conventions' camera tilt)
CAMERA_WALL_GAP_M = 0.6            # camera distance from the +X wall
FOV_DEG = 55.0
GRAY_ALBEDO = 0.5
SPHERE_RADIUS_FRACTION = (0.07, 0.1)   # sphere outline radius / image width
SPHERE_DISTANCE_M = (1.2, 3.2)
FLASH_OFFSET_M = 0.12              # flash centre above the camera centre
FLASH_RADIUS_M = 0.05              # a flash with a diffuser: visible as a glint in the chrome sphere
SNOOT_LENGTH_M = 0.12               # MidConfig.snoot_m: 0.12 gives no direct light beyond ~40 deg
SNOOT_RADIUS_M = 1.05 * FLASH_RADIUS_M
FLASH_CCT_K = 5500.0               # MidConfig.flash_cct_k: one white flash for every room
FLASH_INTENSITY_W_SR = 20.0        # on-axis radiant intensity (radiance x disk area)
CUBE_RES = 64                      # within a median 0.5 deg of 128 a face (16: 1.6, 32: 1.1 deg)
CAP_DEG = 10.0
EXPOSURE_KEY = 0.18                # PNGs: the median luminance is exposed to 0.18 (auto exposure)
REFERENCE = "ref"

# 25 flash directions relative to the camera: (yaw to the camera's right, elevation),
# degrees; yaw 0 is the camera's horizontal viewing direction. 8 yaws at 10, 40 and 70
# degrees of elevation, and straight up.
FLASH_DIRECTIONS: tuple[tuple[float, float], ...] = tuple(
    (float(yaw), float(el)) for el in (10.0, 40.0, 70.0) for yaw in range(0, 360, 45)) + ((0.0, 90.0),)


@dataclass(frozen=True)
class MidConfig:
    """Settings of a MID-like dataset (written to its card).

    ``res`` image size (pixels), ``spp`` light paths a pixel of the image, ``max_depth``
    path length, ``cube_res``/``cube_spp`` the physical truth's cube maps, ``probe_zoom``
    the probe photograph's magnification with ``probe_spp`` (chrome) and ``probe_gray_spp``
    samples a pixel, ``snoot_m`` the flash's snoot length (0: bare), ``n_clutter`` the
    range of clutter objects. ``flash_cct_k``: the flash's colour temperature, the same
    in every room, as MID's photographs all come from one flash (``None``: each room
    draws 5000-6500 K, the first sets' setting). ``directions``: indices into :data:`FLASH_DIRECTIONS`
    rendered per scene (all 25 by default; tests use a few). Splits are per scene: scene ``i`` is ``test`` when
    ``i % 5 == 4``, ``val`` when ``i % 10 == 2``, else ``train``.
    """
    res: int = 96
    spp: int = 64             # light paths per pixel of the image (Mitsuba ptracer)
    max_depth: int = 5
    fov_deg: float = FOV_DEG
    cube_res: int = CUBE_RES
    cube_spp: int = 8
    probe_zoom: int = 3
    snoot_m: float = 0.0
    probe_spp: int = 16
    probe_gray_spp: int = 4
    directions: tuple[int, ...] = tuple(range(len(FLASH_DIRECTIONS)))
    n_clutter: tuple[int, int] = (3, 6)
    flash_cct_k: float | None = FLASH_CCT_K

    def __post_init__(self):
        object.__setattr__(self, "directions", tuple(int(i) for i in self.directions))
        object.__setattr__(self, "n_clutter", tuple(int(i) for i in self.n_clutter))
        if not 16 <= int(self.res) <= 1024 or int(self.spp) < 1 or int(self.max_depth) < 2:
            raise ConfigError(f"mid preset: res must be in [16, 1024], spp >= 1, max_depth >= 2 "
                              f"(got {self.res}, {self.spp}, {self.max_depth})")
        if not self.directions or any(not 0 <= i < len(FLASH_DIRECTIONS) for i in self.directions) \
                or len(set(self.directions)) != len(self.directions):
            raise ConfigError(f"mid preset: directions must be distinct indices in [0, {len(FLASH_DIRECTIONS)})")
        if not 20.0 <= float(self.fov_deg) <= 90.0 or int(self.cube_res) < 4 or int(self.cube_spp) < 1:
            raise ConfigError("mid preset: fov_deg in [20, 90], cube_res >= 4, cube_spp >= 1")
        if self.flash_cct_k is not None and not 2000.0 <= float(self.flash_cct_k) <= 20000.0:
            raise ConfigError(f"mid preset: flash_cct_k must be in [2000, 20000] K or null, got {self.flash_cct_k!r}")

    def to_dict(self) -> dict:
        d = asdict(self)
        d["directions"], d["n_clutter"] = list(self.directions), list(self.n_clutter)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "MidConfig":
        known = {k: v for k, v in d.items() if k in cls.__dataclass_fields__}
        unknown = sorted(set(d) - set(known))
        if unknown:
            raise ConfigError(f"mid preset: unknown setting {unknown[0]!r}")
        return cls(**known)


def split_of_scene(index: int) -> str:
    """Scene-level split (no scene in two splits).

    >>> [split_of_scene(i) for i in range(5)]
    ['train', 'train', 'val', 'train', 'test']
    """
    if index % 5 == 4:
        return "test"
    return "val" if index % 10 == 2 else "train"


@dataclass
class MidScene:
    """One sampled room (world frame, metres)."""
    index: int
    seed: int
    room_half: tuple[float, float]
    ceiling_m: float
    camera_position: np.ndarray
    camera_tilt_deg: float
    wall_rgb: list            # +x, -x, +y, -y walls, ceiling
    floor_rgb: list
    chrome_centre: np.ndarray
    gray_centre: np.ndarray
    sphere_radius: tuple[float, float]    # chrome, gray
    clutter: list = field(default_factory=list)   # (family, params, position, scale, rotation_deg, rgb)
    flash_rgb: tuple = (1.0, 1.0, 1.0)
    flash_cct_k: float = 6500.0

    @property
    def flash_position(self) -> np.ndarray:
        return self.camera_position + np.array([0.0, 0.0, FLASH_OFFSET_M])

    def to_dict(self) -> dict:
        def conv(v):
            if isinstance(v, np.ndarray):
                return v.tolist()
            if isinstance(v, (list, tuple)):
                return [conv(x) for x in v]
            return v
        return {k: conv(v) for k, v in asdict(self).items()}


def flash_axis(yaw_deg: float, elevation_deg: float) -> np.ndarray:
    """World unit vector of a flash direction relative to the camera (camera at pan 0
    looks along -X; yaw 90 is the camera's right, +Y).

    >>> (np.round(flash_axis(90.0, 0.0), 9) + 0.0).tolist(), (np.round(flash_axis(0.0, 90.0), 9) + 0.0).tolist()
    ([0.0, 1.0, 0.0], [0.0, 0.0, 1.0])
    """
    # pan of the world direction: camera looks toward pan 180; its right (+Y) is pan 90
    return frames.direction(180.0 - yaw_deg, elevation_deg)


def reference_axis(camera_tilt_deg: float) -> np.ndarray:
    """The reference pose: the flash along the camera's optical axis."""
    return frames.camera_basis(camera_tilt_deg)[2]


def camera_camera_frame(scene: MidScene, p_world) -> np.ndarray:
    """World point(s) -> camera frame (x right, y up, z toward the camera), camera at origin."""
    return frames.world_to_camera(np.asarray(p_world, np.float64) - scene.camera_position, scene.camera_tilt_deg)


def probe_camera(cfg: MidConfig, zoom: int = 1):
    """The scene camera at ``zoom`` x the image size (``cfg.probe_zoom``: the probe
    photograph's, whose pixels the procedure's circles are in)."""
    from relight.probe.geometry import Camera
    return Camera.from_fov(cfg.res * zoom, cfg.res * zoom, cfg.fov_deg)


def probe_sphere(scene: MidScene, which: str):
    """The ``which`` ("chrome"/"gray") sphere in the probe's camera frame."""
    from relight.probe.geometry import Sphere
    c = scene.chrome_centre if which == "chrome" else scene.gray_centre
    r = scene.sphere_radius[0 if which == "chrome" else 1]
    return Sphere(tuple(camera_camera_frame(scene, c).tolist()), float(r))


def sample_mid_scene(cfg: MidConfig, seed: int, index: int) -> MidScene:
    """Scene ``index`` of a dataset of seed ``seed`` (depends on nothing else)."""
    from relight.colour import cct_duv_to_rgb
    from relight.scene.shapes import FAMILIES, sample_shape_params
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(index), 0x4D4944]))
    hx, hy = (float(rng.uniform(*ROOM_HALF_M)) for _ in range(2))
    ceiling = float(rng.uniform(*CEILING_M))
    tilt = float(rng.uniform(*CAMERA_TILT_DEG))
    cam = np.array([hx - CAMERA_WALL_GAP_M, float(rng.uniform(-0.3, 0.3)) * hy, float(rng.uniform(*CAMERA_HEIGHT_M))])

    def pale():
        base = rng.uniform(0.45, 0.8)
        return np.clip(base * (1 + rng.uniform(-0.15, 0.15, 3)), 0.05, 0.9).tolist()
    walls = [pale() for _ in range(5)]
    floor = np.clip(rng.uniform(0.15, 0.45) * (1 + rng.uniform(-0.2, 0.2, 3)), 0.05, 0.9).tolist()
    cct = float(rng.uniform(5000.0, 6500.0))     # drawn in any case: the rooms stay the same
    if cfg.flash_cct_k is not None:
        cct = float(cfg.flash_cct_k)
    flash_rgb = tuple(float(v) for v in cct_duv_to_rgb(cct, 0.0))
    camera = probe_camera(cfg)
    f = camera.focal_px
    right, up, forward = frames.camera_basis(tilt)
    rot = np.stack([right, up, -forward])            # world -> camera rows

    def ray(px, py):
        d_cam = np.array([px - cfg.res / 2.0, -(py - cfg.res / 2.0), -f])
        d = rot.T @ d_cam
        return d / np.linalg.norm(d)

    def place(radius_px, taken):
        for _ in range(500):
            m = radius_px * 1.4 + 2
            px, py = rng.uniform(m, cfg.res - m), rng.uniform(max(m, cfg.res * 0.3), cfg.res - m)
            if any(math.hypot(px - x, py - y) < (radius_px + r) * 1.4 + 2 for x, y, r in taken):
                continue
            d = ray(px, py)
            # sphere resting on the floor: centre at z = R, R from the wanted image radius
            dist, radius = 2.0, 0.1
            for _it in range(4):
                radius = dist * math.sin(math.atan(radius_px / f))
                if d[2] >= -1e-3:
                    break
                t = (radius - cam[2]) / d[2]
                dist = t
            if d[2] >= -1e-3 or not SPHERE_DISTANCE_M[0] <= dist <= SPHERE_DISTANCE_M[1]:
                continue
            c = cam + dist * d
            if abs(c[0]) > hx - radius - 0.05 or abs(c[1]) > hy - radius - 0.05:
                continue
            taken.append((px, py, radius_px))
            return c, radius
        return None
    for _attempt in range(50):
        taken: list = []
        a = place(rng.uniform(*SPHERE_RADIUS_FRACTION) * cfg.res, taken)
        b = place(rng.uniform(*SPHERE_RADIUS_FRACTION) * cfg.res, taken) if a else None
        if a and b:
            break
    else:
        raise ConfigError(f"mid scene {index}: could not place the spheres in view")
    (chrome_c, chrome_r), (gray_c, gray_r) = a, b
    clutter = []
    n = int(rng.integers(cfg.n_clutter[0], cfg.n_clutter[1] + 1))
    for _ in range(n):
        for _try in range(60):
            px, py = rng.uniform(0, cfg.res), rng.uniform(cfg.res * 0.2, cfg.res)
            d = ray(px, py)
            if d[2] >= -1e-3:
                continue
            t = -cam[2] / d[2] * rng.uniform(1.0, 1.6)     # on the floor, at or behind the ray's floor point
            p = cam + t * d
            p[2] = 0.0
            scale = float(rng.uniform(0.12, 0.35))
            if abs(p[0]) > hx - scale - 0.05 or abs(p[1]) > hy - scale - 0.05:
                continue
            if any(np.linalg.norm(p[:2] - s[:2]) < scale + r + 0.15 for s, r in
                   ((chrome_c, chrome_r), (gray_c, gray_r))):
                continue
            if any(_blocks(cam, s, r, p, scale) for s, r in ((chrome_c, chrome_r), (gray_c, gray_r))):
                continue
            family = str(rng.choice(FAMILIES))
            params = sample_shape_params(family, rng)
            clutter.append((family, params, p.tolist(), scale, float(rng.uniform(0, 360)),
                            rng.uniform(0.08, 0.85, 3).tolist()))
            break
    return MidScene(index, int(seed), (hx, hy), ceiling, cam, tilt, walls, floor, chrome_c, gray_c,
                    (float(chrome_r), float(gray_r)), clutter, flash_rgb, cct)


def _blocks(cam, sphere_c, sphere_r, p, scale) -> bool:
    """Whether an object of radius ``scale`` (height up to 3 scale) standing at ``p``
    comes near the line of sight from the camera to a sphere."""
    for h in (0.5, 1.5, 2.5):
        q = np.array([p[0], p[1], h * scale])
        seg = sphere_c - cam
        t = np.clip((q - cam) @ seg / (seg @ seg), 0.0, 1.0)
        if np.linalg.norm(cam + t * seg - q) < scale * 1.2 + sphere_r * 1.3 and t > 0.05:
            return True
    return False


# --------------------------------------------------------------------------- Mitsuba
def _flash_transforms(scene: MidScene, axis: np.ndarray, snoot_m: float = 0.0):
    """``(disk to_world, snoot to_world)`` 4x4 for a flash pointing along ``axis``."""
    z = axis / np.linalg.norm(axis)
    frame = frames.frame_z_to(z)          # 3x3, third column = z
    pos = scene.flash_position
    disk = np.eye(4)
    disk[:3, :3] = frame * FLASH_RADIUS_M
    disk[:3, 3] = pos
    snoot = np.eye(4)
    snoot[:3, :3] = frame @ np.diag([SNOOT_RADIUS_M, SNOOT_RADIUS_M, max(snoot_m, 1e-4)])
    snoot[:3, 3] = pos
    return disk, snoot


def flash_radiance() -> float:
    return FLASH_INTENSITY_W_SR / (math.pi * FLASH_RADIUS_M ** 2)


def _mesh(name: str, mesh, to_world: np.ndarray, rgb):
    mi = backend_mi()
    import drjit as dr
    v = mesh.vertices.astype(np.float64) @ to_world[:3, :3].T + to_world[:3, 3]
    n = mesh.normals.astype(np.float64) @ np.linalg.inv(to_world[:3, :3])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    props = mi.Properties()
    props["bsdf"] = mi.load_dict({"type": "diffuse", "reflectance": {"type": "rgb", "value": list(rgb)}})
    m = mi.Mesh(name, len(v), len(mesh.faces), props=props, has_vertex_normals=True)
    p = mi.traverse(m)
    p["vertex_positions"] = dr.ravel(mi.Point3f(v.astype(np.float32).T))
    p["vertex_normals"] = dr.ravel(mi.Normal3f(n.astype(np.float32).T))
    p["faces"] = dr.ravel(mi.Vector3u(mesh.faces.astype(np.uint32).T))
    p.update()
    return m


def backend_mi():
    from relight import backend
    return backend.mitsuba()


def _room(scene: MidScene, mi, with_spheres: bool, cfg: MidConfig) -> dict:
    t = mi.ScalarTransform4f
    hx, hy = scene.room_half
    H = scene.ceiling_m

    def diffuse(rgb):
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(rgb)}}
    d = {
        "type": "scene",
        "floor": {"type": "rectangle", "to_world": t().scale([hx, hy, 1.0]), "bsdf": diffuse(scene.floor_rgb)},
        "ceiling": {"type": "rectangle", "to_world": t().translate([0, 0, H]) @ t().rotate([1, 0, 0], 180)
                    @ t().scale([hx, hy, 1.0]), "bsdf": diffuse(scene.wall_rgb[4])},
        # rectangles face local +z: each wall faces into the room
        "wall_px": {"type": "rectangle", "to_world": t().translate([hx, 0, H / 2]) @ t().rotate([0, 1, 0], -90)
                    @ t().scale([H / 2, hy, 1.0]), "bsdf": diffuse(scene.wall_rgb[0])},
        "wall_nx": {"type": "rectangle", "to_world": t().translate([-hx, 0, H / 2]) @ t().rotate([0, 1, 0], 90)
                    @ t().scale([H / 2, hy, 1.0]), "bsdf": diffuse(scene.wall_rgb[1])},
        "wall_py": {"type": "rectangle", "to_world": t().translate([0, hy, H / 2]) @ t().rotate([1, 0, 0], 90)
                    @ t().scale([hx, H / 2, 1.0]), "bsdf": diffuse(scene.wall_rgb[2])},
        "wall_ny": {"type": "rectangle", "to_world": t().translate([0, -hy, H / 2]) @ t().rotate([1, 0, 0], -90)
                    @ t().scale([hx, H / 2, 1.0]), "bsdf": diffuse(scene.wall_rgb[3])},
    }
    disk, snoot = _flash_transforms(scene, reference_axis(scene.camera_tilt_deg), cfg.snoot_m)
    L = flash_radiance()
    d["flash"] = {"type": "disk", "to_world": mi.ScalarTransform4f(disk),
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [L * c for c in scene.flash_rgb]}}}
    # black inside and out: lit at millimetres by the disk, any albedo would make it a tiny
    # bright lamp (path-tracing fireflies)
    if cfg.snoot_m > 0:
        d["snoot"] = {"type": "cylinder", "to_world": mi.ScalarTransform4f(snoot), "bsdf": diffuse([0.0] * 3)}
    from relight.scene.shapes import make_mesh
    for i, (family, params, pos, scale, rot, rgb) in enumerate(scene.clutter):
        mesh = make_mesh(family, params, 24, 12)
        c, s = math.cos(math.radians(rot)), math.sin(math.radians(rot))
        m = np.eye(4)
        m[:3, :3] = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) * scale
        m[:3, 3] = pos
        d[f"obj{i}"] = _mesh(f"obj{i}", mesh, m, rgb)
    if with_spheres:
        d["chrome"] = {"type": "sphere", "center": scene.chrome_centre.tolist(), "radius": scene.sphere_radius[0],
                       "bsdf": {"type": "conductor", "material": "Cr"}}
        d["gray"] = {"type": "sphere", "center": scene.gray_centre.tolist(), "radius": scene.sphere_radius[1],
                     "bsdf": diffuse([GRAY_ALBEDO] * 3)}
    return d


CUBE_AXES = ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))


def _cube_face_matrix(centre, axis) -> np.ndarray:
    """Mitsuba sensor to_world (local +X left, +Y up, +Z forward) looking along ``axis``."""
    fwd = np.asarray(axis, np.float64)
    up = np.array([0.0, 0.0, 1.0]) if abs(fwd[2]) < 0.5 else np.array([0.0, 1.0, 0.0])
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = frames.sensor_frame(fwd, up), centre
    return m


def cube_directions(n: int) -> tuple[np.ndarray, np.ndarray]:
    """World unit directions ``(6, n, n, 3)`` of the cube-map pixels (faces in the order
    of :data:`CUBE_AXES`, rows top to bottom) and their solid angles ``(6, n, n)``."""
    s = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    xx, yy = np.meshgrid(s, s)             # xx: image right, yy: image down
    local = np.stack([-xx, -yy, np.ones_like(xx)], -1)      # +X left, +Y up
    norm = np.linalg.norm(local, axis=-1)
    omega = (2.0 / n) ** 2 / norm ** 3
    dirs = []
    for axis in CUBE_AXES:
        m = _cube_face_matrix(np.zeros(3), axis)[:3, :3]
        dirs.append(local / norm[..., None] @ m.T)
    return np.stack(dirs), np.broadcast_to(omega, (6, n, n)).copy()


def _cube_sensor(mi, centres, n: int, spp: int) -> dict:
    sensor = {"type": "batch", "film": {"type": "hdrfilm", "width": n * 6 * len(centres), "height": n,
                                        "rfilter": {"type": "box"}, "pixel_format": "rgb"},
              "sampler": {"type": "independent", "sample_count": spp}}
    k = 0
    for c in centres:
        for axis in CUBE_AXES:
            sensor[f"face{k}"] = {"type": "perspective", "fov": 90.0, "fov_axis": "x", "near_clip": 1e-3,
                                  "to_world": mi.ScalarTransform4f(_cube_face_matrix(c, axis))}
            k += 1
    return sensor


class MidRenderer:
    """The two loaded Mitsuba scenes of one room: the camera's view (with the spheres)
    and the probes' cube maps (without them); :meth:`render` points the flash."""

    def __init__(self, scene: MidScene, cfg: MidConfig):
        from relight import render
        mi = backend_mi()
        self.scene, self.cfg, self.mi = scene, cfg, mi
        d = _room(scene, mi, True, cfg)
        right, up, forward = frames.camera_basis(scene.camera_tilt_deg)
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = -right, up, forward, scene.camera_position
        d["integrator"] = {"type": "path", "max_depth": cfg.max_depth}
        d["sensor"] = render.sensor(cfg.res, cfg.fov_deg, "multijitter", mi.ScalarTransform4f(m))
        # the probes photographed at probe_zoom x the resolution (MID's photographs are
        # large; the network sees them reduced): one cropped sensor per sphere
        self.crops = []
        big = cfg.res * cfg.probe_zoom
        from relight.probe.geometry import bounding_box, outline_polygon
        camera = probe_camera(cfg, cfg.probe_zoom)
        for k, which in enumerate(("chrome", "gray")):
            x0, y0, x1, y1 = bounding_box(camera, probe_sphere(scene, which), margin=4 * cfg.probe_zoom)
            z = cfg.probe_zoom      # whole image pixels, so the chrome crop can be pasted in
            x0, y0 = max(0, x0 // z * z), max(0, y0 // z * z)
            x1, y1 = min(big, -(-x1 // z) * z), min(big, -(-y1 // z) * z)
            s = render.sensor(big, cfg.fov_deg, "multijitter", mi.ScalarTransform4f(m))
            s["film"].update(crop_offset_x=int(x0), crop_offset_y=int(y0), crop_width=int(x1 - x0),
                             crop_height=int(y1 - y0))
            d[f"crop_{which}"] = s
            self.crops.append((x0, y0, x1, y1))
        self.view = mi.load_dict(d)
        # light tracing: a room lit by a flash bouncing off a wall is what it does well;
        # it cannot see the chrome sphere (a mirror), whose pixels come from the path-traced crop
        self.ptracer = mi.load_dict({"type": "ptracer", "max_depth": cfg.max_depth})
        import cv2
        x0, y0, x1, y1 = self.crops[0]
        inside = np.zeros((y1 - y0, x1 - x0), np.uint8)
        x, y = outline_polygon(camera, probe_sphere(scene, "chrome"), 256)
        pts = np.round(np.stack([x - 0.5 - x0, y - 0.5 - y0], -1) * 16).astype(np.int32)
        cv2.fillPoly(inside, [pts], 1, cv2.LINE_8, shift=4)
        self.chrome_inside = inside.astype(np.float32)
        p = _room(scene, mi, False, cfg)
        p["integrator"] = {"type": "path", "max_depth": cfg.max_depth, "hide_emitters": True}
        p["sensor"] = _cube_sensor(mi, [scene.chrome_centre, scene.gray_centre], cfg.cube_res, cfg.cube_spp)
        self.probe = mi.load_dict(p)
        self.params = [mi.traverse(self.view), mi.traverse(self.probe)]

    def _point(self, axis):
        disk, snoot = _flash_transforms(self.scene, axis, self.cfg.snoot_m)
        for p in self.params:
            p["flash.to_world"] = self.mi.ScalarTransform4f(disk)
            if self.cfg.snoot_m > 0:
                p["snoot.to_world"] = self.mi.ScalarTransform4f(snoot)
            p.update()

    def render(self, axis, seed: int) -> tuple[np.ndarray, np.ndarray, dict]:
        """With the flash along ``axis``: the linear image ``(res, res, 3)``, the probe
        photograph (``probe_zoom`` x larger, black but around the two spheres) and the
        physical truth."""
        from relight import render
        self._point(axis)
        image = render.render_scene(self.view, self.cfg.spp, seed, "multijitter", integrator=self.ptracer)[..., :3]
        big = self.cfg.res * self.cfg.probe_zoom
        probe = np.zeros((big, big, 3), np.float32)
        for k, (x0, y0, x1, y1) in enumerate(self.crops):
            spp = self.cfg.probe_gray_spp if k == 1 else self.cfg.probe_spp   # the gray mean needs few
            crop = render.render_scene(self.view, spp, seed + 7 + k, "multijitter", sensor=k + 1)
            probe[y0:y1, x0:x1] = crop[..., :3]
            if k == 0:    # the chrome sphere's pixels: its path-traced crop, averaged per image pixel
                z = self.cfg.probe_zoom
                h, w = (y1 - y0) // z, (x1 - x0) // z
                inside = self.chrome_inside[..., None]
                cover = self.chrome_inside.reshape(h, z, w, z).mean((1, 3))[..., None]
                mirror = (crop[..., :3] * inside).reshape(h, z, w, z, 3).mean((1, 3))
                win = image[y0 // z:y0 // z + h, x0 // z:x0 // z + w]
                image[y0 // z:y0 // z + h, x0 // z:x0 // z + w] = win * (1 - cover) + mirror
        cube = render.render_scene(self.probe, self.cfg.cube_spp, seed + 1)[..., :3]
        n = self.cfg.cube_res
        faces = cube.reshape(n, 12, n, 3).transpose(1, 0, 2, 3)     # (12, n, n, 3)
        truth = physical_truth(self.scene, axis, faces[:6], faces[6:], self.probe, self.cfg.snoot_m)
        return image, probe, truth


def _direct_flash(scene: MidScene, axis, point, mi_scene, snoot_m: float = 0.0) -> tuple[np.ndarray, float]:
    """The flash seen from ``point``: (unit direction, radiance x projected solid angle per
    rgb unit) -- 0 when the point is behind the disk or the view is blocked."""
    to = scene.flash_position - point
    dist = float(np.linalg.norm(to))
    w = to / dist
    cos_emit = float(-w @ axis)
    if cos_emit <= 0:
        return w, 0.0
    omega = math.pi * FLASH_RADIUS_M ** 2 * cos_emit / dist ** 2
    # the snoot's front opening (radius 1.05 r, SNOOT_LENGTH_M ahead) shifted by L tan(off-axis)
    # over the disk: the visible part is the two circles' overlap
    shift = snoot_m * math.tan(math.acos(min(cos_emit, 1.0)))
    visible_fraction = circle_overlap(FLASH_RADIUS_M, SNOOT_RADIUS_M, shift) / (math.pi * FLASH_RADIUS_M ** 2)
    if visible_fraction > 0 and mi_scene is not None:
        mi = backend_mi()
        ray = mi.Ray3f(mi.Point3f(*point.tolist()), mi.Vector3f(*w.tolist()))
        si = mi_scene.ray_intersect(ray)
        hit_t = float(np.array(si.t)[0]) if bool(np.array(si.is_valid())[0]) else math.inf
        if hit_t < dist - math.hypot(snoot_m, SNOOT_RADIUS_M) - 0.02:   # the snoot is in the closed form
            visible_fraction = 0.0
    return w, flash_radiance() * omega * visible_fraction


def circle_overlap(r1: float, r2: float, d: float) -> float:
    """Area of the intersection of two discs of radii ``r1``, ``r2`` whose centres are
    ``d`` apart.

    >>> round(circle_overlap(1.0, 2.0, 0.5), 6) == round(math.pi, 6), circle_overlap(1.0, 1.0, 2.0)
    (True, 0.0)
    >>> round(circle_overlap(1.0, 1.0, 1.0), 6)     # two unit discs one radius apart
    1.22837
    """
    if d >= r1 + r2:
        return 0.0
    if d <= abs(r1 - r2):
        return math.pi * min(r1, r2) ** 2
    a1 = math.acos((d * d + r1 * r1 - r2 * r2) / (2 * d * r1))
    a2 = math.acos((d * d + r2 * r2 - r1 * r1) / (2 * d * r2))
    return r1 * r1 * (a1 - math.sin(2 * a1) / 2) + r2 * r2 * (a2 - math.sin(2 * a2) / 2)


def dominant_direction(dirs: np.ndarray, weights_lum: np.ndarray, cap_deg: float = CAP_DEG) -> np.ndarray:
    """The centre of the brightest ``cap_deg`` cap of a radiance field sampled as
    directions ``(N, 3)`` with luminance x solid angle ``(N,)``: the cap (centred on a
    sample) of largest integral, refined as the weighted mean direction inside it.

    >>> d = np.array([[0, 0, 1.0], [0, 0.05, 1.0], [1.0, 0, 0]]); d /= np.linalg.norm(d, axis=1)[:, None]
    >>> np.round(dominant_direction(d, np.array([1.0, 1.0, 1.5])), 3).tolist()
    [0.0, 0.025, 1.0]
    """
    from scipy.spatial import cKDTree
    dirs = np.asarray(dirs, np.float64)
    weights_lum = np.asarray(weights_lum, np.float64)
    chord = 2.0 * math.sin(math.radians(cap_deg) / 2.0) * (1 + 1e-9)   # cap radius as a chord
    tree = cKDTree(dirs)
    pairs = tree.sparse_distance_matrix(tree, chord, output_type="coo_matrix")   # memory ~ N x cap
    cap = np.bincount(pairs.row, weights=weights_lum[pairs.col], minlength=len(dirs))   # self pairs included
    best = int(np.argmax(cap))
    sel = tree.query_ball_point(dirs[best], chord)
    v = (dirs[sel] * weights_lum[sel, None]).sum(0)
    return v / np.linalg.norm(v)


def physical_truth(scene: MidScene, axis, chrome_faces: np.ndarray, gray_faces: np.ndarray,
                   mi_scene=None, snoot_m: float = 0.0) -> dict:
    """The physical ground truth (module docstring) from the cube maps ``(6, n, n, 3)``
    at the chrome and gray spheres' centres (emitters hidden) and the flash's closed form."""
    axis = np.asarray(axis, np.float64)
    n = chrome_faces.shape[1]
    dirs, omega = cube_directions(n)
    dirs, omega = dirs.reshape(-1, 3), omega.reshape(-1)
    out = {}
    for which, faces, centre in (("chrome", chrome_faces, scene.chrome_centre),
                                 ("gray", gray_faces, scene.gray_centre)):
        rad = faces.reshape(-1, 3).astype(np.float64)
        w_flash, power = _direct_flash(scene, axis, centre, mi_scene, snoot_m)
        d_all = np.concatenate([dirs, w_flash[None]])
        rgb_all = np.concatenate([rad * omega[:, None], power * np.asarray(scene.flash_rgb)[None]])
        out[which] = (d_all, rgb_all, power)
    d_all, rgb_all, power = out["chrome"]
    world = dominant_direction(d_all, luminance(rgb_all))
    total = rgb_all.sum(0)
    direct_share = float(luminance(power * np.asarray(scene.flash_rgb)) / max(luminance(total), 1e-12))
    g_rgb = out["gray"][1].sum(0)
    g_rgb = g_rgb / np.linalg.norm(g_rgb)
    cam = frames.world_to_camera(world, scene.camera_tilt_deg)
    _, pan, tilt = frames.cartesian_to_spherical(world)
    return {"to_light_world": world.tolist(), "to_light_camera": cam.tolist(),
            "pan_rel_deg": float(frames.wrap360(pan)), "tilt_deg": float(tilt),
            "rgb": g_rgb.tolist(), "direct_share": direct_share}

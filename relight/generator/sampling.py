"""SID2 sampling rules: draw a random :class:`SceneSpec` like the paper's dataset.

Paper, section "A synthetic dataset": 1-3 objects placed near the scene centre on the
floor, never overlapping, each with a diffuse BSDF of random colour and roughness (the
paper: one colour "for each mesh texture in each object"; ``object_parts`` cuts each
procedural object into that many independently coloured parts); a
multi-sided room with flat textures on the walls (``backgrounds``: ``patterns``, 2-5
colours per texture, or ``mosaic``, grids of 16-256 cells coloured independently: many
surfaces in view); a point light at r in [20, 50] m,
tilt in [30, 90] deg in steps of 5, pan in [0, 360) deg in steps of 1, colour near the
Planckian locus; the camera at r = 20 m, pan 0, tilt in [10, 70] deg, looking at the
centre.

Every random choice comes from one ``numpy.random.Generator`` seeded per image, so an
image's spec depends only on (dataset seed, image index) and the config.

``--preset sid2-paper`` (:func:`sid2_paper_config`) sets the paper group's colour protocol
beside these rooms: Tanner-Helland lights in 100 K steps, a closed library of 250
backgrounds, pastel part colours (see the block at the end of this module).
"""
from __future__ import annotations

__all__ = [
    "read_config_file", "GeneratorConfig", "LEGACY_CONFIG", "BUILTIN_MESHES", "BUILTIN_MESH_DIR", "mesh_files",
    "image_rng", "split_of", "GLOSSY_WEIGHT", "GLOSS_ALPHA", "METAL_F0",
    "sample_scene",
    "sid2_paper_config", "is_sid2_paper",
]

import dataclasses
import json
import math
import os
from dataclasses import dataclass

import numpy as np

from relight import colour, frames
from relight.scene import albedo, noise, shapes, textures
from relight.scene.spec import (LEGACY_SAMPLER, MAX_DEPTH, MAX_RES, MAX_SPP, SAMPLERS, CameraSpec, LightSpec,
                                BackdropSpec, ObjectSpec, RenderSpec, RoomSpec, SceneSpec)
from relight.errors import ConfigError


def read_config_file(path: str) -> dict:
    """The JSON object of a generator config file; :class:`ConfigError` (one line) if the
    file cannot be read or holds something else."""
    try:
        with open(path) as f:
            data = json.load(f)
    except (OSError, json.JSONDecodeError) as exc:
        raise ConfigError(f"cannot read config {path}: {str(exc).splitlines()[0]}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"config {path}: expected a JSON object")
    return data


VOID_ALBEDO = 0.01        # walls and floor of a void scene: grey albedo in [0, VOID_ALBEDO] by default
#                           (config void_albedo: real black cloth, velvet to felt, reflects about 1-5%)


@dataclass(frozen=True)
class GeneratorConfig:
    """Settings of the SID2-style generator (units in the names; ranges inclusive)."""
    res: int = 128
    spp: int | None = None          # samples per pixel; None: the fewest reaching target_rmse
    target_rmse: float = noise.DEFAULT_TARGET_RMSE   # relative RMSE target (used when spp is None)
    sampler: str = noise.DEFAULT_SAMPLER             # Mitsuba sampler plugin
    colour_prior: str = albedo.DEFAULT_PRIOR         # surface-colour prior (relight.scene.albedo)
    backgrounds: str = "patterns"                    # wall/floor textures (textures.BACKGROUNDS)
    light_colour: str = "planckian"                  # colour.LIGHT_COLOURS: CCT + Duv, or Tanner-Helland
    max_depth: int = 4
    fov_deg: float = 40.0
    camera_r_m: float = 20.0
    camera_tilt_deg: tuple[float, float] = (10.0, 70.0)
    light_r_m: tuple[float, float] = (20.0, 50.0)
    light_tilt_deg: tuple[float, float] = (30.0, 90.0)
    light_tilt_step_deg: float = 5.0
    light_pan_step_deg: float = 1.0
    light_strength: tuple[float, float] = (2.5, 4.0)   # irradiance at the centre, W/m^2
    n_objects: tuple[int, int] = (1, 3)
    object_parts: tuple[int, int] = (1, 32)            # independently coloured parts per object (1, 1 before)
    object_size_m: tuple[float, float] = (0.8, 2.0)   # max horizontal radius after scaling
    placement_radius_m: float = 3.5                    # object centres within this disc
    object_gap_m: float = 0.1                          # minimum gap between bounding circles
    families: tuple[str, ...] = ()                     # empty: all of shapes.FAMILIES
    n_walls: tuple[int, int] = (4, 8)
    room_inradius_m: tuple[float, float] = (100.0, 140.0)
    wall_height_m: float = 80.0
    texture_res: int = 128
    split: tuple[float, float, float] = (0.8, 0.1, 0.1)
    mesh_dir: str | None = None  # a folder of .obj/.ply meshes, or "builtin": relight/assets/meshes
    mesh_fraction: float = 0.5   # share of objects taken from mesh_dir when given
    # Photo-like variation (None / 0: off, and the draws of every image are exactly as before)
    fov_range_deg: tuple[float, float] | None = None     # field of view drawn per image (else fov_deg)
    view_halfwidth_m: tuple[float, float] | None = None  # half-width of the view at the scene centre,
    #                                                      drawn per image; sets the camera distance
    void_fraction: float = 0.0   # share of scenes on a near-black void (walls and floor of albedo <= VOID_ALBEDO)
    void_albedo: tuple[float, float] = (0.0, VOID_ALBEDO)   # a void's grey albedo range (black cloth 0.01-0.05)
    # Object materials (0: every object matte, and the draws of every image exactly as before)
    glossy_fraction: float = 0.0  # share of objects with a varnish-like white specular lobe (GLOSSY_WEIGHT)
    metal_fraction: float = 0.0   # share of objects that are metals (a specular lobe alone, METAL_F0 colours)
    # Lights near the camera (on-camera flash, lamp behind the photographer; 0: off, draws as before)
    flash_fraction: float = 0.0   # share of scenes whose light lies within flash_cone_deg of the camera's direction
    flash_cone_deg: float = 40.0
    # Sky fill (0: off, draws as before): a share of scenes gets a uniform sky of the light's colour
    ambient_fraction: float = 0.0
    ambient_ratio: tuple[float, float] = (0.05, 0.5)   # its irradiance over the light's (LightSpec.ambient)
    # Studio backdrop (0: off, draws as before): a share of void scenes gets a grey backdrop close
    # behind the objects (BackdropSpec); a light it would hide from an object moves to its mirror
    # direction in front of it
    backdrop_fraction: float = 0.0
    backdrop_albedo: tuple[float, float] = (0.005, 0.2)   # grey albedo, drawn log-uniform
    backdrop_gap: tuple[float, float] = (0.3, 3.0)        # gap behind the objects, in largest object radii
    # Object masks (false: none, the folder as before): masks/ID.png, each pixel's share covered by
    # the objects (SceneTemplate.object_mask), named by the record's "mask" field. No draw depends on it.
    object_masks: bool = False

    def __post_init__(self):
        def rng_ok(name, lo_min, hi_max):
            lo, hi = getattr(self, name)
            if not (lo_min <= lo <= hi <= hi_max):
                raise ConfigError(f"{name}: expected {lo_min} <= lo <= hi <= {hi_max}, got {(lo, hi)}")
        limits = {"res": MAX_RES, "max_depth": MAX_DEPTH, "texture_res": MAX_RES, "spp": MAX_SPP}
        for name in ("res", "max_depth", "texture_res") + (("spp",) if self.spp is not None else ()):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or not 1 <= v <= limits[name]:
                raise ConfigError(f"{name}: expected an integer in [1, {limits[name]}], got {v!r}")
        if self.sampler not in SAMPLERS:
            raise ConfigError(f"sampler: expected one of {', '.join(SAMPLERS)}, got {self.sampler!r}")
        if self.colour_prior not in albedo.PRIORS:
            raise ConfigError(f"colour_prior: expected one of {', '.join(albedo.PRIORS)}, "
                              f"got {self.colour_prior!r}")
        if self.backgrounds not in textures.BACKGROUNDS:
            raise ConfigError(f"backgrounds: expected one of {', '.join(textures.BACKGROUNDS)}, "
                              f"got {self.backgrounds!r}")
        if self.light_colour not in colour.LIGHT_COLOURS:
            raise ConfigError(f"light_colour: expected one of {', '.join(colour.LIGHT_COLOURS)}, "
                              f"got {self.light_colour!r}")
        if self.spp is None:
            try:
                noise.spp_for_target(self.target_rmse, self.sampler)
            except ValueError as exc:
                raise ConfigError(str(exc)) from None
        rng_ok("camera_tilt_deg", -89, 89)
        rng_ok("light_r_m", 0.1, 1e4)
        rng_ok("light_tilt_deg", 0, 90)
        rng_ok("n_objects", 1, 3)
        rng_ok("object_parts", 1, shapes.MAX_PARTS)
        rng_ok("n_walls", 3, 12)
        rng_ok("object_size_m", 0.01, 100)
        rng_ok("light_strength", 1e-6, 1e6)
        rng_ok("room_inradius_m", 1, 1e5)
        if self.room_inradius_m[0] < 2 * self.light_r_m[1]:
            raise ConfigError("room_inradius_m must be at least twice the largest light distance "
                              "(so a light near a wall never over-lights it)")
        if self.room_inradius_m[0] <= self.camera_r_m:
            raise ConfigError("the camera must stand inside the room")
        if abs(sum(self.split) - 1.0) > 1e-9 or min(self.split) < 0:
            raise ConfigError(f"split: three non-negative fractions summing to 1 expected, got {self.split}")
        unknown = set(self.families) - set(shapes.FAMILIES)
        if unknown:
            raise ConfigError(f"unknown shape families {sorted(unknown)}; valid: {', '.join(shapes.FAMILIES)}")
        if self.fov_range_deg is not None:
            rng_ok("fov_range_deg", 5, 120)
        if self.view_halfwidth_m is not None:
            rng_ok("view_halfwidth_m", 0.5, 100)
        if not (isinstance(self.flash_cone_deg, (int, float)) and 0.0 <= self.flash_cone_deg <= 90.0):
            raise ConfigError(f"flash_cone_deg: expected a number in [0, 90], got {self.flash_cone_deg!r}")
        rng_ok("ambient_ratio", 0.0, 10.0)
        rng_ok("void_albedo", 0.0, 1.0)
        rng_ok("backdrop_albedo", 1e-4, 1.0)
        rng_ok("backdrop_gap", 0.01, 100.0)
        for name in ("void_fraction", "glossy_fraction", "metal_fraction", "mesh_fraction", "flash_fraction",
                     "ambient_fraction", "backdrop_fraction"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and 0.0 <= v <= 1.0):
                raise ConfigError(f"{name}: expected a number in [0, 1], got {v!r}")
        if not isinstance(self.object_masks, bool):
            raise ConfigError(f"object_masks: expected true or false, got {self.object_masks!r}")
        if self.glossy_fraction + self.metal_fraction > 1.0:
            raise ConfigError("glossy_fraction + metal_fraction: at most 1")
        if self.mesh_dir is not None and not mesh_files(self.mesh_dir):
            raise ConfigError(f"--mesh-dir {self.mesh_dir}: no .obj or .ply files found")

    @classmethod
    def from_file(cls, path: str | None, preset: str | None = None, **overrides) -> "GeneratorConfig":
        """Settings of a named preset (:data:`PRESETS`; ``None``: the defaults), then a JSON
        config file (keys as the fields; ``None``: no file), then ``overrides`` (not None)."""
        data = dict(PRESETS[preset]) if preset in PRESETS else {}
        if path is not None:
            found = read_config_file(path)
            names = {f.name for f in dataclasses.fields(cls)}
            unknown = set(found) - names
            if unknown:
                raise ConfigError(f"config {path}: unknown keys {sorted(unknown)}")
            data.update({k: tuple(v) if isinstance(v, list) else v for k, v in found.items()})
        data.update({k: v for k, v in overrides.items() if v is not None})
        return cls(**data)

    @property
    def render_spp(self) -> int:
        """Samples per pixel of every image: ``spp``, or the fewest that reach
        ``target_rmse`` with ``sampler`` (:func:`relight.scene.noise.spp_for_target`)."""
        return self.spp if self.spp is not None else noise.spp_for_target(self.target_rmse, self.sampler)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


MIN_CAMERA_R_M = 6.0      # a camera set by view_halfwidth_m stays at least this far from the centre

# Named generator presets (``relight generate --preset NAME``): overrides of the defaults.
# ``photo``: the photo-training mix of issue "from renders to photographs" (docs/photo.md): level
# to steep cameras, 20-90 degree fields of view framed on the objects, lights down to 5 degrees
# of elevation, and half the scenes on a black void, as studio photographs of objects are.
PRESETS: dict[str, dict] = {
    "photo": {"camera_tilt_deg": (2.0, 70.0), "fov_range_deg": (20.0, 90.0), "view_halfwidth_m": (2.5, 8.0),
              "light_tilt_deg": (5.0, 90.0), "void_fraction": 0.5, "placement_radius_m": 2.5},
}


# Settings added after the first datasets, with the value every dataset made before the
# setting existed used: a card without the key means that value (never today's default).
LEGACY_CONFIG: dict = {"sampler": LEGACY_SAMPLER, "colour_prior": "hsv", "object_parts": [1, 1],
                       "backgrounds": "patterns", "light_colour": "planckian",
                       # the photo-like, material, flash and sky draws: off before they existed
                       "void_fraction": 0.0, "glossy_fraction": 0.0, "metal_fraction": 0.0,
                       "flash_fraction": 0.0, "flash_cone_deg": 40.0, "ambient_fraction": 0.0,
                       "ambient_ratio": [0.05, 0.5], "void_albedo": [0.0, VOID_ALBEDO],
                       "backdrop_fraction": 0.0, "backdrop_albedo": [0.005, 0.2], "backdrop_gap": [0.3, 3.0],
                       "object_masks": False}


BUILTIN_MESHES = "builtin"   # mesh_dir value: the meshes shipped in relight/assets/meshes
BUILTIN_MESH_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "assets", "meshes")


def mesh_files(mesh_dir: str) -> list[str]:
    """Sorted absolute paths of the .obj/.ply files in a folder (not recursive);
    ``"builtin"``: relight's shipped meshes (:data:`BUILTIN_MESH_DIR`, public-domain and
    CC BY scans and models, each with its licence file beside it)."""
    if mesh_dir == BUILTIN_MESHES:
        mesh_dir = BUILTIN_MESH_DIR
    if not os.path.isdir(mesh_dir):
        return []
    return sorted(os.path.abspath(os.path.join(mesh_dir, f)) for f in os.listdir(mesh_dir)
                  if f.lower().endswith((".obj", ".ply")))


def image_rng(dataset_seed: int, index: int) -> np.random.Generator:
    """The generator of image ``index``: independent of every other image."""
    return np.random.default_rng(np.random.SeedSequence([int(dataset_seed), int(index)]))


def split_of(image_id: str, fractions=(0.8, 0.1, 0.1)) -> str:
    """Deterministic train/val/test split of an image id (hash of the id)."""
    import hashlib
    u = int.from_bytes(hashlib.sha256(image_id.encode()).digest()[:8], "big") / 2.0 ** 64
    if u < fractions[0]:
        return "train"
    return "val" if u < fractions[0] + fractions[1] else "test"


def _place_objects(rng: np.random.Generator, sizes_m: list[float], cfg: GeneratorConfig):
    """Rejection-sample non-overlapping bounding circles inside the placement disc."""
    for _attempt in range(200):
        centres = []
        for r in sizes_m:
            for _try in range(50):
                rho = cfg.placement_radius_m * math.sqrt(rng.uniform())
                phi = rng.uniform(0.0, 2.0 * math.pi)
                c = (rho * math.cos(phi), rho * math.sin(phi))
                if all(math.hypot(c[0] - o[0], c[1] - o[1]) >= r + ro + cfg.object_gap_m
                       for o, ro in zip(centres, sizes_m)):
                    centres.append(c)
                    break
            else:
                break
        if len(centres) == len(sizes_m):
            return centres
        sizes_m = [s * 0.9 for s in sizes_m]  # crowded: shrink and retry
    raise RuntimeError("could not place objects without overlap")  # unreachable for sane configs


def sample_scene(cfg: GeneratorConfig, dataset_seed: int, index: int) -> SceneSpec:
    """The spec of image ``index`` of a dataset (id is the zero-padded index)."""
    rng = image_rng(dataset_seed, index)
    cam_tilt = float(np.round(rng.uniform(*cfg.camera_tilt_deg), 2))
    camera = CameraSpec(tilt_deg=cam_tilt, r_m=cfg.camera_r_m, pan_deg=0.0, fov_deg=cfg.fov_deg)

    n_tilt = int(round((cfg.light_tilt_deg[1] - cfg.light_tilt_deg[0]) / cfg.light_tilt_step_deg))
    tilt_l = cfg.light_tilt_deg[0] + cfg.light_tilt_step_deg * int(rng.integers(0, n_tilt + 1))
    n_pan = int(round(360.0 / cfg.light_pan_step_deg))
    pan_l = cfg.light_pan_step_deg * int(rng.integers(0, n_pan))
    r_l = float(np.round(rng.uniform(*cfg.light_r_m), 3))
    if cfg.light_colour == "tanner-helland":   # a temperature alone: no Duv
        cct_k, rgb = colour.sample_cct_step_light(rng)
        duv = None
    else:
        cct_k, duv, rgb = colour.sample_light_colour(rng)
    light = LightSpec(r_m=r_l, pan_deg=float(pan_l), tilt_deg=float(tilt_l),
                      rgb=tuple(float(c) for c in rgb),
                      strength=float(np.round(rng.uniform(*cfg.light_strength), 4)),
                      cct_k=float(cct_k), duv=None if duv is None else float(duv))

    n_walls = int(rng.integers(cfg.n_walls[0], cfg.n_walls[1] + 1))
    prior = albedo.scene_prior(rng, cfg.colour_prior)
    inradius_m = float(np.round(rng.uniform(*cfg.room_inradius_m), 3))
    rotation_deg = float(np.round(rng.uniform(0.0, 360.0 / n_walls), 3))
    if cfg.backgrounds in (textures.LIBRARY, textures.UNSEEN):   # one background: every wall, and the floor
        wall, floor_texture = textures.sample_background(rng, cfg.backgrounds)
        wall_textures = (wall,) * n_walls
    else:
        kind = textures.MOSAIC if cfg.backgrounds == textures.MOSAIC else None
        wall_textures = tuple(textures.sample_texture_params(rng, kind, prior) for _ in range(n_walls))
        floor_texture = textures.sample_texture_params(rng, kind, prior)
    room = RoomSpec(n_walls=n_walls, inradius_m=inradius_m, height_m=cfg.wall_height_m,
                    rotation_deg=rotation_deg, wall_textures=wall_textures, floor_texture=floor_texture,
                    texture_res=cfg.texture_res)

    families = cfg.families or shapes.FAMILIES
    user_meshes = mesh_files(cfg.mesh_dir) if cfg.mesh_dir else []
    n_obj = int(rng.integers(cfg.n_objects[0], cfg.n_objects[1] + 1))
    sizes = [float(np.round(rng.uniform(*cfg.object_size_m), 4)) for _ in range(n_obj)]
    centres = _place_objects(rng, list(sizes), cfg)
    objects = []
    for size, centre in zip(sizes, centres):
        if user_meshes and rng.uniform() < cfg.mesh_fraction:
            family, params = "mesh", {}
            mesh_path = user_meshes[int(rng.integers(0, len(user_meshes)))]
        else:
            family = str(families[int(rng.integers(0, len(families)))])
            params, mesh_path = shapes.sample_shape_params(family, rng), None
        yaw_deg = float(np.round(rng.uniform(0.0, 360.0), 3))
        # one-part objects draw exactly what they drew before parts existed (same images)
        n_parts = 1 if cfg.object_parts == (1, 1) else int(rng.integers(cfg.object_parts[0],
                                                                         cfg.object_parts[1] + 1))
        colours = [albedo.object_reflectance(rng, prior) for _ in range(n_parts)]
        objects.append(ObjectSpec(
            family=family, params=params, mesh_path=mesh_path,
            position_m=(float(np.round(centre[0], 4)), float(np.round(centre[1], 4))),
            yaw_deg=yaw_deg, size_m=size, reflectance=colours[0],
            roughness=float(np.round(rng.uniform(0.0, 1.0), 4)),
            part_reflectances=tuple(colours) if n_parts > 1 else ()))
    render = RenderSpec(res=cfg.res, spp=cfg.render_spp, max_depth=cfg.max_depth,
                        seed=int(rng.integers(0, 2 ** 31)), sampler=cfg.sampler)
    void = False
    if cfg.fov_range_deg is not None or cfg.view_halfwidth_m is not None or cfg.void_fraction > 0:
        camera, room, void = _photo_draws(rng, cfg, camera, room)   # drawn last: other draws unchanged
    if cfg.glossy_fraction > 0 or cfg.metal_fraction > 0:
        objects = [_material_draws(rng, cfg, o) for o in objects]   # after the photo draws
    if cfg.flash_fraction > 0 and rng.uniform() < cfg.flash_fraction:   # after the material draws
        light = _flash_light(rng, cfg, camera, light)
    if cfg.ambient_fraction > 0 and rng.uniform() < cfg.ambient_fraction:   # after the flash draw
        light = dataclasses.replace(light, ambient=float(np.round(rng.uniform(*cfg.ambient_ratio), 4)))
    backdrop = None
    if void and cfg.backdrop_fraction > 0 and rng.uniform() < cfg.backdrop_fraction:   # after the sky draw
        backdrop, light = _backdrop_draw(rng, cfg, camera, light, objects)
    return SceneSpec(id=f"{index:06d}", camera=camera, light=light, room=room,
                     objects=tuple(objects), render=render, colour_prior=prior, backdrop=backdrop)


def _photo_draws(rng: np.random.Generator, cfg: GeneratorConfig, camera: CameraSpec,
                 room: RoomSpec) -> tuple[CameraSpec, RoomSpec, bool]:
    """The photo-like draws of one image (after all others): field of view, camera
    distance from the view's half-width at the centre (``r = w / tan(fov / 2)``, at least
    :data:`MIN_CAMERA_R_M`), and a void room (walls and floor near-black, one grey each;
    the flag says whether it was drawn)."""
    fov = camera.fov_deg
    if cfg.fov_range_deg is not None:
        fov = float(np.round(rng.uniform(*cfg.fov_range_deg), 2))
    r_m = camera.r_m
    if cfg.view_halfwidth_m is not None:
        halfwidth = rng.uniform(*cfg.view_halfwidth_m)
        r_m = float(np.round(max(MIN_CAMERA_R_M, halfwidth / math.tan(math.radians(fov) / 2.0)), 3))
    camera = dataclasses.replace(camera, fov_deg=fov, r_m=min(r_m, room.inradius_m / 2.0))
    if cfg.void_fraction > 0 and rng.uniform() < cfg.void_fraction:
        def dark():
            grey = float(np.round(rng.uniform(*cfg.void_albedo), 4))
            return {"kind": "checker", "seed": 0, "cells": 2, "angle": 0.0, "colors": [[grey] * 3, [grey] * 3]}
        room = dataclasses.replace(room, wall_textures=tuple(dark() for _ in room.wall_textures),
                                   floor_texture=dark())
        return camera, room, True
    return camera, room, False


BACKDROP_TURN_DEG = 20.0   # a backdrop faces the camera to within this many degrees of azimuth
BACKDROP_MAX_M = 200.0     # cap on a backdrop's height and half-width


def _backdrop_draw(rng: np.random.Generator, cfg: GeneratorConfig, camera: CameraSpec, light: LightSpec,
                   objects: list[ObjectSpec]) -> tuple[BackdropSpec, LightSpec]:
    """A studio backdrop behind the objects as the camera sees them, and the light.

    It faces the camera's azimuth to within :data:`BACKDROP_TURN_DEG`, stands a gap of
    ``backdrop_gap`` largest object radii behind the farthest object, reaches 0.7-1.5
    times the height at which the image's top edge meets it (so that it mostly fills the
    view behind the objects, its top edge sometimes in view) and is 1.2-2 times as wide
    as the view there; grey albedo log-uniform in ``backdrop_albedo``.

    A studio never lights through its backdrop, and the label must stay the light that
    lights the objects: a light the backdrop would hide from any object (its base or top)
    moves to its mirror direction across the backdrop's plane (same tilt, now on the
    camera's side of it). The backdrop itself never depends on the light: whether a void
    scene has one says nothing about where its light is."""
    pan = float(np.round(frames.wrap360(camera.pan_deg + 180.0 + rng.uniform(-1, 1) * BACKDROP_TURN_DEG), 3))
    out = frames.direction(pan, 0.0)
    size = max(o.size_m for o in objects)
    behind = max([0.0] + [float(np.dot(out[:2], o.position_m)) + o.size_m for o in objects])
    distance = float(np.round(behind + size * rng.uniform(*cfg.backdrop_gap), 4))
    cam = frames.camera_to_world(camera.tilt_deg, camera.r_m, camera.pan_deg)
    half_fov = math.tan(math.radians(camera.fov_deg) / 2.0)
    top_ray = -cam[:3, 2] + half_fov * cam[:3, 1]        # the image's top edge (square images)
    origin = cam[:3, 3]
    away = float(np.dot(top_ray, out))                    # > 0: the top edge's ray runs toward the backdrop
    reach = (distance - float(np.dot(origin, out))) / away if away > 0 else math.inf
    z_top = origin[2] + reach * top_ray[2] if math.isfinite(reach) else BACKDROP_MAX_M
    height = float(np.round(min(BACKDROP_MAX_M, max(2.0 * size, z_top * rng.uniform(0.7, 1.5))), 3))
    view_m = (float(np.linalg.norm(origin[:2])) + distance) * half_fov
    half_width = float(np.round(min(BACKDROP_MAX_M, view_m * rng.uniform(1.2, 2.0) + size), 3))
    albedo_ = float(np.round(math.exp(rng.uniform(*np.log(cfg.backdrop_albedo))), 4))
    backdrop = BackdropSpec(pan_deg=pan, distance_m=distance, half_width_m=half_width, height_m=height,
                            albedo=albedo_)
    points = [(o.position_m[0], o.position_m[1], z) for o in objects for z in (0.0, o.size_m)]
    if any(backdrop.blocks(p, light.position_m) for p in points):
        # the mirror azimuth across the plane whose normal is at pan: 2 * pan + 180 - light pan
        light = dataclasses.replace(light, pan_deg=float(np.round(frames.wrap360(
            2.0 * pan + 180.0 - light.pan_deg), 2)))
    return backdrop, light


# Object materials. A glossy object: the diffuse plus a white GGX lobe of weight GLOSSY_WEIGHT
# (varnish, glazed ceramic, plastic); a metal: the lobe alone, coloured by one of METAL_F0
# (linear RGB reflectance at normal incidence of common metals, rounded; the usual
# real-time-rendering tables). GGX alpha log-uniform in GLOSS_ALPHA for both.
GLOSSY_WEIGHT = (0.04, 0.3)
GLOSS_ALPHA = (0.08, 0.5)
METAL_F0 = {"silver": (0.97, 0.96, 0.91), "aluminium": (0.91, 0.92, 0.92), "gold": (1.0, 0.78, 0.34),
            "copper": (0.96, 0.64, 0.54), "brass": (0.91, 0.78, 0.42), "iron": (0.56, 0.57, 0.58),
            "chromium": (0.55, 0.56, 0.55), "nickel": (0.66, 0.61, 0.53)}


def _material_draws(rng: np.random.Generator, cfg: GeneratorConfig, obj: ObjectSpec) -> ObjectSpec:
    """One object's material draws (after all others): matte, glossy or metal."""
    u = rng.uniform()
    alpha = float(np.round(math.exp(rng.uniform(*np.log(GLOSS_ALPHA))), 4))
    if u < cfg.metal_fraction:
        f0 = list(METAL_F0.values())[int(rng.integers(0, len(METAL_F0)))]
        return dataclasses.replace(obj, gloss=1.0, gloss_alpha=alpha, gloss_rgb=f0)
    if u < cfg.metal_fraction + cfg.glossy_fraction:
        weight = float(np.round(rng.uniform(*GLOSSY_WEIGHT), 4))
        return dataclasses.replace(obj, gloss=weight, gloss_alpha=alpha, gloss_rgb=(1.0, 1.0, 1.0))
    return obj


def _flash_light(rng: np.random.Generator, cfg: GeneratorConfig, camera: CameraSpec,
                 light: LightSpec) -> LightSpec:
    """The light moved to a direction uniform on the spherical cap of half-angle
    ``flash_cone_deg`` around the direction from the scene centre to the camera, redrawn
    while it is below ``light_tilt_deg[0]`` (at most 100 draws; then the camera's own
    direction). Distance, colour and strength stay as drawn."""
    to_camera = frames.direction(camera.pan_deg, camera.tilt_deg)
    u, v = frames.perpendicular_pair(to_camera)
    cos_cone = math.cos(math.radians(cfg.flash_cone_deg))
    pan, tilt = camera.pan_deg, camera.tilt_deg
    for _ in range(100):
        cos_t = rng.uniform(cos_cone, 1.0)
        phi = rng.uniform(0.0, 2.0 * math.pi)
        d = cos_t * to_camera + math.sqrt(max(0.0, 1.0 - cos_t * cos_t)) * (math.cos(phi) * u + math.sin(phi) * v)
        _, p, t = frames.cartesian_to_spherical(d)
        if cfg.light_tilt_deg[0] <= float(t) <= 90.0:
            pan, tilt = float(p), float(t)
            break
    return dataclasses.replace(light, pan_deg=float(np.round(frames.wrap360(pan), 2)),
                               tilt_deg=float(np.round(tilt, 2)))


# --------------------------------------------------------------------------- --preset sid2-paper
# The paper group's colour protocol (what is known from its later public sets; not stated for
# SID2), beside relight's default rooms: geometry, camera and light directions as the default.
SID2_PAPER_PRESET: dict = {
    "light_colour": "tanner-helland",   # 2000-9900 K in 100 K steps, Tanner-Helland RGB (relight.colour)
    "backgrounds": textures.LIBRARY,    # one of 250 backgrounds, shared by train and test (textures)
    "colour_prior": "pastel",           # one pastel colour per object part (albedo)
    "object_parts": (1, 11),            # parts per object, uniform: median 6, as ShapeNet's
}


def sid2_paper_config(path: str | None = None, **overrides) -> GeneratorConfig:
    """The settings of ``relight generate --preset sid2-paper``: :data:`SID2_PAPER_PRESET`
    over the defaults, then the keys of a config file ``path``, then ``overrides`` that
    are not None (the command's explicit options; ``backgrounds="unseen"`` makes the same
    preset with backgrounds outside the library)."""
    return GeneratorConfig.from_file(path, preset="sid2-paper", **overrides)


def is_sid2_paper(config: dict) -> bool:
    """Whether a card's config (a dict) holds the preset's settings."""
    return all(json.dumps(config.get(k)) == json.dumps(list(v) if isinstance(v, tuple) else v)
               for k, v in SID2_PAPER_PRESET.items() if k != "backgrounds") \
        and config.get("backgrounds") in (textures.LIBRARY, textures.UNSEEN)


PRESETS["sid2-paper"] = SID2_PAPER_PRESET

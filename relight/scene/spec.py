"""Scene description: versioned, human-readable JSON that fully determines one render.

A scene file (format ``relight.scene/v1``) is the contract between the generator,
``relight render``, ``relight compare`` and the inverse-rendering baseline: the same
file, seed and machine give the same image, bit for bit.

Units: metres, degrees, linear Rec.709 RGB. Frames: see :mod:`relight.frames`.
Procedural textures and shapes are stored as their parameters (which determine them
exactly), never as pixels or vertices; user meshes are stored as a file path.
"""
from __future__ import annotations

__all__ = [
    "SCENE_FORMAT", "CameraSpec", "LightSpec", "RoomSpec", "BackdropSpec", "ObjectSpec", "SAMPLERS", "LEGACY_SAMPLER",
    "RenderSpec", "SceneSpec", "load_scene",
]

import dataclasses
import json
import math
import os
from dataclasses import dataclass, field

import numpy as np

from relight import frames
from relight.errors import SceneFileError
from relight.scene.shapes import MAX_PARTS as MAX_OBJECT_PARTS

SCENE_FORMAT = "relight.scene/v1"
# Documented limits of a scene file (docs/guarantees.md), checked when it is read, before
# any allocation: an image or texture of MAX_RES^2 float RGB pixels is 200 MB, far above
# any use here (the generator's default is 128 px); the command-line options have the same
# bounds (relight/commands/argtypes.py).
MAX_RES = 4096            # render.res and room.texture_res, pixels per side
MAX_SPP = 1 << 16         # render.spp
MAX_DEPTH = 64            # render.max_depth


def _finite(name: str, *values: float) -> None:
    for v in values:
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            raise SceneFileError(f"{name}: expected a finite number, got {v!r}")


@dataclass(frozen=True)
class CameraSpec:
    """Pinhole camera at spherical (r_m, pan_deg, tilt_deg), looking at the origin, up +Z."""
    tilt_deg: float
    r_m: float = 20.0
    pan_deg: float = 0.0
    fov_deg: float = 40.0  # horizontal field of view

    def __post_init__(self):
        _finite("camera", self.tilt_deg, self.r_m, self.pan_deg, self.fov_deg)
        if not -89.0 <= self.tilt_deg <= 89.0:
            raise SceneFileError(f"camera.tilt_deg must be in [-89, 89], got {self.tilt_deg}")
        if self.r_m <= 0 or not 1.0 <= self.fov_deg <= 170.0:
            raise SceneFileError(f"camera: r_m > 0 and fov_deg in [1, 170] expected, got "
                                 f"{self.r_m}, {self.fov_deg}")

    @property
    def position_m(self) -> np.ndarray:
        return frames.camera_position(self.tilt_deg, self.r_m, self.pan_deg)


@dataclass(frozen=True)
class LightSpec:
    """Point light at spherical (r_m, pan_deg, tilt_deg) with colour and strength.

    ``rgb`` is the unit-norm linear colour. ``strength`` is the irradiance the light
    gives at the scene centre on a surface facing it (W/m^2); the emitter's radiant
    intensity is ``strength * r_m**2 * sqrt(3) * rgb`` (W/sr), so exposure does not
    depend on the light's distance, and a white light has per-channel intensity
    ``strength * r_m**2``.

    ``ambient`` (optional, 0: none): a sky fill, a uniform environment of the light's
    colour whose radiance (:attr:`sky_radiance`) gives an unoccluded surface facing up
    ``ambient`` times the irradiance the light gives a surface facing it. The label is
    the point light, the dominant one.
    """
    r_m: float
    pan_deg: float
    tilt_deg: float
    rgb: tuple[float, float, float]
    strength: float = math.pi
    cct_k: float | None = None
    duv: float | None = None
    ambient: float = 0.0

    def __post_init__(self):
        _finite("light", self.r_m, self.pan_deg, self.tilt_deg, self.strength, self.ambient)
        if not 0.0 <= self.ambient <= 10.0:
            raise SceneFileError(f"light.ambient: expected a number in [0, 10], got {self.ambient!r}")
        rgb = tuple(float(c) for c in self.rgb)
        if len(rgb) != 3:
            raise SceneFileError(f"light.rgb: expected 3 numbers, got {self.rgb!r}")
        _finite("light.rgb", *rgb)
        if min(rgb) < 0 or max(rgb) <= 0:
            raise SceneFileError(f"light.rgb: expected non-negative, non-zero values, got {rgb}")
        norm = math.sqrt(sum(c * c for c in rgb))
        object.__setattr__(self, "rgb", tuple(c / norm for c in rgb))
        if self.r_m <= 0 or self.strength <= 0:
            raise SceneFileError("light: r_m and strength must be positive")

    @property
    def position_m(self) -> np.ndarray:
        return frames.spherical_to_cartesian(self.r_m, self.pan_deg, self.tilt_deg)

    @property
    def intensity(self) -> np.ndarray:
        """Radiant intensity per channel (W/sr) of the point emitter."""
        return self.strength * self.r_m ** 2 * math.sqrt(3.0) * np.asarray(self.rgb)

    @property
    def sky_radiance(self) -> np.ndarray:
        """Radiance per channel (W/(m^2 sr)) of the sky fill: ``ambient * strength *
        sqrt(3) * rgb / pi``, so that pi times it, the irradiance of a surface under the
        whole sky, is ``ambient`` times the light's own irradiance at the centre."""
        return self.ambient * self.strength * math.sqrt(3.0) * np.asarray(self.rgb) / math.pi


@dataclass(frozen=True)
class RoomSpec:
    """Regular ``n_walls``-sided room around the origin, no ceiling.

    Walls stand at distance ``inradius_m`` from the centre; with inradius >= 2 x the
    largest light distance, a light never gives a wall more irradiance than it gives
    the scene centre. ``rotation_deg`` turns the polygon about +Z. Each wall and the
    floor carry a procedural texture (parameters of :mod:`relight.scene.textures`),
    tiled ``wall_tiles`` times across a wall and every ``floor_tile_m`` metres.
    """
    n_walls: int
    inradius_m: float
    height_m: float
    rotation_deg: float
    wall_textures: tuple[dict, ...]
    floor_texture: dict
    texture_res: int = 128

    def __post_init__(self):
        if not isinstance(self.n_walls, int) or not 3 <= self.n_walls <= 12:
            raise SceneFileError(f"room.n_walls must be an integer in [3, 12], got {self.n_walls!r}")
        _finite("room", self.inradius_m, self.height_m, self.rotation_deg)
        if len(self.wall_textures) != self.n_walls:
            raise SceneFileError(f"room: {self.n_walls} walls but {len(self.wall_textures)} textures")
        object.__setattr__(self, "wall_textures", tuple(dict(t) for t in self.wall_textures))
        res = self.texture_res
        if not isinstance(res, int) or isinstance(res, bool) or not 1 <= res <= MAX_RES:
            raise SceneFileError(f"room.texture_res: expected an integer in [1, {MAX_RES}], got {res!r}")


@dataclass(frozen=True)
class BackdropSpec:
    """A studio backdrop: one upright grey rectangle standing on the floor close behind
    the objects (optional; a scene without one has no field and renders as before).

    Its centre line is at horizontal distance ``distance_m`` from the scene centre in the
    direction ``pan_deg`` (world frame, as a light's pan); it faces the centre, is
    ``2 * half_width_m`` wide and ``height_m`` tall, and reflects diffusely with the grey
    albedo ``albedo`` (black velvet 0.01, dark grey card 0.1-0.2).
    """
    pan_deg: float
    distance_m: float
    half_width_m: float
    height_m: float
    albedo: float

    def __post_init__(self):
        _finite("backdrop", self.pan_deg, self.distance_m, self.half_width_m, self.height_m, self.albedo)
        if min(self.distance_m, self.half_width_m, self.height_m) <= 0 or not 0.0 <= self.albedo <= 1.0:
            raise SceneFileError("backdrop: distance_m, half_width_m and height_m > 0 and albedo in [0, 1] "
                                 "expected")

    def to_world(self) -> np.ndarray:
        """4x4 matrix placing Mitsuba's ``rectangle`` ([-1,1]^2, normal +z) as the
        backdrop: normal toward the scene centre, bottom edge on the floor."""
        return frames.upright_rectangle_to_world(self.pan_deg, self.distance_m, self.half_width_m, self.height_m)

    def blocks(self, start_m, end_m) -> bool:
        """Whether the segment from ``start_m`` to ``end_m`` (world points, metres)
        passes through the backdrop."""
        m = self.to_world()
        centre, normal = m[:3, 3], m[:3, 2]
        a, b = np.asarray(start_m, float), np.asarray(end_m, float)
        da, db = float((a - centre) @ normal), float((b - centre) @ normal)
        if da * db > 0 or da == db:   # both ends on one side (or the segment in the plane)
            return False
        local = a + (b - a) * (da / (da - db)) - centre
        across = local @ (m[:3, 0] / self.half_width_m)
        along_up = local @ (m[:3, 1] / (self.height_m / 2.0))
        return abs(across) <= self.half_width_m and abs(along_up) <= self.height_m / 2.0


@dataclass(frozen=True)
class ObjectSpec:
    """One object resting on the floor.

    The mesh (procedural ``family`` + ``params``, or ``mesh_path`` for a user file) is
    normalised in object space (centred on the z axis, min z = 0, max horizontal radius
    1), then scaled uniformly by ``size_m``, turned by ``yaw_deg`` about +Z and moved
    to ``position_m`` = (x, y) on the floor. Material: rough diffuse (Oren-Nayar), or,
    with ``gloss`` > 0, that diffuse blended with a specular lobe.

    ``gloss`` (optional, 0: none): weight w of a GGX microfacet mirror lobe (Fresnel
    factor 1) of colour ``gloss_rgb`` and GGX alpha ``gloss_alpha``; the material is
    ``(1 - w) * diffuse + w * specular`` (Mitsuba's ``blendbsdf``; Cycles' Mix Shader of
    Diffuse and Glossy). A varnished or plastic object: small w, white ``gloss_rgb``; a
    metal: w = 1 and a metal's reflectance as ``gloss_rgb``.

    ``part_reflectances`` (optional, the paper's "random color ... for each mesh texture in
    each object"): K >= 2 linear-RGB albedos; the mesh faces are split into K patches
    (:func:`relight.scene.shapes.part_labels`) and patch j gets entry j. Empty: the whole
    object has ``reflectance`` (which is entry 0 when parts are given).
    """
    family: str
    params: dict
    position_m: tuple[float, float]
    yaw_deg: float
    size_m: float
    reflectance: tuple[float, float, float]
    roughness: float
    mesh_path: str | None = None
    part_reflectances: tuple[tuple[float, float, float], ...] = ()
    gloss: float = 0.0
    gloss_alpha: float = 0.1
    gloss_rgb: tuple[float, float, float] = (1.0, 1.0, 1.0)

    def __post_init__(self):
        _finite("object", *self.position_m, self.yaw_deg, self.size_m, *self.reflectance, self.roughness)
        if not isinstance(self.gloss_rgb, (list, tuple)) or len(self.gloss_rgb) != 3:
            raise SceneFileError("object: gloss_rgb needs 3 numbers")
        object.__setattr__(self, "gloss_rgb", tuple(float(v) for v in self.gloss_rgb))
        _finite("object gloss", self.gloss, self.gloss_alpha, *self.gloss_rgb)
        if not (0 <= self.gloss <= 1 and 0.001 <= self.gloss_alpha <= 1 and all(0 <= v <= 1 for v in self.gloss_rgb)):
            raise SceneFileError("object: gloss and gloss_rgb in [0, 1], gloss_alpha in [0.001, 1] expected")
        object.__setattr__(self, "position_m", tuple(float(v) for v in self.position_m))
        object.__setattr__(self, "reflectance", tuple(float(v) for v in self.reflectance))
        if len(self.position_m) != 2 or len(self.reflectance) != 3:
            raise SceneFileError("object: position_m needs 2 numbers and reflectance 3")
        if not 0 <= self.roughness <= 1 or self.size_m <= 0 or not all(0 <= c <= 1 for c in self.reflectance):
            raise SceneFileError("object: roughness and reflectance in [0, 1], size_m > 0 expected")
        parts = self.part_reflectances
        if not isinstance(parts, (list, tuple)) or any(not isinstance(c, (list, tuple)) or len(c) != 3
                                                       for c in parts):
            raise SceneFileError("object: part_reflectances must be a list of [r, g, b] albedos")
        parts = tuple(tuple(float(v) for v in c) for c in parts)
        _finite("object part", *(v for c in parts for v in c))
        if len(parts) == 1 or len(parts) > MAX_OBJECT_PARTS or not all(0 <= v <= 1 for c in parts for v in c):
            raise SceneFileError(f"object: part_reflectances needs 2-{MAX_OBJECT_PARTS} albedos in [0, 1] "
                                 f"(or none), got {len(parts)}")
        object.__setattr__(self, "part_reflectances", parts)

    @property
    def colours(self) -> tuple[tuple[float, float, float], ...]:
        """The albedo of each part (one entry, ``reflectance``, for a one-colour object)."""
        return self.part_reflectances or (self.reflectance,)


SAMPLERS = ("independent", "stratified", "multijitter", "orthogonal", "ldsampler")
LEGACY_SAMPLER = "independent"   # scene files written before ``render.sampler`` existed


@dataclass(frozen=True)
class RenderSpec:
    """Image size (square, pixels), samples per pixel, path depth, sampler seed and
    Mitsuba sampler plugin (one of :data:`SAMPLERS`).

    A file without ``sampler`` was written when relight always used ``independent``:
    reading it gives that sampler, so old files re-render bit for bit.
    """
    res: int = 128
    spp: int = 64
    max_depth: int = 4
    seed: int = 0
    sampler: str = LEGACY_SAMPLER

    def __post_init__(self):
        for name in ("res", "spp", "max_depth", "seed"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < (0 if name == "seed" else 1):
                raise SceneFileError(f"render.{name}: expected a positive integer, got {v!r}")
        if self.seed >= 2 ** 32:
            raise SceneFileError("render.seed must fit in 32 bits")
        for name, hi in (("res", MAX_RES), ("spp", MAX_SPP), ("max_depth", MAX_DEPTH)):
            if getattr(self, name) > hi:
                raise SceneFileError(f"render.{name}: at most {hi} (the documented limit), got {getattr(self, name)}")
        if self.sampler not in SAMPLERS:
            raise SceneFileError(f"render.sampler: expected one of {', '.join(SAMPLERS)}, got {self.sampler!r}")


@dataclass(frozen=True)
class SceneSpec:
    """Everything that determines one image."""
    id: str
    camera: CameraSpec
    light: LightSpec
    room: RoomSpec
    objects: tuple[ObjectSpec, ...]
    render: RenderSpec = field(default_factory=RenderSpec)
    colour_prior: str | None = None   # surface-colour prior that drew the albedos (metadata)
    backdrop: BackdropSpec | None = None   # a studio backdrop close behind the objects (optional)
    format: str = SCENE_FORMAT

    def __post_init__(self):
        if self.format != SCENE_FORMAT:
            raise SceneFileError(f"unknown scene format {self.format!r}, expected {SCENE_FORMAT!r}")
        object.__setattr__(self, "objects", tuple(self.objects))
        if self.colour_prior is not None and not isinstance(self.colour_prior, str):
            raise SceneFileError(f"colour_prior: expected a name or null, got {self.colour_prior!r}")

    @property
    def pan_rel_deg(self) -> float:
        return float(frames.pan_rel_deg(self.light.pan_deg, self.camera.pan_deg))

    def with_light(self, pan_rel_deg: float | None = None, tilt_deg: float | None = None,
                   rgb=None) -> "SceneSpec":
        """The same scene under another light (direction relative to the camera; colour
        unit-normalised); distance and strength are kept."""
        light = self.light
        changes = {}
        if pan_rel_deg is not None:
            changes["pan_deg"] = float(frames.pan_from_rel(float(pan_rel_deg), self.camera.pan_deg))
        if tilt_deg is not None:
            changes["tilt_deg"] = float(tilt_deg)
        if rgb is not None:
            changes.update(rgb=tuple(float(c) for c in rgb), cct_k=None, duv=None)
        return dataclasses.replace(self, light=dataclasses.replace(light, **changes))

    # --- JSON ---------------------------------------------------------------------
    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        if d["backdrop"] is None:   # no backdrop: no field, as in files written before it
            del d["backdrop"]
        if not d["light"]["ambient"]:   # no sky fill: no field, as in files written before it
            del d["light"]["ambient"]
        for o in d["objects"]:   # one-colour, matte objects: no fields, as in files written before them
            if not o["part_reflectances"]:
                del o["part_reflectances"]
            if not o["gloss"]:
                del o["gloss"], o["gloss_alpha"], o["gloss_rgb"]
        return {"format": d.pop("format"), **d}

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1, sort_keys=False)

    @classmethod
    def from_dict(cls, d: dict) -> "SceneSpec":
        if not isinstance(d, dict):
            raise SceneFileError("a scene file must hold a JSON object")
        if d.get("format") != SCENE_FORMAT:
            raise SceneFileError(f"unknown scene format {d.get('format')!r}, expected {SCENE_FORMAT!r}")
        try:
            room = dict(d["room"])
            room["wall_textures"] = tuple(room["wall_textures"])
            return cls(
                id=str(d["id"]),
                camera=CameraSpec(**d["camera"]),
                light=LightSpec(**{**d["light"], "rgb": tuple(d["light"]["rgb"])}),
                room=RoomSpec(**room),
                objects=tuple(ObjectSpec(**{**o, "position_m": tuple(o["position_m"]),
                                            "reflectance": tuple(o["reflectance"])})
                              for o in d["objects"]),
                render=RenderSpec(**d.get("render", {})),
                colour_prior=d.get("colour_prior"),
                backdrop=None if d.get("backdrop") is None else BackdropSpec(**d["backdrop"]),
            )
        except (KeyError, TypeError) as exc:
            raise SceneFileError(f"malformed scene description: {exc}") from None

    @classmethod
    def from_json(cls, text: str) -> "SceneSpec":
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise SceneFileError(f"scene file is not valid JSON: {exc}") from None
        return cls.from_dict(d)

    def save(self, path: str | os.PathLike) -> None:
        """Write atomically (temporary file, then rename)."""
        from relight.fileio import write_text
        write_text(os.fspath(path), self.to_json())


def load_scene(path: str | os.PathLike) -> SceneSpec:
    """Read a scene file; :class:`SceneFileError` names the file on any problem.

    A relative ``mesh_path`` is taken relative to the scene file's folder, so a
    scene and its meshes can be moved together (``scenes/meshes/``).

    Args:
        path: a ``relight.scene/v1`` JSON file.

    Returns:
        The :class:`SceneSpec`: camera and light (metres, degrees, linear unit-norm
        ``rgb``), room, objects and render settings (``res`` pixels, ``spp``, seed).

    >>> import os, relight
    >>> spec = load_scene(os.path.join(os.path.dirname(relight.__file__), "..", "scenes", "sphere_right.json"))
    >>> spec.light.pan_deg, spec.light.tilt_deg, spec.camera.tilt_deg, spec.render.res
    (90.0, 30.0, 30.0, 128)
    """
    try:
        with open(path) as f:
            text = f.read()
    except OSError as exc:
        raise SceneFileError(f"cannot read scene file {os.fspath(path)}: {exc.strerror}") from None
    try:
        spec = SceneSpec.from_json(text)
    except SceneFileError as exc:
        raise SceneFileError(f"{os.fspath(path)}: {exc}") from None
    folder = os.path.dirname(os.path.abspath(os.fspath(path)))
    if any(o.mesh_path and not os.path.isabs(o.mesh_path) for o in spec.objects):
        spec = dataclasses.replace(spec, objects=tuple(
            dataclasses.replace(o, mesh_path=os.path.join(folder, o.mesh_path))
            if o.mesh_path and not os.path.isabs(o.mesh_path) else o for o in spec.objects))
    return spec

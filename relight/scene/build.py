"""Turn a :class:`SceneSpec` into a Mitsuba scene, reusing loaded scenes.

Loading a scene (``mi.load_dict``) and compiling its kernels costs more than a render
at our sizes, so a :class:`SceneTemplate` loads one scene per *structure* (image size,
path depth, mesh topologies; rooms of up to 8 walls share 8 wall slots) and every spec of that structure is
written into it through ``mi.traverse``: wall/floor texture pixels, object vertex
buffers and materials (a per-face albedo attribute, so multi-coloured objects need no
extra BSDFs; scenes with a glossy object get templates whose object BSDFs blend the
diffuse with a GGX lobe, so matte scenes render exactly as before), camera pose and field of view, light position and intensity.
None of these is a kernel literal, so nothing recompiles. Procedural shapes all share
one mesh topology (:mod:`relight.scene.shapes`), so they share templates.

Unused object and wall slots are shrunk to a point 1 km below the floor, where no
camera or light ray reaches them. Fewer live scenes also keep renders fast: Dr.Jit's
virtual calls dispatch over every live BSDF and shape, so each extra loaded scene
makes every render a little slower (about 10% for five rooms measured here).

:func:`build_naive` builds a fresh template for one spec: the straightforward way,
kept for the benchmark and as the readable reference of what a template holds.
"""
from __future__ import annotations

__all__ = [
    "N_OBJECT_SLOTS", "N_WALL_SLOTS", "MASK_SUBSAMPLES", "FLOOR_HALF_SIZE_M", "FLOOR_TILE_M", "HIDDEN_DEPTH_M", "FACE_ALBEDO",
    "TemplateKey", "object_mesh", "template_key", "wall_to_world", "face_albedos", "part_labels",
    "SceneTemplate", "texture", "SceneBuilder", "build_naive", "render_spec",
]

import functools
import math
import os
from dataclasses import dataclass

import numpy as np

from relight import backend, frames, render
from relight.timing import NO_TIMER
from relight.scene import bsdf as rough_bsdf
from relight.scene import shapes, textures
from relight.scene.spec import ObjectSpec, SceneFileError, SceneSpec
from relight.errors import brief

N_OBJECT_SLOTS = 3          # the generator places 1-3 objects
N_WALL_SLOTS = 8            # rooms of up to 8 walls share one loaded scene
FLOOR_HALF_SIZE_M = 400.0   # floor square reaches past every wall corner
FLOOR_TILE_M = 10.0         # the floor texture repeats every 10 m
HIDDEN_DEPTH_M = -1000.0    # where unused object slots are parked
FACE_ALBEDO = "face_albedo"  # per-face mesh attribute read by the object BSDFs (parts)
MASK_SUBSAMPLES = 4         # object masks: 4 x 4 primary rays per pixel (coverage in steps of 1/16)


@dataclass(frozen=True)
class TemplateKey:
    """What forces a new Mitsuba scene: anything that changes kernel or buffer shapes."""
    wall_slots: int
    res: int
    max_depth: int
    texture_res: int
    slots: tuple[tuple[int, int], ...]  # (vertex count, face count) per object slot
    sampler: str = "independent"        # Mitsuba sampler plugin (render.sampler)
    envmap_shape: tuple[int, int] | None = None   # (H, W): an ``envmap`` emitter, no point light
    glossy: bool = False    # object BSDFs blend the diffuse with a specular lobe (some object has gloss)
    sky: bool = False       # a uniform environment emitter (the light's sky fill, ``light.ambient`` > 0)
    backdrop: bool = False  # a studio backdrop rectangle (``spec.backdrop``); scenes without one: no shape


def object_mesh(obj: ObjectSpec) -> shapes.Mesh:
    """Object-space mesh of an object (normalised: centred, min z 0, max radius 1)."""
    if obj.mesh_path is not None:
        return _user_mesh(obj.mesh_path)
    try:
        return _procedural_mesh(obj.family, _freeze(obj.params))
    except (ValueError, KeyError, TypeError) as exc:
        raise SceneFileError(f"object {obj.family!r}: {exc}") from None


def _freeze(d):
    if isinstance(d, dict):
        return tuple(sorted((k, _freeze(v)) for k, v in d.items()))
    if isinstance(d, list):
        return tuple(_freeze(v) for v in d)
    return d


def _thaw(t):
    if isinstance(t, tuple) and all(isinstance(i, tuple) and len(i) == 2 and isinstance(i[0], str) for i in t) and t:
        return {k: _thaw(v) for k, v in t}
    if isinstance(t, tuple):
        return [_thaw(v) for v in t]
    return t


@functools.lru_cache(maxsize=64)
def _procedural_mesh(family: str, frozen_params) -> shapes.Mesh:
    return shapes.make_mesh(family, _thaw(frozen_params))


@functools.lru_cache(maxsize=32)
def _user_mesh(path: str) -> shapes.Mesh:
    """Load an OBJ or PLY file (taken as z-up) and normalise it like procedural shapes."""
    ext = os.path.splitext(path)[1].lower()
    if ext not in (".obj", ".ply"):
        raise SceneFileError(f"mesh {path}: expected a .obj or .ply file")
    if not os.path.isfile(path):
        raise SceneFileError(f"mesh {path}: file not found")
    mi = backend.mitsuba()
    try:
        mesh = mi.load_dict({"type": ext[1:], "filename": path, "face_normals": True})
    except Exception as exc:  # noqa: BLE001 - Mitsuba raises RuntimeError with its own text
        raise SceneFileError(f"mesh {path}: cannot be loaded ({brief(exc)})") from None
    p = mi.traverse(mesh)
    v = np.array(p["vertex_positions"], dtype=np.float64).reshape(-1, 3)
    f = np.array(p["faces"], dtype=np.uint32).reshape(-1, 3)
    if len(v) < 3 or len(f) < 1 or not np.isfinite(v).all():
        raise SceneFileError(f"mesh {path}: empty or non-finite geometry")
    lo, hi = v.min(0), v.max(0)
    v = v - np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    radius = np.hypot(v[:, 0], v[:, 1]).max()
    if radius <= 0:
        raise SceneFileError(f"mesh {path}: degenerate (no horizontal extent)")
    v = (v / radius).astype(np.float32)
    uv = np.zeros((len(v), 2), np.float32)
    return shapes.Mesh(vertices=v, faces=f, normals=shapes.vertex_normals(v, f), uv=uv)


def template_key(spec: SceneSpec, meshes: list[shapes.Mesh],
                 envmap_shape: tuple[int, int] | None = None) -> TemplateKey:
    slots = [(len(m.vertices), len(m.faces)) for m in meshes]
    while len(slots) < N_OBJECT_SLOTS:
        slots.append(slots[0] if slots else (shapes.DEFAULT_NU * shapes.DEFAULT_NV, 0))
    return TemplateKey(max(N_WALL_SLOTS, spec.room.n_walls), spec.render.res, spec.render.max_depth,
                       spec.room.texture_res, tuple(slots), spec.render.sampler,
                       None if envmap_shape is None else (int(envmap_shape[0]), int(envmap_shape[1])),
                       any(o.gloss > 0 for o in spec.objects), envmap_shape is None and spec.light.ambient > 0,
                       spec.backdrop is not None)


def wall_to_world(k: int, n_walls: int, inradius_m: float, height_m: float,
                  rotation_deg: float) -> np.ndarray:
    """4x4 matrix placing Mitsuba's ``rectangle`` ([-1,1]^2, normal +z) as wall ``k``,
    its normal facing the room centre (:func:`relight.frames.upright_rectangle_to_world`)."""
    return frames.upright_rectangle_to_world(rotation_deg + k * 360.0 / n_walls, inradius_m,
                                             inradius_m * math.tan(math.pi / n_walls), height_m)


def face_albedos(obj: ObjectSpec, mesh: shapes.Mesh) -> np.ndarray:
    """``(F, 3)`` float32 albedo of each face: ``obj.reflectance`` everywhere, or part j's
    colour on the faces of part j (:func:`relight.scene.shapes.part_labels`)."""
    colours = np.asarray(obj.colours, np.float32)
    if len(colours) == 1:
        return np.broadcast_to(colours[0], (len(mesh.faces), 3)).copy()
    return colours[part_labels(mesh, len(colours))]


@functools.lru_cache(maxsize=64)
def part_labels(mesh: shapes.Mesh, n_parts: int) -> np.ndarray:
    """:func:`relight.scene.shapes.part_labels`, cached (a Mesh hashes by identity, and
    :func:`object_mesh` returns cached meshes)."""
    return shapes.part_labels(mesh, n_parts)


def _object_vertices(obj: ObjectSpec, mesh: shapes.Mesh) -> tuple[np.ndarray, np.ndarray]:
    """World-space vertices and normals of an object: scale, yaw about +Z, translate."""
    rot = frames.rotation_z(obj.yaw_deg)
    v = (mesh.vertices.astype(np.float64) * obj.size_m) @ rot.T
    v[:, 0] += obj.position_m[0]
    v[:, 1] += obj.position_m[1]
    n = mesh.normals.astype(np.float64) @ rot.T
    return v.astype(np.float32), n.astype(np.float32)


class SceneTemplate:
    """One loaded Mitsuba scene of a fixed structure, updated in place per spec."""

    def __init__(self, key: TemplateKey):
        mi = backend.mitsuba()
        rough_bsdf.register()
        self.key = key
        tex = np.full((key.texture_res, key.texture_res, 3), 0.5, np.float32)

        def bitmap(to_uv=None):
            d = {"type": "bitmap", "data": mi.TensorXf(tex), "raw": True,
                 "filter_type": "bilinear", "wrap_mode": "repeat"}
            if to_uv is not None:
                d["to_uv"] = to_uv
            return d

        scene = {
            "type": "scene",
            "integrator": {"type": "path", "max_depth": key.max_depth},
            "sensor": render.sensor(key.res, 40.0, key.sampler, mi.ScalarTransform4f().look_at(
                origin=[20, 0, 5], target=[0, 0, 0], up=[0, 0, 1])),   # pose and fov: set by apply
            "light": {"type": "point", "position": [0.0, 0.0, 30.0],
                      "intensity": {"type": "rgb", "value": [1.0, 1.0, 1.0]}} if key.envmap_shape is None
            else {"type": "envmap", "bitmap": mi.Bitmap(np.ones((*key.envmap_shape, 3), np.float32))},
            "floor": {"type": "rectangle",
                      "to_world": mi.ScalarTransform4f().scale([FLOOR_HALF_SIZE_M, FLOOR_HALF_SIZE_M, 1.0]),
                      "bsdf": {"type": "diffuse", "reflectance": bitmap(
                          mi.ScalarTransform3f().scale(2.0 * FLOOR_HALF_SIZE_M / FLOOR_TILE_M))}},
        }
        if key.sky:
            scene["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
        for k in range(key.wall_slots):
            scene[f"wall{k}"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f(np.eye(4)),
                                 "bsdf": {"type": "diffuse", "reflectance": bitmap()}}
        if key.backdrop:
            scene["backdrop"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f(np.eye(4)),
                                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5] * 3}}}
        for i, (n_vertices, n_faces) in enumerate(key.slots):
            props = mi.Properties()
            diffuse = {"type": rough_bsdf.PLUGIN, "roughness": 0.5,
                       "reflectance": {"type": "mesh_attribute", "name": FACE_ALBEDO}}
            props["bsdf"] = mi.load_dict(diffuse if not key.glossy else {
                "type": "blendbsdf", "weight": 0.0, "bsdf_0": diffuse,
                "bsdf_1": {"type": "roughconductor", "material": "none", "distribution": "ggx",
                           "alpha": 0.1, "specular_reflectance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}})
            mesh = mi.Mesh(f"obj{i}", n_vertices, max(n_faces, 1), props=props,
                           has_vertex_normals=True, has_vertex_texcoords=False)
            mesh.add_attribute(FACE_ALBEDO, 3, [0.5] * (3 * max(n_faces, 1)))
            scene[f"obj{i}"] = mesh
        self.scene = mi.load_dict(scene)
        self.params = mi.traverse(self.scene)
        self._faces_written = [None] * len(key.slots)

    def apply(self, spec: SceneSpec, meshes: list[shapes.Mesh], timer=NO_TIMER) -> None:
        """Write ``spec`` (with its object meshes, in order) into the loaded scene
        (``timer``: a :class:`~relight.timing.StageTimer` for the two steps)."""
        with timer.stage("template: parameters"):
            self._write_params(spec, meshes)
        with timer.stage("template: update + acceleration structure", sync=True):
            self.params.update()

    def _write_params(self, spec: SceneSpec, meshes: list[shapes.Mesh]) -> None:
        mi = backend.mitsuba()
        p = self.params
        cam = spec.camera
        p["sensor.to_world"] = mi.AffineTransform4f(
            frames.mitsuba_sensor_to_world(cam.tilt_deg, cam.r_m, cam.pan_deg))
        p["sensor.x_fov"] = cam.fov_deg
        self.set_light(spec.light.position_m, spec.light.intensity)
        if self.key.sky:
            p["sky.radiance.value"] = mi.Color3f(*[float(c) for c in spec.light.sky_radiance])
        room = spec.room
        res = room.texture_res
        p["floor.bsdf.reflectance.data"] = mi.TensorXf(_texture(_freeze(room.floor_texture), res))
        for k in range(self.key.wall_slots):
            if k < room.n_walls:
                p[f"wall{k}.to_world"] = mi.AffineTransform4f(
                    wall_to_world(k, room.n_walls, room.inradius_m, room.height_m, room.rotation_deg))
                p[f"wall{k}.bsdf.reflectance.data"] = mi.TensorXf(_texture(_freeze(room.wall_textures[k]), res))
            else:  # park the unused wall slot: a 1 mm square far below the floor
                parked = np.diag([1e-3, 1e-3, 1.0, 1.0])
                parked[2, 3] = HIDDEN_DEPTH_M
                p[f"wall{k}.to_world"] = mi.AffineTransform4f(parked)
        if self.key.backdrop:
            p["backdrop.to_world"] = mi.AffineTransform4f(spec.backdrop.to_world())
            p["backdrop.bsdf.reflectance.value"] = mi.Color3f(*([float(spec.backdrop.albedo)] * 3))
        for i in range(len(self.key.slots)):
            if i < len(spec.objects):
                obj, mesh = spec.objects[i], meshes[i]
                v, n = _object_vertices(obj, mesh)
                faces = mesh.faces
                p[f"obj{i}.{FACE_ALBEDO}"] = mi.Float(face_albedos(obj, mesh).ravel())
                if self.key.glossy:
                    p[f"obj{i}.bsdf.bsdf_0.roughness"] = mi.Float(obj.roughness)
                    p[f"obj{i}.bsdf.weight.value"] = mi.Float(obj.gloss)
                    p[f"obj{i}.bsdf.bsdf_1.alpha.value"] = mi.Float(obj.gloss_alpha)
                    p[f"obj{i}.bsdf.bsdf_1.specular_reflectance.value"] = mi.Color3f(*obj.gloss_rgb)
                else:
                    p[f"obj{i}.bsdf.roughness"] = mi.Float(obj.roughness)
            else:  # park the unused slot: a tiny copy of slot 0 far below the floor
                v, n = _object_vertices(spec.objects[0], meshes[0]) if spec.objects else (None, None)
                n_vertices = self.key.slots[i][0]
                v = np.zeros((n_vertices, 3), np.float32) if v is None or len(v) != n_vertices else v
                v = (v - v.mean(0)) * 1e-3 + np.array([0.0, 0.0, HIDDEN_DEPTH_M], np.float32)
                n = np.tile(np.array([0.0, 0.0, 1.0], np.float32), (n_vertices, 1))
                faces = meshes[0].faces if spec.objects and len(meshes[0].faces) == self.key.slots[i][1] \
                    else np.zeros((max(self.key.slots[i][1], 1), 3), np.uint32)
            p[f"obj{i}.vertex_positions"] = mi.Float(v.ravel())
            p[f"obj{i}.vertex_normals"] = mi.Float(n.ravel())
            if self._faces_written[i] is None or not np.array_equal(self._faces_written[i], faces):
                p[f"obj{i}.faces"] = mi.UInt32(faces.astype(np.uint32).ravel())
                self._faces_written[i] = faces

    def set_light(self, position_m, intensity) -> None:
        """Move the point light and set its radiant intensity (W/sr per channel);
        call ``self.params.update()`` after (``apply`` does)."""
        mi = backend.mitsuba()
        if self.key.envmap_shape is not None:   # an environment-map scene has no point light
            return
        self.params["light.position"] = mi.Point3f(*[float(x) for x in position_m])
        self.params["light.intensity.value"] = mi.Color3f(*[float(x) for x in intensity])

    def render(self, spp: int, seed: int, timer=NO_TIMER) -> np.ndarray:
        """Render the current state: ``(res, res, 3)`` float32 linear RGB."""
        return render.render_scene(self.scene, spp, seed, self.key.sampler, timer=timer)

    def object_mask(self, subsamples: int = MASK_SUBSAMPLES) -> np.ndarray:
        """Each pixel's share ``(H, W)`` float32 in [0, 1] covered by the scene's objects
        as the camera sees them (the current state): a ``subsamples`` x ``subsamples``
        grid of primary rays per pixel, each counting when its first hit is an object
        (not a wall, the floor or a backdrop; parked slots lie below the floor). Exact
        in the limit, with no sampling noise (a fixed grid)."""
        mi = backend.mitsuba()
        sensor = self.scene.sensors()[0]
        w, h = (int(v) for v in sensor.film().size())
        n = int(subsamples)
        j, i = np.meshgrid(np.arange(h * n), np.arange(w * n), indexing="ij")
        uv = mi.Point2f(((i.ravel() + 0.5) / (w * n)).astype(np.float32),
                        ((j.ravel() + 0.5) / (h * n)).astype(np.float32))
        rays, _ = sensor.sample_ray(0.0, 0.5, uv, mi.Point2f(0.5, 0.5))
        hit_shape = self.scene.ray_intersect(rays).shape
        on_object = mi.Bool(False)
        objects = {f"obj{i}" for i in range(len(self.key.slots))}
        for shape in self.scene.shapes():
            if shape.id() in objects:
                on_object |= hit_shape == mi.ShapePtr(shape)
        hits = np.array(on_object, dtype=np.float32).reshape(h, n, w, n)
        return hits.mean(axis=(1, 3))

    def render_under(self, position_m, intensity, spp: int, seed: int) -> np.ndarray:
        """Move the point light to ``position_m`` with radiant ``intensity`` (W/sr per
        channel), then render as :meth:`render`; the light stays there."""
        self.set_light(position_m, intensity)
        self.params.update()
        return self.render(spp, seed)

    def render_under_envmap(self, envmap, to_world, spp: int, seed: int) -> np.ndarray:
        """Light the scene by an equirectangular map instead (a template made with
        ``envmap_shape``): ``envmap`` ``(H, W, 3)`` linear radiance in Mitsuba's
        ``envmap`` layout (:func:`relight.verify.envmap.mitsuba_layout`), ``to_world`` its 4x4 (:func:`relight.frames.mitsuba_envmap_to_world`);
        then render as :meth:`render`."""
        mi = backend.mitsuba()
        envmap = np.asarray(envmap, np.float32)
        if self.key.envmap_shape is None or envmap.shape != (*self.key.envmap_shape, 3):
            raise ValueError(f"this template holds a {self.key.envmap_shape} map, got {envmap.shape}")
        # the plugin stores the map with one wrapped column on each side (periodic in u)
        padded = np.concatenate([envmap[:, -1:], envmap, envmap[:, :1]], axis=1)
        self.params["light.data"] = mi.TensorXf(np.ascontiguousarray(padded))
        self.params["light.to_world"] = mi.AffineTransform4f(np.asarray(to_world, np.float64))
        self.params.update()
        return self.render(spp, seed)


def texture(params: dict, size: int) -> np.ndarray:
    """Pixels ``(size, size, 3)`` float32 of a procedural texture (cached)."""
    return _texture(_freeze(params), size)


@functools.lru_cache(maxsize=128)
def _texture(frozen_params, size: int) -> np.ndarray:
    return textures.make_texture(_thaw(frozen_params), size).astype(np.float32)


class SceneBuilder:
    """Renders specs, keeping one :class:`SceneTemplate` per structure it meets."""

    def __init__(self, max_templates: int = 16):
        self._templates: dict[TemplateKey, SceneTemplate] = {}
        self.max_templates = max_templates

    def template_for(self, spec: SceneSpec, envmap_shape: tuple[int, int] | None = None) -> SceneTemplate:
        """The template holding ``spec`` (applied), loading one if this structure is new;
        with ``envmap_shape`` (H, W) one lit by an environment map of that size instead."""
        return self.template(spec, [object_mesh(o) for o in spec.objects], envmap_shape)

    def template(self, spec: SceneSpec, meshes: list[shapes.Mesh],
                 envmap_shape: tuple[int, int] | None = None, timer=NO_TIMER) -> SceneTemplate:
        """Like :meth:`template_for` with the object meshes already made (``timer``: a
        :class:`~relight.timing.StageTimer`)."""
        if len(meshes) > N_OBJECT_SLOTS:
            raise SceneFileError(f"at most {N_OBJECT_SLOTS} objects per scene, got {len(meshes)}")
        key = template_key(spec, meshes, envmap_shape)
        template = self._templates.get(key)
        if template is None:
            if len(self._templates) >= self.max_templates:
                self._templates.pop(next(iter(self._templates)))
            with timer.stage("template: load (new structure)", sync=True):
                template = self._templates[key] = SceneTemplate(key)
        template.apply(spec, meshes, timer)
        return template

    def render(self, spec: SceneSpec) -> np.ndarray:
        """Linear RGB image ``(res, res, 3)`` float32 of ``spec``."""
        return self.template_for(spec).render(spec.render.spp, spec.render.seed)


def build_naive(spec: SceneSpec) -> SceneTemplate:
    """A fresh scene for one spec (load_dict every time): the reference way."""
    meshes = [object_mesh(o) for o in spec.objects]
    template = SceneTemplate(template_key(spec, meshes))
    template.apply(spec, meshes)
    return template


_builder = None


def render_spec(spec: SceneSpec) -> np.ndarray:
    """Render a scene spec with a process-wide :class:`SceneBuilder` that reuses loaded
    scenes; returns linear ``(res, res, 3)`` float32.

    Args:
        spec: the scene (:func:`relight.scene.spec.load_scene`); its ``render`` settings
            (``res``, ``spp``, ``seed``, ``sampler``, ``max_depth``) decide the image.

    Returns:
        Linear RGB radiance, ``(res, res, 3)`` float32: the same pixels as the dataset's
        EXR of that scene file, bit for bit.

    The example scene at 16 pixels, and again under a light moved to the camera's left:

    >>> import dataclasses, os, relight
    >>> spec = relight.load_scene(os.path.join(os.path.dirname(relight.__file__), "..", "scenes",
    ...                                        "sphere_right.json"))
    >>> spec = dataclasses.replace(spec, render=dataclasses.replace(spec.render, res=16, spp=4))
    >>> image = render_spec(spec)
    >>> image.shape, image.dtype.name, bool(image.mean() > 0)
    ((16, 16, 3), 'float32', True)
    >>> bool(np.array_equal(render_spec(spec), image))   # same seed: the same image
    True
    """
    global _builder
    if _builder is None:
        _builder = SceneBuilder()
    return _builder.render(spec)

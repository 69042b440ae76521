"""The same scene file in Blender Cycles (the paper's renderer), for side-by-side checks.

:func:`export_blender` builds a :class:`~relight.scene.spec.SceneSpec` with ``bpy``
exactly as :mod:`relight.scene.build` builds it for Mitsuba:

* floor and walls: flat quads with the same corners and UVs as Mitsuba's ``rectangle``
  (``uv = ((x + 1) / 2, (y + 1) / 2)`` in its local [-1, 1]^2, the floor's UVs scaled so
  the texture repeats every ``FLOOR_TILE_M``), Lambert (Diffuse BSDF, roughness 0); a
  studio backdrop (``spec.backdrop``): one more such quad, of its uniform grey albedo;
* textures: float images used as data ("Non-Color", Mitsuba's ``raw: True``), bilinear,
  repeating; texture row 0 at v = 0 in both renderers;
* objects: the same world-space vertices and per-vertex normals (custom normals,
  smooth shading), Diffuse BSDF with the scene's roughness as its ``Roughness`` (both
  are Fujii's Oren-Nayar with sigma = roughness; see :data:`DIFFERENCES`); a glossy
  object (``gloss`` > 0) mixes it with a GGX Glossy BSDF (Mix Shader, factor ``gloss``,
  Roughness = sqrt(``gloss_alpha``)), as Mitsuba's ``blendbsdf`` of the diffuse and a
  ``roughconductor`` with Fresnel factor 1;
* camera: the same pose (Blender's camera frame is x right, y up, looking down -z,
  i.e. :func:`relight.frames.camera_to_world`) and horizontal field of view;
* point light: radius 0, power from :func:`point_light_power` (same radiant intensity);
* integrator: ``max_bounces = max_depth - 2`` (:func:`cycles_max_bounces`), box pixel
  filter 1 px wide, Sobol-Burley sampling, no adaptive sampling, denoising, clamping,
  light tree or light threshold; black world (the sky fill's radiance when
  ``light.ambient`` > 0, Mitsuba's ``constant`` emitter); "Standard" view, linear float output.

``bpy`` (PyPI, ``relight[blender]``) needs its own Python 3.11 environment (it pins
numpy < 2); only this module's functions that say so import it, and the rest of relight
reaches it through :func:`blender_python` / ``python -m relight.scene.blender`` in that
environment. Only numpy-only parts of relight are imported on the bpy side.
"""
from __future__ import annotations

__all__ = [
    "BLENDER_VENV_ENV", "DEFAULT_BLENDER_VENV", "INSTALL_HINT", "SAMPLING_PATTERN", "DIFFERENCES",
    "point_light_power", "point_light_intensity", "cycles_max_bounces", "rectangle_quad", "export_blender",
    "render_cycles", "blender_python", "run_blender_module", "CyclesWorker", "main", "export_and_render",
    "relative_rmse",
]

import contextlib
import json
import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from relight import frames
from relight.children import child_env, die_with_parent
from relight.scene.spec import SceneSpec
from relight.errors import BlenderError

BLENDER_VENV_ENV = "RELIGHT_BLENDER_PYTHON"     # python of an environment with bpy
DEFAULT_BLENDER_VENV = os.path.join("~", "relight-bpy-venv")  # scripts/setup_blender.sh
INSTALL_HINT = ("bpy is not installed: run scripts/setup_blender.sh (a separate Python 3.11 "
                "environment with relight[blender], i.e. bpy==5.0.1 and numpy<2), or set "
                f"{BLENDER_VENV_ENV} to a python that can import bpy")
SAMPLING_PATTERN = "SOBOL_BURLEY"

# What cannot be made identical in Blender 5.0 and why (measured in benchmarks/bench_cycles.py).
DIFFERENCES = (
    "Cycles >= 4.3 adds an energy-compensating multiple-scattering term (OpenPBR's EON) to "
    "Fujii's Oren-Nayar for roughness > 0; relight's roughdiffuse (like Cycles <= 4.2) has "
    "only the single-scattering term, so rough bright objects are brighter in Cycles.",
    "Cycles' Glossy BSDF (GGX) compensates multiple scattering between microfacets; Mitsuba's "
    "roughconductor does not, so rough glossy lobes (large gloss_alpha) are a little brighter in Cycles.",
)


# --------------------------------------------------------------------------- units (pure)
def point_light_power(intensity_w_sr) -> tuple[float, tuple[float, float, float]]:
    """Blender point-light ``energy`` (W) and ``color`` giving radiant intensity ``intensity_w_sr``.

    Cycles turns a point light of power P (radius 0) into radiant intensity
    ``I = P color / (4 pi)`` W/sr (``eval_fac = 1 / (pi * area)`` with the radius-0 area
    stand-in 4, in ``scene/light.cpp``), the isotropic emitter's flux-to-intensity
    relation, and Mitsuba's ``point`` emitter takes ``intensity`` in W/sr directly. So
    ``P = 4 pi max(I)`` and ``color = I / max(I)`` (in [0, 1]).

    Args: intensity_w_sr: 3 non-negative per-channel intensities, not all zero.
    Returns: (power in W, colour triple).
    """
    i = np.asarray(intensity_w_sr, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(i)) or i.min() < 0 or i.max() <= 0:
        raise ValueError(f"point light intensity: expected 3 finite values >= 0, not all 0, got {i}")
    peak = float(i.max())
    return 4.0 * math.pi * peak, tuple(float(c) for c in i / peak)


def point_light_intensity(power_w: float, color) -> np.ndarray:
    """Radiant intensity (W/sr per channel) of a Cycles point light (radius 0): the
    inverse of :func:`point_light_power`."""
    return float(power_w) * np.asarray(color, dtype=np.float64) / (4.0 * math.pi)


def cycles_max_bounces(max_depth: int) -> int:
    """Cycles ``max_bounces`` equal to Mitsuba's ``path`` integrator ``max_depth``.

    Mitsuba counts path segments: depth 2 is direct light only (camera -> surface ->
    light), depth 4 adds two indirect bounces. Cycles counts bounces after the first
    hit: 0 is direct light only. So bounces = max_depth - 2. Depth 1 (emitters seen
    directly; an image of point lights is black) has no Cycles equivalent.
    """
    if not isinstance(max_depth, int) or max_depth < 2:
        raise BlenderError(f"render.max_depth must be >= 2 for Cycles (got {max_depth!r}); "
                           "depth 1 shows only emitters")
    return max_depth - 2


# The generator's noise measure; relight.scene.noise needs only numpy, so the bpy side can import it.
from relight.scene.noise import relative_rmse  # noqa: E402,F401


def rectangle_quad(to_world: np.ndarray, uv_scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """World corners ``(4, 3)`` and UVs ``(4, 2)`` of Mitsuba's ``rectangle`` ([-1, 1]^2 in
    local x, y, normal +z, ``uv = ((x + 1) / 2, (y + 1) / 2)``) under ``to_world`` (4x4),
    UVs multiplied by ``uv_scale``; counter-clockwise about +z (front face along +z)."""
    local = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    homog = np.column_stack([local, np.zeros(4), np.ones(4)])
    corners = (homog @ np.asarray(to_world, np.float64).T)[:, :3]
    uv = (local + 1.0) / 2.0 * uv_scale
    return corners, uv


# --------------------------------------------------------------------------- bpy side
def _bpy():
    try:
        import bpy
    except ImportError:
        raise BlenderError(INSTALL_HINT) from None
    return bpy


@contextlib.contextmanager
def _quiet_stdout():
    """Silence Blender's render log (it writes to the C-level stdout)."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def _material(bpy, name: str, color, roughness: float, image=None, gloss: float = 0.0,
              gloss_alpha: float = 0.1, gloss_rgb=(1.0, 1.0, 1.0)):
    """A Diffuse BSDF material; with ``gloss`` > 0 mixed (factor ``gloss``) with a GGX
    Glossy BSDF of colour ``gloss_rgb`` and Roughness sqrt(``gloss_alpha``) (Cycles'
    roughness is the square root of the GGX alpha): the object's ``blendbsdf``."""
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True  # always on from Blender 5
    nt = mat.node_tree
    nt.nodes.clear()
    diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (*[float(c) for c in color], 1.0)
    diffuse.inputs["Roughness"].default_value = float(roughness)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    out.target = "CYCLES"
    surface = diffuse.outputs["BSDF"]
    if gloss > 0:
        glossy = nt.nodes.new("ShaderNodeBsdfGlossy")
        glossy.distribution = "GGX"
        glossy.inputs["Color"].default_value = (*[float(c) for c in gloss_rgb], 1.0)
        glossy.inputs["Roughness"].default_value = math.sqrt(float(gloss_alpha))
        mix = nt.nodes.new("ShaderNodeMixShader")
        mix.inputs["Fac"].default_value = float(gloss)
        nt.links.new(diffuse.outputs["BSDF"], mix.inputs[1])
        nt.links.new(glossy.outputs["BSDF"], mix.inputs[2])
        surface = mix.outputs["Shader"]
    nt.links.new(surface, out.inputs["Surface"])
    if image is not None:
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = image
        tex.interpolation = "Linear"   # Mitsuba bitmap filter_type "bilinear"
        tex.extension = "REPEAT"       # wrap_mode "repeat"
        tex.projection = "FLAT"
        nt.links.new(tex.outputs["Color"], diffuse.inputs["Color"])
    return mat


def _image(bpy, name: str, pixels: np.ndarray):
    """A float image holding ``pixels`` (H, W, 3) as data (no colour conversion), packed.

    relight textures have row 0 at v = 0 in Mitsuba (``bitmap`` does not flip); Blender's
    pixel buffer starts at v = 0 as well, so rows go in unchanged."""
    h, w, _ = pixels.shape
    img = bpy.data.images.new(name, width=w, height=h, alpha=False, float_buffer=True)
    img.colorspace_settings.name = "Non-Color"
    rgba = np.concatenate([pixels.astype(np.float32), np.ones((h, w, 1), np.float32)], axis=-1)
    img.pixels.foreach_set(rgba.ravel())
    img.file_format = "OPEN_EXR"  # packed losslessly in float
    img.pack()
    return img


def _mesh_object(bpy, name: str, vertices, faces, material, normals=None, uv=None, material_index=None):
    """A mesh object; ``material`` is one material or a list (then ``material_index``
    gives each face's entry)."""
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, v)) for v in vertices], [],
                   [tuple(int(i) for i in f) for f in faces])
    if uv is not None:  # one UV per vertex, written per face corner
        layer = me.uv_layers.new(name="UVMap")
        loop_vertex = np.zeros(len(me.loops), np.int64)
        me.loops.foreach_get("vertex_index", loop_vertex)
        layer.data.foreach_set("uv", np.asarray(uv, np.float32)[loop_vertex].ravel())
    for mat in material if isinstance(material, (list, tuple)) else [material]:
        me.materials.append(mat)
    if material_index is not None:
        me.polygons.foreach_set("material_index", np.asarray(material_index, np.int32))
    if normals is not None:
        me.polygons.foreach_set("use_smooth", np.ones(len(me.polygons), bool))
        me.normals_split_custom_set_from_vertices([tuple(map(float, n)) for n in normals])
    me.update()
    ob = bpy.data.objects.new(name, me)
    ob.cycles.shadow_terminator_geometry_offset = 0.0  # Mitsuba offsets shadow rays by epsilon only
    return ob


def export_blender(spec: SceneSpec, blend_path: str | os.PathLike | None = None, *,
                   spp: int | None = None, seed: int | None = None, threads: int | None = None):
    """Build ``spec`` as the current bpy scene (replacing everything) and return it.

    Args:
        spec: the scene; ``spec.render`` gives size, samples, depth and seed.
        blend_path: if given, also save a self-contained .blend there (atomic).
        spp, seed: override ``spec.render.spp`` / ``spec.render.seed``.
        threads: Cycles threads (default: all cores).
    Needs bpy (raises :class:`BlenderError` without it).
    """
    bpy = _bpy()
    import mathutils

    from relight.scene import build

    bounces = cycles_max_bounces(spec.render.max_depth)
    with _quiet_stdout():
        bpy.ops.wm.read_factory_settings(use_empty=True)
    prefs = bpy.context.preferences
    prefs.experimental.use_cycles_debug = True   # exposes the sampling-pattern choice
    prefs.view.show_developer_ui = True
    scene = bpy.context.scene
    scene.name = spec.id
    _render_settings(scene, spec, bounces, spp, seed, threads)

    world = bpy.data.worlds.new("black")
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    sky = spec.light.sky_radiance   # the sky fill (light.ambient), else black
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 1.0 if spec.light.ambient > 0 else 0.0
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (*[float(c) for c in sky], 1.0)
    scene.world = world

    room = spec.room
    res = room.texture_res
    floor_tf = np.diag([build.FLOOR_HALF_SIZE_M, build.FLOOR_HALF_SIZE_M, 1.0, 1.0])
    corners, uv = rectangle_quad(floor_tf, 2.0 * build.FLOOR_HALF_SIZE_M / build.FLOOR_TILE_M)
    mat = _material(bpy, "floor", (1, 1, 1), 0.0, _image(bpy, "floor", build.texture(room.floor_texture, res)))
    scene.collection.objects.link(_mesh_object(bpy, "floor", corners, [(0, 1, 2, 3)], mat, uv=uv))
    for k in range(room.n_walls):
        tf = build.wall_to_world(k, room.n_walls, room.inradius_m, room.height_m, room.rotation_deg)
        corners, uv = rectangle_quad(tf)
        img = _image(bpy, f"wall{k}", build.texture(room.wall_textures[k], res))
        mat = _material(bpy, f"wall{k}", (1, 1, 1), 0.0, img)
        scene.collection.objects.link(_mesh_object(bpy, f"wall{k}", corners, [(0, 1, 2, 3)], mat, uv=uv))
    if spec.backdrop is not None:   # Mitsuba's "diffuse": Lambert, Cycles' Diffuse BSDF of roughness 0
        corners, uv = rectangle_quad(spec.backdrop.to_world())
        mat = _material(bpy, "backdrop", [spec.backdrop.albedo] * 3, 0.0)
        scene.collection.objects.link(_mesh_object(bpy, "backdrop", corners, [(0, 1, 2, 3)], mat, uv=uv))
    for i, obj in enumerate(spec.objects):
        mesh = build.object_mesh(obj)
        v, n = build._object_vertices(obj, mesh)
        mats = [_material(bpy, f"obj{i}" if j == 0 else f"obj{i}_part{j}", rgb, obj.roughness,
                          gloss=obj.gloss, gloss_alpha=obj.gloss_alpha, gloss_rgb=obj.gloss_rgb)
                for j, rgb in enumerate(obj.colours)]
        labels = build.part_labels(mesh, len(mats)) if len(mats) > 1 else None
        faces = np.asarray(mesh.faces)
        keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
        if not keep.all():   # padded meshes (relight/assets) carry degenerate faces no ray hits
            faces, labels = faces[keep], None if labels is None else labels[keep]
        scene.collection.objects.link(_mesh_object(bpy, f"obj{i}", v, faces, mats, normals=n,
                                                   material_index=labels))

    cam = spec.camera
    cam_data = bpy.data.cameras.new("camera")
    cam_data.type = "PERSP"
    cam_data.sensor_fit = "HORIZONTAL"
    cam_data.angle = math.radians(cam.fov_deg)   # horizontal, as Mitsuba's fov_axis "x"
    cam_data.clip_start, cam_data.clip_end = 0.01, 1e4  # Mitsuba's perspective defaults
    cam_ob = bpy.data.objects.new("camera", cam_data)
    cam_ob.matrix_world = mathutils.Matrix(frames.camera_to_world(cam.tilt_deg, cam.r_m, cam.pan_deg).tolist())
    scene.collection.objects.link(cam_ob)
    scene.camera = cam_ob

    power_w, color = point_light_power(spec.light.intensity)
    light = bpy.data.lights.new("light", "POINT")
    light.energy = power_w
    light.color = color
    light.shadow_soft_size = 0.0     # a true point light
    light.use_soft_falloff = False
    light.normalize = True
    light.exposure = 0.0
    light.use_temperature = False
    light.cycles.use_multiple_importance_sampling = False
    light_ob = bpy.data.objects.new("light", light)
    light_ob.location = tuple(float(x) for x in spec.light.position_m)
    scene.collection.objects.link(light_ob)

    if blend_path is not None:
        from relight.fileio import atomic_write

        def save(tmp):
            with _quiet_stdout():
                bpy.ops.wm.save_as_mainfile(filepath=tmp, copy=True, compress=True)
        atomic_write(os.path.abspath(os.fspath(blend_path)), save)
    return scene


def _render_settings(scene, spec: SceneSpec, bounces: int, spp, seed, threads) -> None:
    scene.render.engine = "CYCLES"
    r = scene.render
    r.resolution_x = r.resolution_y = spec.render.res
    r.resolution_percentage = 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0
    r.film_transparent = False
    r.use_persistent_data = False
    r.threads_mode = "AUTO" if threads is None else "FIXED"
    if threads is not None:
        r.threads = int(threads)
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_mode = "RGB"
    r.image_settings.color_depth = "32"
    r.image_settings.exr_codec = "ZIP"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    c = scene.cycles
    c.device = "CPU"
    c.samples = int(spec.render.spp if spp is None else spp)
    c.seed = int(spec.render.seed if seed is None else seed) % (2 ** 31)
    c.use_animated_seed = False
    c.sampling_pattern = SAMPLING_PATTERN
    c.use_adaptive_sampling = False
    c.time_limit = 0.0
    c.use_denoising = False
    c.use_preview_denoising = False
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0             # Mitsuba's box rfilter: uniform over the pixel
    c.max_bounces = c.diffuse_bounces = bounces
    c.glossy_bounces = c.transmission_bounces = c.volume_bounces = 0
    c.transparent_max_bounces = 0
    c.min_light_bounces = 0
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.light_sampling_threshold = 0.0
    c.use_light_tree = False
    c.use_guiding = False
    c.caustics_reflective = c.caustics_refractive = False
    c.blur_glossy = 0.0
    c.film_exposure = 1.0


def render_cycles(spec: SceneSpec, *, spp: int | None = None, seed: int | None = None,
                  threads: int | None = None, exr_path: str | None = None) -> tuple[np.ndarray, float]:
    """Render ``spec`` with Cycles: linear RGB ``(res, res, 3)`` float32 (row 0 at the top)
    and the seconds spent in Cycles' render call (scene sync, BVH build and sampling).

    With ``exr_path`` the EXR Cycles writes is kept there (atomic). Needs bpy.
    """
    bpy = _bpy()
    scene = export_blender(spec, spp=spp, seed=seed, threads=threads)
    with tempfile.TemporaryDirectory(prefix="relight-cycles-") as tmp:
        out = os.path.join(tmp, "render.exr")
        scene.render.filepath = out
        with _quiet_stdout():
            t0 = time.perf_counter()
            bpy.ops.render.render(write_still=True, scene=scene.name)
            seconds = time.perf_counter() - t0
        img = bpy.data.images.load(out, check_existing=False)
        try:
            h, w = img.size[1], img.size[0]
            pixels = np.empty(h * w * img.channels, np.float32)
            img.pixels.foreach_get(pixels)
            image = pixels.reshape(h, w, img.channels)[::-1, :, :3].copy()  # bottom-up -> top-down
        finally:
            bpy.data.images.remove(img)
        if exr_path is not None:
            from relight.fileio import write_bytes
            with open(out, "rb") as src:
                write_bytes(exr_path, src.read())
    return image, seconds


# --------------------------------------------------------------------------- from relight's own env
def blender_python() -> str | None:
    """Path of a python that can import bpy: ``$RELIGHT_BLENDER_PYTHON``, else the
    environment made by ``scripts/setup_blender.sh`` (``~/relight-bpy-venv``), else None."""
    explicit = os.environ.get(BLENDER_VENV_ENV)
    if explicit:
        return explicit if os.path.isfile(explicit) and os.access(explicit, os.X_OK) else None
    candidate = os.path.join(os.path.expanduser(DEFAULT_BLENDER_VENV), "bin", "python")
    return candidate if os.path.isfile(candidate) and os.access(candidate, os.X_OK) else None


def _repo_root() -> str:
    return os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _bpy_env() -> dict:
    """The environment of a child in the bpy environment: this checkout of relight first on
    its path, marked to end with this process (:func:`relight.children.child_env`)."""
    env = child_env()
    env["PYTHONPATH"] = os.pathsep.join(p for p in (_repo_root(), env.get("PYTHONPATH")) if p)
    return env


def run_blender_module(args: list[str], python: str | None = None, **kwargs) -> subprocess.CompletedProcess:
    """Run ``python -m relight.scene.blender ARGS`` in the bpy environment (this checkout of
    relight on its path); :class:`BlenderError` if there is none."""
    python = python or blender_python()
    if python is None:
        raise BlenderError(INSTALL_HINT)
    return subprocess.run([python, "-m", "relight.scene.blender", *args], env=_bpy_env(), **kwargs)


class CyclesWorker:
    """A long-lived ``python -m relight.scene.blender worker`` in the bpy environment.

    ``render(spec, spp, seed)`` returns ``(image, seconds)`` like :func:`render_cycles`;
    scenes and images travel as files in a private temporary folder.
    """

    def __init__(self, python: str | None = None, threads: int | None = None):
        python = python or blender_python()
        if python is None:
            raise BlenderError(INSTALL_HINT)
        self._tmp = tempfile.TemporaryDirectory(prefix="relight-cycles-")
        cmd = [python, "-m", "relight.scene.blender", "worker"]
        if threads is not None:
            cmd += ["--threads", str(int(threads))]
        self._proc = subprocess.Popen(cmd, env=_bpy_env(), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      text=True, bufsize=1)
        self._n = 0
        hello = self._proc.stdout.readline()
        if not hello:
            raise BlenderError(f"the Cycles worker did not start (exit code {self._proc.wait()})")
        self.version = json.loads(hello)["bpy"]   # Blender version string

    def render(self, spec: SceneSpec, spp: int, seed: int) -> tuple[np.ndarray, float]:
        self._n += 1
        scene_path = os.path.join(self._tmp.name, f"{self._n}.json")
        out_path = os.path.join(self._tmp.name, f"{self._n}.npy")
        spec.save(scene_path)
        self._proc.stdin.write(json.dumps({"scene": scene_path, "spp": int(spp), "seed": int(seed),
                                           "out": out_path}) + "\n")
        self._proc.stdin.flush()
        line = self._proc.stdout.readline()
        if not line:
            raise BlenderError(f"the Cycles worker stopped (exit code {self._proc.wait()})")
        reply = json.loads(line)
        if "error" in reply:
            raise BlenderError(f"Cycles worker: {reply['error']}")
        image = np.load(out_path)
        os.remove(out_path)
        os.remove(scene_path)
        return image, float(reply["seconds"])

    def close(self) -> None:
        if self._proc.poll() is None:
            self._proc.stdin.close()
            self._proc.wait(timeout=60)
        self._tmp.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# --------------------------------------------------------------------------- python -m relight.scene.blender
def _worker(threads: int | None) -> int:
    """Serve render requests: one JSON object a line on stdin, one reply a line on stdout."""
    from relight.scene.spec import load_scene
    protocol = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)  # anything Blender prints goes to stderr, never into the replies
    protocol.write(json.dumps({"bpy": _bpy().app.version_string}) + "\n")
    for line in sys.stdin:
        if not line.strip():
            continue
        job = json.loads(line)
        try:
            image, seconds = render_cycles(load_scene(job["scene"]), spp=job["spp"], seed=job["seed"],
                                           threads=threads)
            from relight.fileio import atomic_write

            def save(tmp, image=image):
                with open(tmp, "wb") as f:
                    np.save(f, image)
            atomic_write(job["out"], save)
            protocol.write(json.dumps({"seconds": seconds}) + "\n")
        except (BlenderError, ValueError, OSError) as exc:
            protocol.write(json.dumps({"error": str(exc).splitlines()[0]}) + "\n")
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m relight.scene.blender export SCENE --out FILE.blend [--render OUT.exr --spp N]``
    or ``... worker`` (used by :class:`CyclesWorker`)."""
    import argparse
    from relight.scene.spec import SceneFileError, load_scene
    ap = argparse.ArgumentParser(prog="python -m relight.scene.blender")
    sub = ap.add_subparsers(dest="what", required=True)
    e = sub.add_parser("export")
    e.add_argument("scene")
    e.add_argument("--out", required=True)
    e.add_argument("--render", default=None)
    e.add_argument("--spp", type=int, default=None)
    e.add_argument("--threads", type=int, default=None)
    w = sub.add_parser("worker")
    w.add_argument("--threads", type=int, default=None)
    args = ap.parse_args(argv)
    die_with_parent()      # started by relight (run_blender_module, CyclesWorker): ends with it
    try:
        if args.what == "worker":
            return _worker(args.threads)
        return export_and_render(load_scene(args.scene), args.out, render_path=args.render,
                                 spp=args.spp, threads=args.threads)
    except (BlenderError, SceneFileError, ValueError, OSError) as exc:
        sys.stderr.write(f"relight: error: {str(exc).splitlines()[0]}\n")
        return 2


def export_and_render(spec: SceneSpec, blend_path: str, *, render_path: str | None = None,
                      spp: int | None = None, threads: int | None = None) -> int:
    """Save ``spec`` as a .blend and optionally render it to a linear EXR (needs bpy)."""
    if spp is not None and spp < 1:
        raise ValueError(f"--spp must be a positive integer, got {spp}")
    if render_path is not None and not render_path.lower().endswith(".exr"):
        raise ValueError(f"--render must name an .exr file (linear radiance), got {render_path}")
    export_blender(spec, blend_path, spp=spp, threads=threads)
    print(f"wrote {blend_path}")
    if render_path is not None:
        _, seconds = render_cycles(spec, spp=spp, threads=threads, exr_path=render_path)
        print(f"wrote {render_path} ({seconds:.2f} s in Cycles)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The studio backdrop (``SceneSpec.backdrop``): its geometry against closed forms, scene
files, the generator's draws, Mitsuba's render against the Lambert closed form, and
Cycles parity."""
from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from relight import frames
from relight.errors import ConfigError
from relight.generator.sampling import GeneratorConfig, sample_scene
from relight.scene.spec import BackdropSpec, SceneFileError, SceneSpec

from conftest import assert_cycles_matches_mitsuba, needs_blender, sphere_scene

SEED = 23


def _backdrop(**kw):
    d = dict(pan_deg=180.0, distance_m=5.0, half_width_m=20.0, height_m=30.0, albedo=0.4)
    d.update(kw)
    return BackdropSpec(**d)


def test_backdrop_geometry_closed_form():
    """pan 180, distance 5: the plane x = -5 facing +x, |y| <= 20, 0 <= z <= 30."""
    b = _backdrop()
    m = b.to_world()
    np.testing.assert_allclose(m[:3, 3], [-5.0, 0.0, 15.0], atol=1e-12)
    np.testing.assert_allclose(m[:3, 2], [1.0, 0.0, 0.0], atol=1e-12)          # normal: toward the centre
    corners = [m @ [sx, sy, 0.0, 1.0] for sx in (-1, 1) for sy in (-1, 1)]
    np.testing.assert_allclose(sorted(c[1] for c in corners), [-20, -20, 20, 20], atol=1e-12)
    np.testing.assert_allclose(sorted(c[2] for c in corners), [0, 0, 30, 30], atol=1e-12)
    assert b.blocks((0, 0, 1), (-10, 0, 1))            # straight through
    assert not b.blocks((0, 0, 1), (-4, 0, 1))          # stops short of it
    assert not b.blocks((0, 0, 1), (10, 0, 1))          # away from it
    assert not b.blocks((0, 0, 1), (-10, 0, 70))        # over the top: crosses x = -5 at z = 35.5
    assert b.blocks((0, 0, 1), (-10, 0, 55))            # crosses at z = 28
    assert not b.blocks((0, 0, 1), (-10, 50, 1))        # past its side: crosses at y = 25
    turned = _backdrop(pan_deg=90.0)                   # the plane y = 5
    assert turned.blocks((0, 0, 1), (0, 10, 1)) and not turned.blocks((0, 0, 1), (-10, 0, 1))


def test_backdrop_in_scene_files():
    base = sphere_scene()
    assert "backdrop" not in json.loads(base.to_json())        # files without it read as before
    spec = dataclasses.replace(base, backdrop=_backdrop())
    assert SceneSpec.from_json(spec.to_json()) == spec
    for bad in ({"albedo": 1.5}, {"distance_m": 0.0}, {"height_m": -1.0}, {"pan_deg": float("nan")}):
        d = json.loads(spec.to_json())
        d["backdrop"].update(bad)
        with pytest.raises(SceneFileError):
            SceneSpec.from_json(json.dumps(d))
    d = json.loads(spec.to_json())
    d["backdrop"]["colour"] = 1
    with pytest.raises(SceneFileError):
        SceneSpec.from_dict(d)


def _pixel_rays(spec):
    """World-space unit rays through the pixel centres (row 0 at the top), and the origin."""
    cam = spec.camera
    res = spec.render.res
    t = math.tan(math.radians(cam.fov_deg) / 2.0)
    c = (np.arange(res) + 0.5) / res * 2.0 - 1.0
    x, y = np.meshgrid(c * t, -c * t)
    d_cam = np.stack([x, y, -np.ones_like(x)], -1)
    m = frames.camera_to_world(cam.tilt_deg, cam.r_m, cam.pan_deg)
    d = d_cam @ m[:3, :3].T
    return d / np.linalg.norm(d, axis=-1, keepdims=True), m[:3, 3]


def test_backdrop_renders_as_lambert_closed_form(mi):
    """Direct light only (max_depth 2): a Lambert backdrop of albedo rho at a point P shows
    radiance rho / pi * I cos(theta) / |L - P|^2. Checked on the image's top rows, where every
    ray meets the backdrop."""
    from relight.scene.build import SceneBuilder
    base = sphere_scene(pan_rel_deg=20.0, tilt_deg=35.0, camera_tilt_deg=10.0, res=24, spp=64, seed=2)
    spec = dataclasses.replace(base, backdrop=_backdrop(),
                               render=dataclasses.replace(base.render, max_depth=2))
    image = SceneBuilder().render(spec)
    rays, origin = _pixel_rays(spec)
    rays = rays[:4]
    t = (-5.0 - origin[0]) / rays[..., 0]
    p = origin + t[..., None] * rays
    assert (t > 0).all() and (np.abs(p[..., 1]) < 20).all() and (p[..., 2] > 3).all() and (p[..., 2] < 30).all()
    to_light = spec.light.position_m - p
    dist2 = (to_light ** 2).sum(-1)
    cos = to_light[..., 0] / np.sqrt(dist2)
    expected = 0.4 / math.pi * spec.light.intensity[None, None, :] * (cos / dist2)[..., None]
    np.testing.assert_allclose(image[:4], expected, rtol=0.02)
    black = SceneBuilder().render(dataclasses.replace(spec, backdrop=_backdrop(albedo=0.0)))
    assert black[:4].max() == 0.0 and image[:4].min() > 0.0
    # a scene without one loads no extra shape, so it renders as before
    builder = SceneBuilder()
    assert not any(k.startswith("backdrop") for k in builder.template_for(base).params.keys())
    assert any(k.startswith("backdrop") for k in builder.template_for(spec).params.keys())


def test_backdrop_draws_come_last_and_never_shade_the_objects():
    """Every draw but the backdrop (and a light it would hide) as without it; only void
    scenes get one, behind every object, facing the camera; no object is shaded from the
    light by it; a hidden light moves to its mirror direction (same tilt); and having a
    backdrop does not depend on where the light is."""
    photo = dict(preset="photo", path=None)
    plain = GeneratorConfig.from_file(**photo, void_fraction=0.6)
    studio = GeneratorConfig.from_file(**photo, void_fraction=0.6, backdrop_fraction=0.8,
                                       backdrop_albedo=(0.01, 0.1))
    n_void = n_backdrop = n_moved = 0
    for i in range(80):
        a, b = sample_scene(plain, SEED, i), sample_scene(studio, SEED, i)
        assert a.backdrop is None
        assert dataclasses.replace(b, backdrop=None, light=a.light) == a          # every other draw as before
        void = a.room.floor_texture["colors"][0] == a.room.floor_texture["colors"][1] \
            and a.room.floor_texture.get("cells") == 2 and a.room.floor_texture["kind"] == "checker"
        n_void += void
        if b.backdrop is None:
            assert b.light == a.light
            continue
        assert void                                                 # only void scenes get one
        n_backdrop += 1
        bd = b.backdrop
        assert 0.01 <= bd.albedo <= 0.1
        out = frames.direction(bd.pan_deg, 0.0)
        to_camera = frames.direction(b.camera.pan_deg, 0.0)
        assert float(out @ to_camera) <= -math.cos(math.radians(20.0)) + 1e-9   # faces the camera
        for o in b.objects:
            assert float(out[:2] @ np.asarray(o.position_m)) + o.size_m < bd.distance_m   # behind every object
            for z in (0.0, 0.5 * o.size_m, o.size_m):
                assert not bd.blocks((*o.position_m, z), b.light.position_m)
        if b.light != a.light:
            n_moved += 1
            assert dataclasses.replace(b.light, pan_deg=a.light.pan_deg) == a.light   # only its azimuth
            was, now = frames.direction(a.light.pan_deg, 0.0), frames.direction(b.light.pan_deg, 0.0)
            assert float(was @ out) > 0 and float(now @ out) == pytest.approx(-float(was @ out), abs=1e-3)
            assert float(now @ (np.cross(out, [0, 0, 1]))) == pytest.approx(
                float(was @ (np.cross(out, [0, 0, 1]))), abs=1e-3)                       # mirrored across it
    assert n_void >= 30 and n_backdrop >= 0.5 * n_void and n_moved >= 1
    # whether a scene has a backdrop does not depend on its light (none is ever dropped):
    # with backdrop_fraction 1 every void scene has one
    every = GeneratorConfig.from_file(**photo, void_fraction=0.6, backdrop_fraction=1.0)
    for i in range(30):
        a, b = sample_scene(plain, SEED, i), sample_scene(every, SEED, i)
        assert (b.backdrop is not None) == (a.room != sample_scene(GeneratorConfig.from_file(
            **photo, void_fraction=0.0), SEED, i).room)
    with pytest.raises(ConfigError):
        GeneratorConfig(backdrop_fraction=1.5)
    with pytest.raises(ConfigError):
        GeneratorConfig(backdrop_albedo=(0.0, 0.1))


@needs_blender
def test_cycles_matches_mitsuba_with_a_backdrop(mi, tmp_path):
    """export-blender writes the backdrop as one more Lambert quad: Cycles and Mitsuba agree."""
    base = sphere_scene(pan_rel_deg=20.0, tilt_deg=35.0, camera_tilt_deg=10.0, res=24, spp=256, seed=3)
    assert_cycles_matches_mitsuba(dataclasses.replace(base, backdrop=_backdrop(albedo=0.3)), tmp_path)

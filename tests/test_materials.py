"""Object materials (glossy and metal objects) and the shipped meshes: generator draws,
scene files, Mitsuba renders against the blend's closed form, Cycles parity."""
from __future__ import annotations

import dataclasses
import json
import math
import os

import numpy as np
import pytest

from relight.errors import ConfigError
from relight.generator.sampling import (BUILTIN_MESH_DIR, GLOSS_ALPHA, GLOSSY_WEIGHT, METAL_F0, GeneratorConfig,
                                        mesh_files, sample_scene)
from relight.scene import shapes
from relight.scene.spec import SceneFileError, SceneSpec

from conftest import assert_cycles_matches_mitsuba, needs_blender, sphere_scene

SEED = 17


def test_material_draws_come_last_so_other_draws_are_unchanged():
    plain = GeneratorConfig()
    shiny = GeneratorConfig(glossy_fraction=0.5, metal_fraction=0.5)
    changed = 0
    for i in range(6):
        a, b = sample_scene(plain, SEED, i), sample_scene(shiny, SEED, i)
        assert a.light == b.light and a.camera == b.camera and a.room == b.room and a.render == b.render
        for oa, ob in zip(a.objects, b.objects, strict=True):
            assert dataclasses.replace(ob, gloss=0.0, gloss_alpha=0.1, gloss_rgb=(1.0, 1.0, 1.0)) == oa
            changed += ob.gloss > 0
    assert changed > 0   # every object is glossy or metal with these shares


def test_material_shares_and_ranges():
    cfg = GeneratorConfig(glossy_fraction=0.3, metal_fraction=0.2, res=16, spp=1)
    objects = [o for i in range(150) for o in sample_scene(cfg, SEED, i).objects]
    n = len(objects)
    metals = [o for o in objects if o.gloss == 1.0]
    glossy = [o for o in objects if 0 < o.gloss < 1]
    for share, found in ((0.2, len(metals)), (0.3, len(glossy))):   # binomial: within 4 sd
        assert abs(found - share * n) <= 4 * math.sqrt(n * share * (1 - share))
    assert all(tuple(o.gloss_rgb) in set(METAL_F0.values()) for o in metals)
    assert all(GLOSSY_WEIGHT[0] <= o.gloss <= GLOSSY_WEIGHT[1] and o.gloss_rgb == (1.0, 1.0, 1.0) for o in glossy)
    assert all(GLOSS_ALPHA[0] <= o.gloss_alpha <= GLOSS_ALPHA[1] for o in metals + glossy)


def test_material_settings_are_validated():
    for bad in ({"glossy_fraction": 1.5}, {"metal_fraction": -0.1}, {"glossy_fraction": 0.7, "metal_fraction": 0.6},
                {"mesh_fraction": 2.0}):
        with pytest.raises(ConfigError):
            GeneratorConfig(**bad)


def test_scene_files_keep_gloss_and_matte_files_are_unchanged():
    base = sphere_scene()
    matte = json.loads(base.to_json())
    assert "gloss" not in matte["objects"][0]   # a file of a matte object reads as before
    shiny = dataclasses.replace(base, objects=(dataclasses.replace(
        base.objects[0], gloss=0.2, gloss_alpha=0.3, gloss_rgb=(1.0, 0.78, 0.34)),))
    again = SceneSpec.from_json(shiny.to_json())
    assert again == shiny and again.objects[0].gloss_rgb == (1.0, 0.78, 0.34)
    for bad in ({"gloss": 1.5}, {"gloss_alpha": 0.0}, {"gloss_rgb": [1, 1]}, {"gloss_rgb": [2, 0, 0]}):
        d = json.loads(shiny.to_json())
        d["objects"][0].update(bad)
        with pytest.raises(SceneFileError):
            SceneSpec.from_dict(d)


def _with(spec, **changes):
    return dataclasses.replace(spec, objects=(dataclasses.replace(spec.objects[0], **changes),))


def test_blend_renders_as_its_closed_form(mi):
    """The object's material is (1 - w) diffuse + w specular: a render at w = 0.25 has the
    mean of 0.75 x the matte render + 0.25 x the pure specular one (dark albedo and a white
    lobe, so the two differ by a factor and w <-> 1 - w would be far off), within the noise."""
    from relight.scene.build import SceneBuilder
    base = sphere_scene(res=32, spp=256, seed=2, camera_tilt_deg=20.0)
    base = dataclasses.replace(base, camera=dataclasses.replace(base.camera, r_m=6.0))   # the sphere fills the view
    builder = SceneBuilder()

    def mean(**changes):
        return float(builder.render(_with(base, reflectance=(0.05, 0.05, 0.05), **changes)).mean())

    matte = mean(gloss=1e-6, gloss_alpha=0.3)       # a glossy template with no specular weight
    plain = mean()                                  # the matte template
    metal = mean(gloss=1.0, gloss_alpha=0.3)
    blend = mean(gloss=0.25, gloss_alpha=0.3)
    assert matte == pytest.approx(plain, rel=0.02)
    assert abs(metal - matte) > 0.1 * matte          # the lobe changes the image (the test can fail)
    assert blend == pytest.approx(0.75 * matte + 0.25 * metal, rel=0.02)
    black = mean(gloss=1.0, gloss_alpha=0.3, gloss_rgb=(0.0, 0.0, 0.0))
    assert black < matte    # a black metal reflects nothing: the object goes dark


def test_builtin_meshes_share_the_procedural_buffers_and_carry_licences(mi):
    from relight.scene.build import object_mesh
    paths = mesh_files("builtin")
    assert len(paths) >= 10 and all(os.path.dirname(p) == BUILTIN_MESH_DIR for p in paths)
    ref = shapes.make_mesh("blob", shapes.sample_shape_params("blob", np.random.default_rng(0)))
    for path in paths:
        lic = path[:-len(".ply")] + ".LICENSE.md"
        first = open(lic).readline().strip()   # the licence, then the original's README
        assert first in ("Licence: public domain", "Licence: CC BY 3.0", "Licence: CC BY 4.0")
        base = sphere_scene().objects[0]
        mesh = object_mesh(dataclasses.replace(base, family="mesh", params={}, mesh_path=path))
        assert mesh.vertices.shape == ref.vertices.shape and mesh.faces.shape == ref.faces.shape
        radius = np.hypot(mesh.vertices[:, 0], mesh.vertices[:, 1]).max()
        assert radius == pytest.approx(1.0, abs=1e-5) and mesh.vertices[:, 2].min() == pytest.approx(0.0, abs=1e-6)


def test_generate_with_builtin_meshes_and_materials(tmp_path):
    from relight.cli import main
    cfg = tmp_path / "c.json"
    cfg.write_text(json.dumps({"glossy_fraction": 0.5, "metal_fraction": 0.25, "mesh_fraction": 1.0}))
    out = tmp_path / "d"
    assert main(["generate", "--count", "3", "--res", "16", "--spp", "2", "--seed", "3", "--quiet",
                 "--mesh-dir", "builtin", "--config", str(cfg), "--out", str(out)]) == 0
    card = json.loads((out / "dataset.json").read_text())
    assert card["config"]["mesh_dir"] == "builtin" and card["config"]["metal_fraction"] == 0.25
    scenes = sorted((out / "scenes").glob("*.json"))
    assert len(scenes) == 3
    objs = [o for s in scenes for o in json.loads(s.read_text())["objects"]]
    assert all(o["mesh_path"].startswith(BUILTIN_MESH_DIR) for o in objs)


@needs_blender
def test_cycles_matches_mitsuba_on_a_glossy_object(mi, tmp_path):
    """export-blender's Mix Shader of Diffuse and GGX Glossy against Mitsuba's blendbsdf."""
    assert_cycles_matches_mitsuba(_with(sphere_scene(res=24, spp=256, seed=3, roughness=0.0), gloss=0.3,
                                         gloss_alpha=0.2, gloss_rgb=(1.0, 0.78, 0.34)), tmp_path)


# ----------------------------------------------------------------------------- sky fill
def _low_walls(spec):
    """The scene with walls 1 m high (at 110 m they hide 0.5 degrees of the sky)."""
    return dataclasses.replace(spec, room=dataclasses.replace(spec.room, height_m=1.0))


def test_sky_fill_lights_the_floor_as_its_closed_form(mi):
    """A Lambert floor of albedo rho under the whole sky has radiance rho * L_sky: the
    bottom image rows (floor, far from the sphere) gain exactly that when the fill is on,
    and twice the fill gives twice the gain."""
    from relight.scene.build import SceneBuilder
    base = _low_walls(sphere_scene(res=24, spp=256, seed=4))
    builder = SceneBuilder()

    def floor(ambient):
        spec = dataclasses.replace(base, light=dataclasses.replace(base.light, ambient=ambient))
        return builder.render(spec)[-4:].mean(axis=(0, 1)), spec.light.sky_radiance

    off, _ = floor(0.0)
    on, sky = floor(0.3)
    on2, sky2 = floor(0.6)
    rho = 0.5   # plain_texture's grey
    np.testing.assert_allclose(on - off, rho * sky, rtol=0.03)
    np.testing.assert_allclose(on2 - off, 2 * (on - off), rtol=0.03)
    np.testing.assert_allclose(sky2, 2 * sky, rtol=1e-12)


def test_sky_fill_in_scene_files_and_draws():
    base = sphere_scene()
    assert "ambient" not in json.loads(base.to_json())["light"]   # files without it read as before
    lit = dataclasses.replace(base, light=dataclasses.replace(base.light, ambient=0.25))
    assert SceneSpec.from_json(lit.to_json()) == lit
    d = json.loads(lit.to_json())
    d["light"]["ambient"] = -1.0
    with pytest.raises(SceneFileError):
        SceneSpec.from_dict(d)
    # white light: the sky's irradiance pi * L is ambient times the light's per-channel irradiance
    white = dataclasses.replace(lit, light=dataclasses.replace(lit.light, rgb=(1.0, 1.0, 1.0)))
    np.testing.assert_allclose(math.pi * white.light.sky_radiance, 0.25 * white.light.strength, rtol=1e-12)
    plain, filled = GeneratorConfig(), GeneratorConfig(ambient_fraction=0.5, ambient_ratio=(0.1, 0.2))
    n_filled = 0
    for i in range(60):
        a, b = sample_scene(plain, SEED, i), sample_scene(filled, SEED, i)
        assert a.objects == b.objects and a.camera == b.camera and a.room == b.room
        assert (a.light.pan_deg, a.light.tilt_deg, a.light.strength) == (b.light.pan_deg, b.light.tilt_deg,
                                                                          b.light.strength)
        if b.light.ambient:
            n_filled += 1
            assert 0.1 <= b.light.ambient <= 0.2
    assert abs(n_filled - 30) <= 4 * math.sqrt(15)
    with pytest.raises(ConfigError):
        GeneratorConfig(ambient_ratio=(0.5, 0.1))


@needs_blender
def test_cycles_matches_mitsuba_with_a_sky_fill(mi, tmp_path):
    """The sky fill exports as the world's background colour (strength 1)."""
    base = _low_walls(sphere_scene(res=24, spp=256, seed=3))
    assert_cycles_matches_mitsuba(dataclasses.replace(base, light=dataclasses.replace(base.light, ambient=0.4)),
                                   tmp_path)

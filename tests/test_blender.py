"""Blender Cycles side by side: unit conversions (no bpy needed) and, where the Blender
environment exists (scripts/setup_blender.sh), a tiny scene rendered by both renderers."""
from __future__ import annotations

import importlib.util
import math
import os

import numpy as np
import pytest

from relight.scene import blender
from relight.scene.spec import LightSpec

from conftest import sphere_scene

# A Cycles render of the tiny scene must match Mitsuba's mean brightness to this
# fraction. With roughness 0 both renderers compute the same integral (Lambert
# surfaces, point light, depth 3), so only noise separates them: at 24 px and 256 spp
# the mean over 1,728 values has a relative standard error near 0.1% (measured: the
# two means differ by <= 0.2%), while a light-unit slip is a factor (pi, 4 pi) and a
# lost bounce 5-20% of the image.
MEAN_TOLERANCE = 0.01
# Pixel-wise relative RMSE allowed between the two: per-pixel noise of both renders at
# 256 spp is about 1% (measured 0.5-1%); a mirrored or shifted image gives > 20% (the
# light is on the camera's right, so the scene is far from symmetric).
PIXEL_TOLERANCE = 0.04


def test_point_light_power_closed_form():
    # Cycles: radiant intensity of a radius-0 point light = power * colour / (4 pi) W/sr.
    power_w, color = blender.point_light_power([3.0, 2.0, 1.0])
    assert power_w == pytest.approx(4.0 * math.pi * 3.0, rel=1e-12)
    assert color == pytest.approx((1.0, 2.0 / 3.0, 1.0 / 3.0), rel=1e-12)
    np.testing.assert_allclose(blender.point_light_intensity(power_w, color), [3.0, 2.0, 1.0], rtol=1e-12)


def test_point_light_power_gives_the_scene_irradiance():
    # A scene light of strength S at distance r gives irradiance S sqrt(3) rgb at the
    # centre (LightSpec); the Blender light must give the same: P colour / (4 pi r^2).
    light = LightSpec(r_m=35.0, pan_deg=10.0, tilt_deg=40.0, rgb=(1.0, 0.8, 0.5), strength=3.2)
    power_w, color = blender.point_light_power(light.intensity)
    irradiance = power_w * np.asarray(color) / (4.0 * math.pi * light.r_m ** 2)
    np.testing.assert_allclose(irradiance, light.strength * math.sqrt(3.0) * np.asarray(light.rgb), rtol=1e-12)


@pytest.mark.parametrize("bad", [[0.0, 0.0, 0.0], [1.0, -1.0, 1.0], [1.0, float("nan"), 1.0]])
def test_point_light_power_rejects_bad_intensity(bad):
    with pytest.raises(ValueError):
        blender.point_light_power(bad)


def test_cycles_max_bounces():
    # Mitsuba depth 2 = direct light only = Cycles 0 bounces; each extra segment one bounce.
    assert [blender.cycles_max_bounces(d) for d in (2, 3, 4, 8)] == [0, 1, 2, 6]
    with pytest.raises(blender.BlenderError):
        blender.cycles_max_bounces(1)


def test_relative_rmse():
    ref = np.full((4, 4, 3), 2.0)
    assert blender.relative_rmse(ref, ref) == 0.0
    assert blender.relative_rmse(ref + 0.1, ref) == pytest.approx(0.05)
    with pytest.raises(ValueError):
        blender.relative_rmse(ref[:2], ref)


def test_rectangle_quad_matches_mitsuba_uv(mi):
    """The exported quad's corners and UVs are those Mitsuba's rectangle has."""
    from relight.scene.build import wall_to_world
    to_world = wall_to_world(1, 5, 110.0, 80.0, 17.0)
    corners, uv = blender.rectangle_quad(to_world, uv_scale=3.0)
    rect = mi.load_dict({"type": "rectangle", "to_world": mi.ScalarTransform4f(to_world)})
    normal = to_world[:3, 2] / np.linalg.norm(to_world[:3, 2])
    # a point at bilinear weights (0.3, 0.6) of the quad, hit along the normal
    w = np.array([(1 - 0.3) * (1 - 0.6), 0.3 * (1 - 0.6), 0.3 * 0.6, (1 - 0.3) * 0.6])
    p, want_uv = w @ corners, w @ uv
    origin = p + normal
    si = rect.ray_intersect(mi.Ray3f(mi.Point3f(*map(float, origin)), mi.Vector3f(*map(float, -normal))))
    np.testing.assert_allclose(np.array(si.uv).ravel() * 3.0, want_uv, atol=1e-4)
    assert np.dot(np.cross(corners[1] - corners[0], corners[2] - corners[0]), normal) > 0  # front face


def test_export_blender_without_bpy_says_how_to_install(tmp_path, capsys, monkeypatch):
    if importlib.util.find_spec("bpy") is not None:
        pytest.skip("bpy is importable here")
    from relight.cli import main
    scene = tmp_path / "s.json"
    sphere_scene(res=16).save(scene)
    monkeypatch.setenv(blender.BLENDER_VENV_ENV, str(tmp_path / "no-python"))
    assert main(["export-blender", str(scene), "--out", str(tmp_path / "s.blend")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "setup_blender.sh" in err
    assert not (tmp_path / "s.blend").exists()


needs_blender = pytest.mark.skipif(blender.blender_python() is None and importlib.util.find_spec("bpy") is None,
                                   reason="no Blender environment (scripts/setup_blender.sh)")


@needs_blender
def test_cycles_matches_mitsuba_on_a_tiny_scene(mi, tmp_path):
    """export-blender's Cycles render (through the CLI) against Mitsuba, same scene file."""
    from relight.cli import main
    from relight.imageio import read_exr
    from relight.scene.build import SceneBuilder
    spec = sphere_scene(res=24, spp=256, seed=3, roughness=0.0)
    scene = tmp_path / "s.json"
    spec.save(scene)
    blend, exr = tmp_path / "s.blend", tmp_path / "s.exr"
    assert main(["export-blender", str(scene), "--out", str(blend), "--render", str(exr)]) == 0
    assert blend.stat().st_size > 0
    cycles = read_exr(exr)
    mitsuba = SceneBuilder().render(spec)
    assert cycles.shape == mitsuba.shape == (24, 24, 3)
    assert cycles.mean() / mitsuba.mean() == pytest.approx(1.0, abs=MEAN_TOLERANCE)
    assert blender.relative_rmse(cycles, mitsuba) < PIXEL_TOLERANCE
    assert not [f for f in os.listdir(tmp_path) if ".tmp" in f]
    # the worker's arrays (used by the benchmark) are the same image, the same way up
    with blender.CyclesWorker() as worker:
        image, seconds = worker.render(spec, spec.render.spp, spec.render.seed)
    np.testing.assert_allclose(image, cycles, rtol=1e-6, atol=1e-6)
    assert seconds > 0


@needs_blender
def test_cycles_matches_mitsuba_with_coloured_parts(mi, tmp_path):
    """An object with independently coloured parts (--object-parts) exports one material
    per part, each face on its part's: Cycles and Mitsuba agree channel by channel."""
    import dataclasses

    from relight.cli import main
    from relight.imageio import read_exr
    from relight.scene.build import SceneBuilder
    base = sphere_scene(res=24, spp=256, seed=3, roughness=0.0)
    parts = ((0.8, 0.1, 0.1), (0.1, 0.1, 0.8), (0.1, 0.7, 0.1), (0.6, 0.6, 0.2))
    spec = dataclasses.replace(base, objects=(dataclasses.replace(
        base.objects[0], reflectance=parts[0], part_reflectances=parts),))
    scene, exr = tmp_path / "s.json", tmp_path / "s.exr"
    spec.save(scene)
    assert main(["export-blender", str(scene), "--out", str(tmp_path / "s.blend"), "--render", str(exr)]) == 0
    cycles, mitsuba = read_exr(exr), SceneBuilder().render(spec)
    for ch in range(3):
        assert cycles[..., ch].mean() / mitsuba[..., ch].mean() == pytest.approx(1.0, abs=MEAN_TOLERANCE)
    assert blender.relative_rmse(cycles, mitsuba) < PIXEL_TOLERANCE

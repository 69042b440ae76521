"""Wall and floor backgrounds (``--backgrounds patterns|mosaic``).

``patterns`` (the default) draws each texture's colours around one hue; ``mosaic`` covers
every wall and the floor with a grid of cells whose colours are drawn one by one from the
colour prior, so a scene shows many independent surfaces (what bounds how well the light
colour can be recovered: ``relight.scene.albedo``, ``benchmarks/bench_colour_floor.py``)."""
import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest

from relight.errors import ConfigError
from relight.scene import textures as T
from relight.generator.sampling import GeneratorConfig, sample_scene
from relight.scene.spec import SceneSpec


def test_mosaic_texture_closed_form():
    # each cell is one flat colour, row-major from the top-left, at any size
    cols = [[0.1 * (k % 9) + 0.05, 0.5, 0.9 - 0.05 * k] for k in range(6)]
    p = {"kind": "mosaic", "seed": 0, "rows": 2, "cols": 3, "colors": cols}
    for size in (6, 12, 30):
        img = T.make_texture(p, size)
        h, w = size // 2, size // 3
        for r in range(2):
            for c in range(3):
                cell = img[r * h:(r + 1) * h, c * w:(c + 1) * w]
                assert np.allclose(cell, np.float32(cols[3 * r + c]), atol=1e-7)


@pytest.mark.parametrize("bad", [{"rows": 2, "cols": 3, "colors": [[0.5] * 3] * 5},    # too few colours
                                 {"rows": 0, "cols": 3, "colors": []},
                                 {"rows": 2, "cols": 2, "colors": [[0.5, 0.5, 1.5]] * 4},
                                 {"rows": 2.5, "cols": 2, "colors": [[0.5] * 3] * 5}])
def test_mosaic_texture_refuses_bad_params(bad):
    with pytest.raises(ValueError, match="mosaic"):
        T.make_texture({"kind": "mosaic", "seed": 0, **bad}, 8)


def test_sampled_mosaic_json_round_trip_and_ranges():
    rng = np.random.default_rng(3)
    for _ in range(20):
        p = T.sample_texture_params(rng, "mosaic", "munsell")
        lo, hi = T.MOSAIC_CELLS
        assert lo <= p["rows"] <= hi and lo <= p["cols"] <= hi
        assert len(p["colors"]) == p["rows"] * p["cols"]
        q = json.loads(json.dumps(p))
        assert np.array_equal(T.make_texture(p, 32), T.make_texture(q, 32))


def _mean_pair_angle(a, b):
    """Mean angle (degrees) between the RGB vectors of a (N, 3) and b (M, 3)."""
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    return float(np.degrees(np.arccos(np.clip(a @ b.T, -1, 1))).mean())


@pytest.mark.parametrize("prior", ["hsv", "munsell"])
def test_mosaic_cells_are_independent_surfaces(prior):
    # two colours of one mosaic differ as much as two colours of different mosaics (drawn
    # independently), and a mosaic holds 16-256 of them (a pattern: 2-5)
    rng = np.random.default_rng(11)

    def within_and_across(kind):
        texs = [np.asarray(T.sample_texture_params(rng, kind, prior)["colors"]) for _ in range(300)]
        within = np.mean([_mean_pair_angle(t, t) * len(t) / (len(t) - 1) for t in texs])   # without self-pairs
        across = np.mean([_mean_pair_angle(texs[i], texs[i + 1]) for i in range(len(texs) - 1)])
        return within, across

    w, a = within_and_across("mosaic")
    assert abs(w / a - 1) < 0.05
    assert min(len(T.sample_texture_params(rng, "mosaic", prior)["colors"]) for _ in range(50)) >= 16


def test_generator_setting_changes_only_the_room_textures():
    patterns, mosaic = GeneratorConfig(res=32, spp=4), GeneratorConfig(res=32, spp=4, backgrounds="mosaic")
    assert patterns.backgrounds == "patterns"
    for i in range(10):
        a, b = sample_scene(patterns, 5, i), sample_scene(mosaic, 5, i)
        assert (a.camera, a.light) == (b.camera, b.light)
        assert (a.room.n_walls, a.room.inradius_m) == (b.room.n_walls, b.room.inradius_m)
        assert all(t["kind"] in T.KINDS for t in a.room.wall_textures + (a.room.floor_texture,))
        assert all(t["kind"] == "mosaic" for t in b.room.wall_textures + (b.room.floor_texture,))
        assert SceneSpec.from_json(b.to_json()) == b
    with pytest.raises(ConfigError, match="backgrounds"):
        GeneratorConfig(backgrounds="plaid")


def test_mosaic_scene_renders_from_its_file(mi):
    from relight.scene.build import render_spec
    spec = sample_scene(GeneratorConfig(res=24, spp=2, backgrounds="mosaic"), 2, 0)
    img = render_spec(spec)
    assert img.shape == (24, 24, 3) and np.isfinite(img).all() and img.max() > 0
    assert np.array_equal(img, render_spec(SceneSpec.from_json(spec.to_json())))


def test_generate_records_the_setting_and_refuses_a_mixed_dataset(tmp_path, mi):
    from relight.dataset import DatasetError
    from relight.generator.run import generate
    cfg = GeneratorConfig(res=16, spp=2, backgrounds="mosaic")
    generate(tmp_path, 1, seed=4, cfg=cfg, progress=False)
    card = json.loads((tmp_path / "dataset.json").read_text())
    assert card["config"]["backgrounds"] == "mosaic"
    with pytest.raises(DatasetError, match=r"other settings \(backgrounds mosaic there, patterns here\)"):
        generate(tmp_path, 2, seed=4, cfg=dataclasses.replace(cfg, backgrounds="patterns"), progress=False)


def test_cli_refuses_an_unknown_background(tmp_path):
    r = subprocess.run([sys.executable, "-m", "relight", "generate", "--count", "1", "--out", str(tmp_path / "d"),
                        "--backgrounds", "plaid"], capture_output=True, text=True)
    assert r.returncode == 2 and "--backgrounds" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "d").exists()

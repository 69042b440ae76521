"""``relight generate --preset sid2-paper``: Tanner-Helland lights in 100 K steps, a closed
library of 250 backgrounds (and ``--backgrounds unseen`` outside it), pastel part colours;
geometry and camera as the default generator."""
import colorsys
import hashlib
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from relight import colour
from relight.scene import textures
from relight.generator.sampling import GeneratorConfig, SID2_PAPER_PRESET, sample_scene, sid2_paper_config

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


# --------------------------------------------------------------------------- Tanner-Helland
def test_tanner_helland_against_the_formula_by_hand():
    """Values worked by hand from the published formula (t = K / 100):
    6600 K: red 255 (t <= 66), green 99.4708025861 ln 66 - 161.1195681661 = 255.63 -> 255,
    blue 255 (t >= 66).
    2000 K: green 99.4708025861 x 2.9957323 - 161.1195682 = 136.868, blue
    138.5177312231 x ln 10 (2.3025851) - 305.0447927 = 13.904.
    1000 K: green 99.4708025861 x ln 10 - 161.1195682 = 67.920, blue 0 (t <= 19).
    9900 K: red 329.698727446 x 39^-0.1332047592 = 329.6987 x exp(-0.4880043) = 202.386,
    green 288.1221695283 x exp(-0.0755148492 x ln 39 (3.6635616)) = 218.488, blue 255.
    Rounded, these are the triplets the approximation's author lists (2000 K: 255, 137, 14;
    1000 K: 255, 68, 0)."""
    th = colour.kelvin_to_rgb_tanner_helland
    assert th(6600.0).tolist() == [255.0, 255.0, 255.0]
    assert th(2000.0) == pytest.approx([255.0, 136.868, 13.904], abs=2e-3)
    assert th(1000.0) == pytest.approx([255.0, 67.920, 0.0], abs=2e-3)
    assert th(9900.0) == pytest.approx([202.386, 218.488, 255.0], abs=2e-3)
    assert np.round(th([2000.0, 1000.0])).tolist() == [[255, 137, 14], [255, 68, 0]]
    assert th(np.array([[2000.0], [9900.0]])).shape == (2, 1, 3)
    # warmer to cooler: blue / red rises over the preset's range
    k = np.arange(2000.0, 9901.0, 100.0)
    ratio = th(k)[:, 2] / th(k)[:, 0]
    assert np.all(np.diff(ratio) > 0)
    for bad in (999.0, 40001.0, float("nan")):
        with pytest.raises(ValueError):
            th(bad)


def test_cct_step_light_draws_the_80_temperatures_with_their_triplet():
    rng = np.random.default_rng(0)
    draws = [colour.sample_cct_step_light(rng) for _ in range(4000)]
    kelvin = np.array([k for k, _ in draws])
    assert set(kelvin.tolist()) == set(np.arange(2000.0, 9901.0, 100.0).tolist())   # all 80, nothing else
    counts = np.unique(kelvin, return_counts=True)[1]
    assert counts.min() > 20 and counts.max() < 85          # uniform: 50 expected each
    for k, rgb in draws[:50]:
        th = colour.kelvin_to_rgb_tanner_helland(k)
        assert np.linalg.norm(rgb) == pytest.approx(1.0) and rgb == pytest.approx(th / np.linalg.norm(th))


# --------------------------------------------------------------------------- the preset's draws
def _srgb_hsv(linear):
    return colorsys.rgb_to_hsv(*colour.srgb_encode(np.asarray(linear)).tolist())


def test_preset_draws_obey_the_stated_ranges():
    cfg = sid2_paper_config()
    default = GeneratorConfig()
    assert (cfg.light_colour, cfg.backgrounds, cfg.colour_prior, cfg.object_parts) == (
        "tanner-helland", "library", "pastel", (1, 11))
    library = textures.background_library()
    parts, objects_per_scene = [], []
    for i in range(150):
        s = sample_scene(cfg, 3, i)
        light = s.light
        assert light.duv is None and light.cct_k % 100 == 0 and 2000 <= light.cct_k <= 9900
        th = colour.kelvin_to_rgb_tanner_helland(light.cct_k)
        assert light.rgb == pytest.approx(tuple(th / np.linalg.norm(th)), abs=1e-12)   # renderer's colour
        # geometry and camera as the default
        assert default.camera_tilt_deg[0] <= s.camera.tilt_deg <= default.camera_tilt_deg[1]
        assert s.camera.r_m == default.camera_r_m and s.camera.fov_deg == default.fov_deg
        assert light.tilt_deg in np.arange(30.0, 90.1, 5.0) and light.pan_deg == int(light.pan_deg)
        assert default.light_r_m[0] <= light.r_m <= default.light_r_m[1]
        assert default.n_walls[0] <= s.room.n_walls <= default.n_walls[1]
        # one library background: every wall carries its wall texture, the floor its floor texture
        tag = s.room.floor_texture["background"]
        k = int(tag.split(":")[1])
        assert tag == f"library:{k:03d}" and s.room.floor_texture == library[k][1]
        assert all(w == library[k][0] for w in s.room.wall_textures)
        assert s.colour_prior == "pastel"
        objects_per_scene.append(len(s.objects))
        for o in s.objects:
            parts.append(len(o.colours))
            for c in o.colours:
                h, sat, v = _srgb_hsv(c)
                assert 0.23 - 2e-3 <= sat <= 0.40 + 2e-3 and v == pytest.approx(0.87, abs=2e-3)
    assert set(objects_per_scene) == {1, 2, 3}
    assert min(parts) >= 1 and max(parts) <= 11 and 5 <= np.median(parts) <= 7


def test_preset_labels_the_light_with_the_triplet_it_renders():
    """The record's label (rgb and the 7-vector) is the Tanner-Helland triplet of the scene."""
    from relight import frames
    from relight.dataset import record_for
    s = sample_scene(sid2_paper_config(), 5, 1)
    rec = record_for(s, "test")
    th = colour.kelvin_to_rgb_tanner_helland(rec["light"]["cct_k"])
    assert rec["light"]["rgb"] == pytest.approx(list(th / np.linalg.norm(th)), abs=1e-12)
    _, _, rgb = frames.decode_y(np.array(rec["y"]), s.camera.tilt_deg, 0.0)
    assert np.asarray(rgb) / np.linalg.norm(rgb) == pytest.approx(th / np.linalg.norm(th), abs=1e-9)


def test_preset_options_order_preset_then_config_file_then_explicit(tmp_path):
    path = tmp_path / "c.json"
    path.write_text(json.dumps({"object_parts": [2, 4], "res": 64}))
    cfg = sid2_paper_config(str(path), backgrounds="unseen", res=None)
    assert cfg.object_parts == (2, 4) and cfg.res == 64 and cfg.backgrounds == "unseen"
    assert cfg.light_colour == "tanner-helland" and cfg.colour_prior == "pastel"
    assert sid2_paper_config(str(path), object_parts=(3, 3)).object_parts == (3, 3)
    assert SID2_PAPER_PRESET["object_parts"] == (1, 11)


# --------------------------------------------------------------------------- the library
def _library_digest() -> str:
    return hashlib.sha256(json.dumps(textures.background_library()).encode()).hexdigest()


def test_library_is_deterministic_closed_and_of_250_distinct_backgrounds():
    lib = textures.background_library()
    assert len(lib) == textures.LIBRARY_SIZE == 250
    assert [w["background"] for w, _ in lib] == [f"library:{k:03d}" for k in range(250)]
    assert lib == textures.background_library()
    lib[0][0]["colors"][0][0] = -1.0   # a caller's edit does not reach the library
    assert textures.background_library()[0][0]["colors"][0][0] != -1.0
    assert len({json.dumps(b) for b in lib}) == 250
    assert {t["kind"] for b in lib for t in b} <= set(textures.LIBRARY_KINDS)
    # the same library in a fresh process (no state, no cache): the seed alone makes it
    code = ("import hashlib, json; from relight.scene import textures; "
            "print(hashlib.sha256(json.dumps(textures.background_library()).encode()).hexdigest())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": ROOT})
    assert out.stdout.strip() == _library_digest()
    # and it is the seed's: the first background is the first draw of default_rng(LIBRARY_SEED)
    wall, floor = textures._draw_background(np.random.default_rng(textures.LIBRARY_SEED), "library:000")
    assert (wall, floor) == textures.background_library()[0]
    for t in lib[5]:   # each renders as a texture
        img = textures.make_texture(t, 16)
        assert img.shape == (16, 16, 3) and np.isfinite(img).all()


def test_unseen_backgrounds_are_disjoint_from_the_library():
    cfg = sid2_paper_config(backgrounds="unseen")
    lib_colours = textures.library_colours()
    lib_params = {json.dumps({k: v for k, v in t.items() if k != "background"}, sort_keys=True)
                  for b in textures.background_library() for t in b}
    seen = set()
    for i in range(200):
        s = sample_scene(cfg, 11, i)
        for t in (*s.room.wall_textures, s.room.floor_texture):
            assert t["background"] == "unseen"
            assert not any(tuple(c) in lib_colours for c in t["colors"])
            assert json.dumps({k: v for k, v in t.items() if k != "background"}, sort_keys=True) not in lib_params
            seen.add(json.dumps(t, sort_keys=True))
        assert s.light.duv is None and s.colour_prior == "pastel"   # the rest of the preset unchanged
    assert len(seen) > 300     # fresh backgrounds, not a second library
    with pytest.raises(ValueError):
        textures.sample_background(np.random.default_rng(0), "patterns")


def test_an_unseen_draw_sharing_a_library_colour_is_redrawn(monkeypatch):
    draws = np.random.default_rng(0)
    first = textures._draw_background(draws, "unseen")
    second = textures._draw_background(draws, "unseen")
    assert textures.sample_background(np.random.default_rng(0), "unseen") == first
    monkeypatch.setattr(textures, "library_colours", lambda: frozenset({tuple(first[1]["colors"][-1])}))
    assert textures.sample_background(np.random.default_rng(0), "unseen") == second


def test_seeds_reproduce_and_differ():
    cfg = sid2_paper_config()
    assert sample_scene(cfg, 4, 9).to_json() == sample_scene(cfg, 4, 9).to_json()
    assert sample_scene(cfg, 4, 9).to_json() != sample_scene(cfg, 5, 9).to_json()


# --------------------------------------------------------------------------- the command
def _run(*args):
    return subprocess.run([sys.executable, "-m", "relight", "generate", "--quiet", *args],
                          capture_output=True, text=True, env={**os.environ, "PYTHONPATH": ROOT})


def _files(folder):
    out = {}
    for root, _, names in os.walk(folder):
        for n in names:
            if not n.startswith(".relight"):
                p = os.path.join(root, n)
                out[os.path.relpath(p, folder)] = open(p, "rb").read()
    return out


def test_generate_preset_is_recorded_byte_identical_and_resumable(tmp_path):
    common = ["--preset", "sid2-paper", "--res", "16", "--spp", "1", "--seed", "3"]
    a, b = tmp_path / "a", tmp_path / "b"
    assert _run(*common, "--count", "3", "--out", str(a)).returncode == 0
    r = _run(*common, "--count", "2", "--out", str(b))
    assert r.returncode == 0, r.stderr
    r = _run(*common, "--count", "3", "--out", str(b))     # resumes: one more image
    assert r.returncode == 0 and "1 images written, 2 already there" in r.stdout, r.stdout + r.stderr
    fa, fb = _files(a), _files(b)
    assert fa.keys() == fb.keys() and all(fa[k] == fb[k] for k in fa if k != "manifest.jsonl")
    assert sorted(fa["manifest.jsonl"].splitlines()) == sorted(fb["manifest.jsonl"].splitlines())
    card = json.loads(fa["dataset.json"])["config"]
    assert (card["light_colour"], card["backgrounds"], card["colour_prior"], card["object_parts"]) == (
        "tanner-helland", "library", "pastel", [1, 11])
    scene = json.loads(fa[os.path.join("scenes", "000000.json")])
    assert scene["colour_prior"] == "pastel" and scene["light"]["duv"] is None
    assert scene["room"]["floor_texture"]["background"].startswith("library:")
    # the unseen variant: another folder, its card says so; mixing settings in one folder is refused
    u = tmp_path / "u"
    assert _run(*common, "--backgrounds", "unseen", "--count", "1", "--out", str(u)).returncode == 0
    assert json.load(open(u / "dataset.json"))["config"]["backgrounds"] == "unseen"
    r = _run(*common, "--backgrounds", "unseen", "--count", "4", "--out", str(a))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "other settings" in r.stderr
    assert _files(a) == fa

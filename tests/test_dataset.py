"""Dataset generation: records agree with the conventions, resume, kill -9 safety, re-render."""
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from relight import frames
from relight.dataset import read_manifest
from relight.generator.run import generate
from relight.generator.sampling import GeneratorConfig

POS_TOL_M = 1e-6
Y_TOL = 1e-9
CFG = GeneratorConfig(res=24, spp=2)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory, mi):
    out = tmp_path_factory.mktemp("ds")
    stats = generate(out, 8, seed=11, cfg=CFG, progress=False)
    assert stats.written == 8
    return out


def test_records_follow_conventions(tiny):
    from PIL import Image
    from relight.imageio import read_exr
    recs = read_manifest(tiny)
    assert [r["id"] for r in recs] == [f"{i:06d}" for i in range(8)]
    for r in recs:
        light, cam = r["light"], r["camera"]
        assert np.allclose(light["position_m"], frames.spherical_to_cartesian(
            light["r_m"], light["pan_deg"], light["tilt_deg"]), atol=POS_TOL_M)
        assert np.allclose(cam["position_m"], frames.spherical_to_cartesian(
            cam["r_m"], cam["pan_deg"], cam["tilt_deg"]), atol=POS_TOL_M)
        assert np.allclose(r["y"], frames.encode_y(light["pan_deg"], light["tilt_deg"], light["rgb"],
                                                   cam["tilt_deg"], cam["pan_deg"]), atol=Y_TOL)
        assert np.linalg.norm(light["rgb"]) == pytest.approx(1.0, abs=1e-9)
        assert 20 <= light["r_m"] <= 50 and 30 <= light["tilt_deg"] <= 90 and light["tilt_deg"] % 5 == 0
        assert 0 <= light["pan_deg"] < 360 and light["pan_deg"] == int(light["pan_deg"])
        assert cam["r_m"] == 20 and cam["pan_deg"] == 0 and 10 <= cam["tilt_deg"] <= 70
        assert r["pan_rel_deg"] == pytest.approx(frames.pan_rel_deg(light["pan_deg"], cam["pan_deg"]))
        assert 2500 <= light["cct_k"] <= 10000 and abs(light["duv"]) <= 0.01
        assert r["split"] in ("train", "val", "test") and 1 <= r["n_objects"] <= 3
        png = np.asarray(Image.open(tiny / r["image"]))
        assert png.shape == (24, 24, 3) and png.dtype == np.uint8
        assert read_exr(tiny / r["exr"]).shape == (24, 24, 3)
        assert json.loads((tiny / r["scene"]).read_text())["format"] == "relight.scene/v1"
    card = json.loads((tiny / "dataset.json").read_text())
    assert card["seed"] == 11 and card["config"]["res"] == 24 and card["count"] == 8


def test_rerender_from_scene_file_is_identical(tiny):
    from relight.dataset import load_spec
    from relight.imageio import read_exr
    from relight.scene.build import render_spec
    rec = read_manifest(tiny)[5]
    assert np.array_equal(render_spec(load_spec(tiny, rec)), read_exr(tiny / rec["exr"]))


def test_resume_never_duplicates(tmp_path, mi):
    assert generate(tmp_path, 3, seed=4, cfg=CFG, progress=False).written == 3
    again = generate(tmp_path, 3, seed=4, cfg=CFG, progress=False)
    assert again.written == 0 and again.skipped == 3
    more = generate(tmp_path, 5, seed=4, cfg=CFG, progress=False)
    assert more.written == 2
    ids = [r["id"] for r in read_manifest(tmp_path)]
    assert sorted(ids) == [f"{i:06d}" for i in range(5)] and len(set(ids)) == 5


def test_partial_last_line_is_ignored_and_repaired(tmp_path, mi):
    generate(tmp_path, 2, seed=4, cfg=CFG, progress=False)
    with open(tmp_path / "manifest.jsonl", "ab") as f:
        f.write(b'{"id": "000002", "ima')            # a writer killed mid-line
    assert len(read_manifest(tmp_path)) == 2
    assert generate(tmp_path, 3, seed=4, cfg=CFG, progress=False).written == 1
    assert [r["id"] for r in read_manifest(tmp_path)] == ["000000", "000001", "000002"]


def test_same_index_same_image_across_runs(tmp_path, tiny, mi):
    generate(tmp_path, 2, seed=11, cfg=CFG, progress=False)
    a = (tmp_path / "images" / "000001.png").read_bytes()
    b = (tiny / "images" / "000001.png").read_bytes()
    assert a == b


@pytest.mark.slow   # two generate processes from a cold start: ~25 s on 2 cores
def test_kill_minus_9_leaves_consistent_manifest(tmp_path, mi):
    from PIL import Image
    from relight.imageio import read_exr
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "relight.cli", "generate", "--count", "40", "--res", "24", "--spp", "2",
           "--seed", "9", "--out", str(out), "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    manifest = out / "manifest.jsonl"
    deadline = time.time() + 120
    while time.time() < deadline:
        if manifest.exists() and manifest.read_bytes().count(b"\n") >= 3:
            break
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    recs = read_manifest(out)
    assert 3 <= len(recs) < 40
    for r in recs:   # every record's files are complete
        assert np.asarray(Image.open(out / r["image"])).shape == (24, 24, 3)
        assert read_exr(out / r["exr"]).shape == (24, 24, 3)
        json.loads((out / r["scene"]).read_text())
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    ids = [r["id"] for r in read_manifest(out)]
    assert sorted(ids) == [f"{i:06d}" for i in range(40)]


def test_other_settings_refuse_to_mix(tmp_path, mi):
    from relight.dataset import DatasetError
    generate(tmp_path, 1, seed=4, cfg=CFG, progress=False)
    with pytest.raises(DatasetError):
        generate(tmp_path, 2, seed=5, cfg=CFG, progress=False)


def test_card_written_before_a_setting_existed_still_resumes(tmp_path, mi):
    # a card without a later setting (object_parts) reads it as the value used before the
    # setting existed: the same dataset resumes; a card whose value differs from the
    # run's still refuses, and so does a card without a sampler (made with
    # "independent") resumed under today's default sampler
    import dataclasses
    import json
    from relight.dataset import DatasetError
    one = dataclasses.replace(CFG, object_parts=(1, 1))   # the value before the setting existed
    generate(tmp_path, 1, seed=4, cfg=one, progress=False)
    card = json.loads((tmp_path / "dataset.json").read_text())
    del card["config"]["object_parts"]
    (tmp_path / "dataset.json").write_text(json.dumps(card))
    assert generate(tmp_path, 2, seed=4, cfg=one, progress=False).written == 1
    with pytest.raises(DatasetError, match=r"other settings \(object_parts \[1, 1\] there, \[2, 2\] here\)"):
        generate(tmp_path, 3, seed=4, cfg=dataclasses.replace(CFG, object_parts=(2, 2)), progress=False)
    assert CFG.sampler != "independent"
    del card["config"]["sampler"]
    (tmp_path / "dataset.json").write_text(json.dumps(card))
    with pytest.raises(DatasetError, match=f"other settings \\(sampler independent there, {CFG.sampler} here\\)"):
        generate(tmp_path, 3, seed=4, cfg=one, progress=False)


def test_card_written_before_the_photo_and_material_settings_still_resumes(tmp_path, mi):
    """Datasets made before void_fraction, glossy_fraction, metal_fraction, flash_* and
    ambient_* existed (their cards lack the keys) resume with those settings off."""
    import dataclasses
    import json
    from relight.dataset import DatasetError
    from relight.generator.sampling import LEGACY_CONFIG
    later = ("void_fraction", "glossy_fraction", "metal_fraction", "flash_fraction", "flash_cone_deg",
             "ambient_fraction", "ambient_ratio", "void_albedo")
    # exact: two settings written in code (no float computed here), "off" is today's default
    assert all(json.dumps(LEGACY_CONFIG[k]) == json.dumps(list(v) if isinstance(v, tuple) else v)  # exact
               for k, v in ((k, getattr(CFG, k)) for k in later))
    generate(tmp_path, 1, seed=4, cfg=CFG, progress=False)
    card = json.loads((tmp_path / "dataset.json").read_text())
    for k in later:
        del card["config"][k]
    (tmp_path / "dataset.json").write_text(json.dumps(card))
    assert generate(tmp_path, 2, seed=4, cfg=CFG, progress=False).written == 1
    with pytest.raises(DatasetError, match=r"other settings \(metal_fraction 0.0 there, 0.5 here\)"):
        generate(tmp_path, 3, seed=4, cfg=dataclasses.replace(CFG, metal_fraction=0.5), progress=False)


def test_split_is_deterministic_and_balanced():
    from relight.generator.sampling import split_of
    splits = [split_of(f"{i:06d}") for i in range(3000)]
    assert splits == [split_of(f"{i:06d}") for i in range(3000)]
    frac = {s: splits.count(s) / 3000 for s in ("train", "val", "test")}
    assert abs(frac["train"] - 0.8) < 0.03 and abs(frac["val"] - 0.1) < 0.02


def test_sampling_rules():
    from relight.generator.sampling import sample_scene
    cfg = GeneratorConfig()
    for i in range(40):
        spec = sample_scene(cfg, 0, i)
        objs = spec.objects
        assert 1 <= len(objs) <= 3 and 4 <= spec.room.n_walls <= 8
        for a in range(len(objs)):       # bounding circles never overlap
            for b in range(a + 1, len(objs)):
                d = np.hypot(objs[a].position_m[0] - objs[b].position_m[0],
                             objs[a].position_m[1] - objs[b].position_m[1])
                assert d >= objs[a].size_m + objs[b].size_m
        # light inside the room (never occluded from the centre), camera inside too
        apothem = spec.room.inradius_m
        assert spec.light.r_m * np.cos(np.radians(spec.light.tilt_deg)) < apothem
        assert spec.room.inradius_m >= 2 * spec.light.r_m and spec.camera.r_m < apothem
    assert sample_scene(cfg, 0, 3) == sample_scene(cfg, 0, 3)
    assert sample_scene(cfg, 0, 3) != sample_scene(cfg, 1, 3)


def test_workers_give_the_same_dataset(tmp_path, tiny, mi):
    # Two worker processes (one thread each) render the same images as one process.
    stats = generate(tmp_path, 4, seed=11, cfg=CFG, progress=False, workers=2)
    assert stats.written == 4
    recs = {r["id"]: r for r in read_manifest(tmp_path)}
    assert sorted(recs) == [f"{i:06d}" for i in range(4)]
    for i in range(4):
        assert (tmp_path / "images" / f"{i:06d}.png").read_bytes() == (tiny / "images" / f"{i:06d}.png").read_bytes()

"""The MID-like experiment: ``generate --preset mid`` records, the physical ground truth
against closed forms, ``train --init`` and Tables 4-5 on known inputs."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TINY = {"res": 32, "spp": 4, "probe_spp": 4, "cube_res": 8, "cube_spp": 4, "directions": [0, 4],
        "n_clutter": [1, 2]}


def _relight(*argv, timeout=600):
    env = dict(os.environ, RELIGHT_THREADS="1")
    return subprocess.run([sys.executable, "-m", "relight", *argv], capture_output=True, text=True,
                          timeout=timeout, env=env, cwd=REPO)


def _angle_deg(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return math.degrees(math.acos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))


def test_preset_mid_records_and_masked_copies(tmp_path):
    cfg = tmp_path / "tiny.json"
    cfg.write_text(json.dumps(TINY))
    out = tmp_path / "mid"
    r = _relight("generate", "--preset", "mid", "--count", "1", "--out", str(out), "--config", str(cfg), "--quiet")
    assert r.returncode == 0, r.stderr
    doc = json.loads((out / "scenes" / "0000.json").read_text())
    records = [json.loads(line) for line in (out / "manifest.jsonl").read_text().splitlines()]
    assert len(records) + len(doc["procedure_failed"]) == 2       # two flash directions
    assert (out / "images" / "0000_ref.png").is_file()             # the reference image
    from relight.imageio import read_srgb8
    from relight.experiments.mid.dataset import sphere_mask
    from relight.experiments.mid.scene import MidConfig, sample_mid_scene
    mcfg = MidConfig.from_dict(TINY)
    mask = sphere_mask(mcfg, sample_mid_scene(mcfg, 0, 0))
    for iid in ("0000_00", "0000_04"):
        vis, masked = read_srgb8(out / "images" / f"{iid}.png")[0], read_srgb8(out / "masked" / f"{iid}.png")[0]
        assert vis.shape == masked.shape == (32, 32, 3)
        assert np.array_equal(vis[~mask], masked[~mask])          # painted out only where the spheres are
        assert mask.sum() > 10
    for rec in records:
        assert rec["split"] == "train" and rec["image_masked"].startswith("masked/")
        for which in ("physical", "procedure"):
            truth = rec[which]
            assert 0 <= truth["pan_rel_deg"] < 360 and -90 <= truth["tilt_deg"] <= 90
            assert abs(np.linalg.norm(truth["rgb"]) - 1) < 1e-6
        assert rec["light"]["pan_deg"] == rec["procedure"]["pan_rel_deg"]    # trained on the procedure's
        assert len(rec["physical"]["y"]) == 7
    # re-running the same command resumes: nothing to do, same manifest
    before = (out / "manifest.jsonl").read_bytes()
    r = _relight("generate", "--preset", "mid", "--count", "1", "--out", str(out), "--config", str(cfg), "--quiet")
    assert r.returncode == 0 and "1 already there" in r.stdout
    assert (out / "manifest.jsonl").read_bytes() == before
    r = _relight("generate", "--preset", "mid", "--count", "1", "--out", str(tmp_path / "x"), "--sampler", "ldsampler")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1


def _empty_room():
    from relight.experiments.mid.scene import MidScene
    return MidScene(index=0, seed=0, room_half=(2.0, 2.0), ceiling_m=2.5,
                    camera_position=np.array([1.7, 0.0, 1.5]), camera_tilt_deg=20.0,
                    wall_rgb=[[0.5] * 3] * 5, floor_rgb=[0.3] * 3,
                    chrome_centre=np.array([0.0, 0.0, 0.15]), gray_centre=np.array([0.0, 0.8, 0.15]),
                    sphere_radius=(0.15, 0.15))


def test_physical_truth_closed_forms(mi):
    """An empty room: (a) the flash aimed at the chrome sphere: the light arrives from the
    flash; (b) the flash aimed at the ceiling: the brightest light is the ceiling's lit
    spot straight above the flash (Lambertian ceiling, the spot's peak irradiance there)."""
    from relight.experiments.mid.scene import MidConfig, MidRenderer
    scene = _empty_room()
    # the flash in a 0.12 m snoot (a ~40 deg beam): the lit spot is compact, its centre above the flash
    cfg = MidConfig(res=16, spp=1, probe_spp=1, cube_res=16, cube_spp=16, directions=(0,), snoot_m=0.12)
    renderer = MidRenderer(scene, cfg)
    to_flash = scene.flash_position - scene.chrome_centre
    _, _, truth = renderer.render(-to_flash / np.linalg.norm(to_flash), 3)
    assert _angle_deg(truth["to_light_world"], to_flash) < 0.5
    assert truth["direct_share"] > 0.5
    _, _, truth = renderer.render(np.array([0.0, 0.0, 1.0]), 5)
    spot = np.array([scene.flash_position[0], scene.flash_position[1], scene.ceiling_m])
    assert truth["direct_share"] == 0.0
    assert _angle_deg(truth["to_light_world"], spot - scene.chrome_centre) < 4.0


def _tiny_dataset(root, n_train=4, n_val=2):
    """A hand-made dataset with masked copies (random images, known targets)."""
    from relight import frames
    from relight.imageio import write_png
    rng = np.random.default_rng(0)
    os.makedirs(root / "images"), os.makedirs(root / "masked")
    lines = []
    for i in range(n_train + n_val):
        iid = f"{i:04d}_00"
        img = rng.uniform(0, 1, (32, 32, 3)).astype(np.float32)
        write_png(root / "images" / f"{iid}.png", img)
        write_png(root / "masked" / f"{iid}.png", img * 0.5)
        pan, tilt = float(rng.uniform(0, 360)), float(rng.uniform(20, 80))
        y = frames.encode_y(pan, tilt, np.ones(3) / math.sqrt(3), 20.0)
        lines.append(json.dumps({"id": iid, "image": f"images/{iid}.png", "image_masked": f"masked/{iid}.png",
                                 "split": "train" if i < n_train else "val",
                                 "light": {"pan_deg": pan, "tilt_deg": tilt, "rgb": [1, 1, 1]},
                                 "camera": {"pan_deg": 0.0, "tilt_deg": 20.0}, "pan_rel_deg": pan,
                                 "y": [float(v) for v in y]}))
    (root / "manifest.jsonl").write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("images,key", [("visible", "image"), ("masked", "image_masked")])
def test_train_init_starts_from_the_model(tmp_path, images, key):
    import torch
    from relight.net.data import LightDataset
    from relight.net.evaluate import run_model
    from relight.net.io import SHIPPED_MODEL, load_model_file
    from relight.net.loss import light_loss
    data = tmp_path / "data"
    _tiny_dataset(data)
    run = tmp_path / "run"
    r = _relight("train", "--data", str(data), "--out", str(run), "--init", SHIPPED_MODEL, "--images", images,
                 "--epochs", "1", "--batch-size", "2", "--quiet")
    assert r.returncode == 0, r.stderr
    settings = json.loads((run / "settings.json").read_text())
    model = load_model_file(SHIPPED_MODEL)
    val = LightDataset(data, "val", 128, image_key=key)
    y, _ = run_model(model, val, 8, with_kappa=True)
    target = torch.from_numpy(np.stack([val.target(i) for i in range(len(val))])).float()
    expected = float(light_loss(torch.from_numpy(y), target))
    assert settings["init_val_loss"] == pytest.approx(expected, rel=1e-5)
    assert settings["image_key"] == key
    assert (run / "best.safetensors").is_file()


def test_train_init_refuses_a_bad_model(tmp_path):
    data = tmp_path / "data"
    _tiny_dataset(data, 2, 1)
    bad = tmp_path / "bad.safetensors"
    bad.write_bytes(b"not a model at all")
    run = tmp_path / "run"
    r = _relight("train", "--data", str(data), "--out", str(run), "--init", str(bad), "--epochs", "1", "--quiet")
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1 and "bad.safetensors" in r.stderr
    assert not run.exists()


def test_tables_on_known_inputs():
    from relight.experiments.mid import dataset as mid
    truth = {"pan_rel_deg": np.array([0.0, 30.0, 180.0, 200.0]), "tilt_deg": np.array([30.0, 40.0, 50.0, 60.0]),
             "rgb": np.ones((4, 3))}
    pred = {"pan_rel_deg": np.array([10.0, 30.0, 180.0, 160.0]), "tilt_deg": np.array([30.0, 44.0, 50.0, 60.0]),
            "rgb": np.array([[1, 1, 1], [1, 1, 1], [1, 1, 1.2], [1, 1, 1]], float)}
    err = mid.errors_against(pred, truth)
    assert err["pan"].tolist() == pytest.approx([10.0, 0.0, 0.0, 40.0])
    assert err["tilt"].tolist() == pytest.approx([0.0, 4.0, 0.0, 0.0])
    # direction of a pure pan error at tilt t: the angle between (t, p) and (t, p + dp)
    d0 = math.degrees(math.acos(math.cos(math.radians(30)) ** 2 * math.cos(math.radians(10))
                                + math.sin(math.radians(30)) ** 2))
    assert err["direction"][0] == pytest.approx(d0)
    c2 = math.degrees(math.acos(3.2 / math.sqrt(3) / math.sqrt(3.44)))
    assert err["colour"].tolist() == pytest.approx([0, 0, c2, 0], abs=1e-6)
    rows = mid.table4_rows(err)
    assert rows["mean"][0] == pytest.approx(12.5) and rows["median"][0] == pytest.approx(5.0)
    assert rows["mean"][1] == pytest.approx(1.0) and rows["median"][3] == pytest.approx(0.0, abs=1e-6)
    t5 = mid.table5_rows(err, truth)
    assert (t5["n_front"], t5["n_back"]) == (2, 2)
    assert t5["front"][0] == pytest.approx(5.0) and t5["back"][0] == pytest.approx(20.0)
    assert t5["back"][3] == pytest.approx(c2 / 2)
    text = mid.format_table4({("unmasked", "procedure"): rows})
    assert "10.83" in text and "12.50" in text
    assert "31.23" in mid.format_table5({"procedure": t5})


def test_one_flash_colour_for_every_room_unless_asked():
    """MID's photographs come from one flash: by default every room's flash has the
    colour of FLASH_CCT_K on the Planckian locus; flash_cct_k=None draws one per room.
    The rooms themselves do not depend on the choice."""
    from relight.colour import cct_duv_to_rgb
    from relight.errors import ConfigError
    from relight.experiments.mid.dataset import mid_config
    from relight.experiments.mid import scene as sm
    fixed = [sm.sample_mid_scene(sm.MidConfig(), 3, i) for i in range(4)]
    free = [sm.sample_mid_scene(sm.MidConfig(flash_cct_k=None), 3, i) for i in range(4)]
    want = np.asarray(cct_duv_to_rgb(sm.FLASH_CCT_K, 0.0))
    for a, b in zip(fixed, free):
        assert a.flash_cct_k == sm.FLASH_CCT_K
        assert np.allclose(a.flash_rgb, want)
        assert 5000.0 <= b.flash_cct_k <= 6500.0
        assert np.array_equal(a.chrome_centre, b.chrome_centre) and a.wall_rgb == b.wall_rgb
    assert len({round(b.flash_cct_k, 3) for b in free}) == 4
    for bad in (100.0, float("nan"), "warm"):
        with pytest.raises(ConfigError):
            mid_config(flash_cct_k=bad)


def test_dominant_direction_equals_the_exhaustive_cap_search():
    """The neighbour-tree cap search gives the exhaustive N x N search's answer (which
    needs N^2 memory: 5 GB at 64 px a face), and finds a lone bright cap's centre."""
    from relight.experiments.mid.scene import cube_directions, dominant_direction
    rng = np.random.default_rng(4)
    dirs, omega = cube_directions(12)
    dirs, omega = dirs.reshape(-1, 3), omega.ravel()
    cos_cap = math.cos(math.radians(10.0))
    for _ in range(4):
        w = rng.random(len(dirs)) ** 8 * omega
        inside = (dirs @ dirs.T) >= cos_cap
        sel = inside[int(np.argmax(inside @ w))]
        want = (dirs[sel] * w[sel, None]).sum(0)
        assert np.allclose(dominant_direction(dirs, w), want / np.linalg.norm(want), atol=1e-12)
    target = np.array([0.3, 0.5, -0.8]) / np.linalg.norm([0.3, 0.5, -0.8])
    dirs, omega = cube_directions(48)
    dirs, omega = dirs.reshape(-1, 3), omega.ravel()
    w = omega * np.exp(-((1 - dirs @ target) / 0.002))      # a ~3.6 deg wide lobe
    assert _angle_deg(dominant_direction(dirs, w), target) < 0.3


def test_reference_expectation_points_from_the_sphere_to_the_flash():
    """The reference correction's assumed direction: the sphere's distance from its
    outline circle (probe-photograph pixels) and known radius, then the direction from
    its centre to the flash above the camera -- against the sampled room's geometry."""
    from relight import frames
    from relight.experiments.mid.dataset import chrome_distance_m, expected_reference
    from relight.probe.geometry import Camera, outline_circle
    from relight.experiments.mid import scene as sm
    cfg = sm.MidConfig()
    size = cfg.res * cfg.probe_zoom     # the probe photograph's camera, built here independently
    for index in range(6):
        scene = sm.sample_mid_scene(cfg, 2, index)
        sphere = sm.probe_sphere(scene, "chrome")
        circle = outline_circle(Camera.from_fov(size, size, cfg.fov_deg), sphere)
        centre = np.asarray(sphere.centre)
        entry = {"chrome_circle": circle, "chrome_centre_camera": (centre / np.linalg.norm(centre)).tolist()}
        distance = chrome_distance_m(entry, cfg, scene.sphere_radius[0])
        assert distance == pytest.approx(np.linalg.norm(scene.chrome_centre - scene.camera_position), rel=0.01)
        to_flash = sm.camera_camera_frame(scene, scene.flash_position) - centre
        want = frames.camera_to_pan_tilt(to_flash / np.linalg.norm(to_flash), scene.camera_tilt_deg)
        got = expected_reference(entry, scene.camera_tilt_deg, distance)
        assert abs(frames.wrap180(got[0] - want[0])) < 0.1 and abs(got[1] - want[1]) < 0.1

"""From renders to photographs: the photo preset's draws, the camera-pipeline augmentation,
the camera-tilt head, answers in the camera frame, the out-of-distribution flag and the
photo-set reader."""
from __future__ import annotations

import dataclasses
import math
import os

import numpy as np
import pytest
import torch

from relight import colour, frames
from relight.errors import ConfigError, DatasetError
from relight.imageio import to_srgb8
from relight.net.augment import HABLE_WHITE, PipelineAugment, hable
from relight.net.model import LightNet, NetConfig, camera_tilt_deg
from relight.generator.sampling import MIN_CAMERA_R_M, PRESETS, VOID_ALBEDO, GeneratorConfig, sample_scene

SEED = 11
N_SCENES = 200


# ----------------------------------------------------------------------------- generator
def test_photo_preset_draws_obey_their_ranges():
    cfg = GeneratorConfig(**PRESETS["photo"])
    lo_fov, hi_fov = cfg.fov_range_deg
    lo_w, hi_w = cfg.view_halfwidth_m
    voids = 0
    for i in range(N_SCENES):
        spec = sample_scene(cfg, SEED, i)
        cam = spec.camera
        assert lo_fov <= cam.fov_deg <= hi_fov
        assert cfg.camera_tilt_deg[0] <= cam.tilt_deg <= cfg.camera_tilt_deg[1]
        assert cfg.light_tilt_deg[0] <= spec.light.tilt_deg <= cfg.light_tilt_deg[1]
        # the camera distance frames a half-width in the drawn range (or stops at MIN_CAMERA_R_M)
        halfwidth = cam.r_m * math.tan(math.radians(cam.fov_deg) / 2)
        assert cam.r_m >= MIN_CAMERA_R_M - 1e-9
        assert halfwidth <= hi_w + 1e-2 or cam.r_m == pytest.approx(MIN_CAMERA_R_M)
        assert halfwidth >= lo_w - 1e-2
        floor = np.asarray(spec.room.floor_texture["colors"], dtype=float)
        if spec.room.floor_texture["kind"] == "checker" and np.all(floor <= VOID_ALBEDO):
            voids += 1
            for wall in spec.room.wall_textures:
                assert np.all(np.asarray(wall["colors"], dtype=float) <= VOID_ALBEDO)
    # void share 0.5: 200 draws lie within 4 standard deviations (sd = sqrt(200 / 4) = 7.1)
    assert abs(voids - N_SCENES * cfg.void_fraction) <= 4 * math.sqrt(N_SCENES / 4)


def test_photo_draws_come_last_so_other_draws_are_unchanged():
    """A void scene has the same light, camera tilt and objects as the default scene of the
    same seed and index: the photo-like draws are taken after every other draw."""
    plain, void = GeneratorConfig(), GeneratorConfig(void_fraction=1.0)
    for i in range(5):
        a, b = sample_scene(plain, SEED, i), sample_scene(void, SEED, i)
        assert a.light == b.light and a.objects == b.objects and a.camera == b.camera
        assert a.render == b.render
        assert b.room.floor_texture != a.room.floor_texture


def test_void_albedo_sets_the_backdrop_grey_and_nothing_else():
    """void_albedo (0.02, 0.05), black cloth rather than an ideal black: the same uniform
    draw scaled to the new range (rounded to 1e-4), every other draw as with the default."""
    dark = GeneratorConfig(void_fraction=1.0)
    cloth = dataclasses.replace(dark, void_albedo=(0.02, 0.05))
    for i in range(8):
        a, b = sample_scene(dark, SEED, i), sample_scene(cloth, SEED, i)
        assert a.light == b.light and a.objects == b.objects and a.camera == b.camera and a.render == b.render
        for ta, tb in zip((a.room.floor_texture, *a.room.wall_textures), (b.room.floor_texture, *b.room.wall_textures)):
            ga, gb = ta["colors"][0][0], tb["colors"][0][0]
            assert 0.0 <= ga <= VOID_ALBEDO and 0.02 <= gb <= 0.05
            assert gb == pytest.approx(0.02 + 3.0 * ga, abs=2e-4)   # u = ga / 0.01, both rounded to 1e-4
    with pytest.raises(ConfigError):
        GeneratorConfig(void_albedo=(0.05, 0.02))
    with pytest.raises(ConfigError):
        GeneratorConfig(void_albedo=(0.0, 1.5))


def test_flash_lights_lie_near_the_camera_and_are_drawn_last():
    """flash_fraction 0.5 over the photo preset: about half the lights lie within
    flash_cone_deg of the direction to the camera (none below light_tilt_deg's minimum);
    everything else is the scene drawn without it."""
    base = GeneratorConfig.from_file(None, preset="photo")
    flash = dataclasses.replace(base, flash_fraction=0.5, flash_cone_deg=30.0)
    moved = 0
    for i in range(N_SCENES):
        a, b = sample_scene(base, SEED, i), sample_scene(flash, SEED, i)
        assert a.camera == b.camera and a.room == b.room and a.objects == b.objects and a.render == b.render
        assert (a.light.r_m, a.light.strength) == (b.light.r_m, b.light.strength)
        np.testing.assert_allclose(a.light.rgb, b.light.rgb, rtol=1e-12)   # re-normalised: last bits
        if (a.light.pan_deg, a.light.tilt_deg) != (b.light.pan_deg, b.light.tilt_deg):
            moved += 1
            to_cam = frames.direction(b.camera.pan_deg, b.camera.tilt_deg)
            angle = math.degrees(math.acos(np.clip(frames.direction(b.light.pan_deg, b.light.tilt_deg) @ to_cam, -1, 1)))
            assert angle <= 30.0 + 0.02 and b.light.tilt_deg >= base.light_tilt_deg[0]
    assert abs(moved - N_SCENES / 2) <= 4 * math.sqrt(N_SCENES / 4)   # binomial, 4 sd


def test_photo_settings_are_validated():
    for bad in ({"void_fraction": 1.5}, {"fov_range_deg": (90.0, 20.0)}, {"view_halfwidth_m": (0.0, 3.0)},
                {"flash_fraction": 1.2}, {"flash_cone_deg": 120.0}):
        with pytest.raises(ConfigError):
            GeneratorConfig(**bad)


# ----------------------------------------------------------------------------- augmentation
def _linear(seed=0, shape=(24, 24, 3)):
    return np.random.default_rng(seed).uniform(0.0, 1.0, shape)


def test_identity_pipeline_is_how_the_pngs_are_written():
    x = _linear()
    assert np.array_equal(PipelineAugment.none().apply(x, np.random.default_rng(0)), to_srgb8(x))


def test_exposure_alone_is_a_gain_before_the_srgb_curve():
    """With every other effect switched off, +1 EV is to_srgb8 of twice the image (to one
    code value: the noise term left on is 1e-6 of a code value)."""
    only_exposure = PipelineAugment(exposure_ev=(1.0, 1.0), photon_a=(1e-18, 1e-18), read_sigma=(0.0, 0.0),
                                    vignette=(0.0, 0.0), blur_px=(0.0, 0.0), tone_curves=("srgb",), jpeg_p=0.0)
    x = _linear(1)
    out = only_exposure.apply(x, np.random.default_rng(3)).astype(int)
    assert np.abs(out - to_srgb8(2.0 * x).astype(int)).max() <= 1


def test_pipeline_keeps_grey_grey():
    """Every effect but JPEG acts on the three channels alike, so a grey image stays grey:
    the light's colour (the label) is never changed by the pipeline."""
    grey = np.repeat(_linear(2, (24, 24, 1)), 3, axis=2)
    no_jpeg = PipelineAugment(jpeg_p=0.0, photon_a=(1e-18, 1e-18), read_sigma=(0.0, 0.0))
    for seed in range(5):
        out = no_jpeg.apply(grey, np.random.default_rng(seed))
        assert np.array_equal(out[..., 0], out[..., 1]) and np.array_equal(out[..., 1], out[..., 2])


def test_hable_curve_is_normalised_and_monotone():
    assert hable(np.array(0.0)) == pytest.approx(0.0, abs=1e-12)
    assert hable(np.array(HABLE_WHITE)) == pytest.approx(1.0, abs=1e-12)
    v = hable(np.linspace(0.0, HABLE_WHITE, 200))
    assert np.all(np.diff(v) > 0)


def test_pipeline_is_reproducible_from_its_seed():
    x, aug = _linear(4), PipelineAugment()
    a = aug.apply(x, np.random.default_rng([7, 1, 3, 1]))
    b = aug.apply(x, np.random.default_rng([7, 1, 3, 1]))
    assert np.array_equal(a, b)


# ----------------------------------------------------------------------------- camera head
def _net(**kw):
    torch.manual_seed(0)
    return LightNet(NetConfig(res=32, width=8, **kw)).eval()


def test_camera_tilt_from_sin_cos():
    t = np.radians([0.0, 30.0, 70.0, -10.0])
    out = camera_tilt_deg(torch.tensor(np.stack([np.sin(t), np.cos(t)], 1) * 3.0))   # scale-free
    assert np.allclose(out.numpy(), [0.0, 30.0, 70.0, -10.0], atol=1e-9)


def test_adding_a_camera_head_keeps_every_other_output():
    from relight.net.train import camera_loss, with_camera_head
    net = _net()
    grown = with_camera_head(net).eval()
    x = torch.rand(3, 3, 32, 32)
    with torch.no_grad():
        y0 = net(x)
        y1, _, camera = grown.forward_full(x)
    assert torch.equal(y0, y1) and camera.shape == (3, 2)
    tilts = torch.tensor([10.0, 40.0, 65.0])
    exact = torch.stack([torch.sin(torch.deg2rad(tilts)), torch.cos(torch.deg2rad(tilts))], 1)
    assert float(camera_loss(exact, tilts)) == pytest.approx(0.0, abs=1e-12)


def test_predictions_answer_in_the_camera_frame():
    """to_light_camera is the decoded light seen from the camera: turned back into the world
    with the same camera tilt it gives the decoded pan and tilt; a model with a camera head
    decodes with its own tilt unless one is given."""
    from relight.net.predict import _predict_inputs
    net = _net(camera_head=True)
    x = [torch.rand(3, 32, 32) for _ in range(4)]
    own = _predict_inputs(net, x, None)
    given = _predict_inputs(net, x, [30.0] * 4)
    for p in own:
        assert p["camera_tilt_source"] == "predicted"
        assert np.linalg.norm(p["to_light_camera"]) == pytest.approx(1.0, abs=1e-12)
        back = frames.camera_to_world_vector(p["to_light_camera"], p["camera_tilt_deg"])
        assert np.allclose(back, frames.direction(p["pan_deg"], p["tilt_deg"]), atol=1e-9)
    assert all(p["camera_tilt_deg"] == 30.0 and p["camera_tilt_source"] == "given" for p in given)


def test_light_on_the_cameras_right_is_plus_x_in_the_camera_frame():
    """pan_rel 90 is the camera's right (conventions), so a light there, level with a level
    camera, is +x in the camera frame."""
    v = frames.world_to_camera(frames.direction(90.0, 0.0), 0.0)
    assert np.allclose(v, [1.0, 0.0, 0.0], atol=1e-12)


# ----------------------------------------------------------------------------- out of distribution
def test_ood_flags_images_unlike_the_fitting_set(tmp_path):
    from relight.net.io import load_model_file, save_model
    from relight.net.ood import OOD_CONE_DEG, fit_ood, ood_fields
    g = torch.Generator().manual_seed(0)
    held_out = 0.45 + 0.1 * torch.rand(160, 3, 32, 32, generator=g)      # dim grey noise
    fitted, summary = fit_ood(_net(kappa_head=True), held_out, dims=8)
    assert summary["ood_dims"] == 8
    inside = 0.45 + 0.1 * torch.rand(100, 3, 32, 32, generator=g)        # more of the same
    stripes = torch.zeros(20, 3, 32, 32)
    stripes[:, 0, :, ::2] = 1.0                                          # saturated red stripes
    flags_in = [f["ood"] for f in ood_fields(fitted, inside)]
    flags_out = ood_fields(fitted, stripes)
    assert np.mean(flags_in) <= 0.1          # threshold at the 99% quantile of the fitting set
    assert all(f["ood"] and f["cone90_deg"] == OOD_CONE_DEG for f in flags_out)
    path = tmp_path / "m.safetensors"
    save_model(path, fitted, {})
    again = load_model_file(path)
    assert [f["ood"] for f in ood_fields(again, stripes)] == [True] * 20


def test_ood_needs_enough_images():
    from relight.net.ood import fit_ood
    with pytest.raises(DatasetError):
        fit_ood(_net(), torch.rand(5, 3, 32, 32), dims=8)


# ----------------------------------------------------------------------------- photo sets
def test_photo_set_reader(tmp_path):
    from PIL import Image

    from relight.net.photos import read_photo_set
    (tmp_path / "lights.txt").write_text("2\n0 0 1\n0.6 0.8 0\n")
    for name in ("ball.0.png", "ball.1.png", "cup.1.png", "ball.mask.png"):
        Image.new("RGB", (8, 8)).save(tmp_path / name)
    files, truth = read_photo_set(str(tmp_path))
    assert [f.split("/")[-1] for f in files] == ["ball.0.png", "ball.1.png", "cup.1.png"]
    assert np.allclose(truth, [[0, 0, 1], [0.6, 0.8, 0], [0.6, 0.8, 0]])
    files, _ = read_photo_set(str(tmp_path), ("cup",))
    assert len(files) == 1
    (tmp_path / "lights.txt").write_text("3\n0 0 1\n")
    with pytest.raises(DatasetError):
        read_photo_set(str(tmp_path))


def test_backdrop_off_scores_the_photo_as_if_its_surroundings_were_black(tmp_path):
    """score_photo_set(surround="black") on a photo with a lit backdrop gives the answer of
    the same photo saved with its backdrop black; a missing mask is one DatasetError."""
    from PIL import Image

    from relight.net.photos import score_photo_set
    from relight.net.predict import load_model
    rng = np.random.default_rng(2)
    yy, xx = np.mgrid[:48, :64]
    mask = (yy - 24) ** 2 + (xx - 30) ** 2 < 15 ** 2
    lit, black = tmp_path / "lit", tmp_path / "black"
    for d in (lit, black):
        d.mkdir()
        (d / "lights.txt").write_text("2\n0 0 1\n0.6 0.8 0\n")
    for k in range(2):
        shade = (150 + 90 * (xx / 64.0 if k else yy / 48.0))[..., None] * np.ones(3)
        backdrop = rng.integers(20, 90, size=(48, 64, 3))
        photo = np.where(mask[..., None], shade, backdrop).astype(np.uint8)
        Image.fromarray(photo).save(lit / f"ball.{k}.png")
        Image.fromarray(np.where(mask[..., None], photo, 0).astype(np.uint8)).save(black / f"ball.{k}.png")
    Image.fromarray((mask * 255).astype(np.uint8)).save(lit / "ball.mask.png")
    model = load_model()
    off = score_photo_set(model, str(lit), camera_tilt_deg=10.0, surround="black")
    ref = score_photo_set(model, str(black), camera_tilt_deg=10.0)
    plain = score_photo_set(model, str(lit), camera_tilt_deg=10.0)
    assert off["id"] == ref["id"] == ["ball.0", "ball.1"]
    np.testing.assert_allclose(off["to_light_camera"], ref["to_light_camera"], atol=1e-5)
    assert np.max(np.abs(plain["to_light_camera"] - ref["to_light_camera"])) > 1e-3   # the backdrop mattered
    (lit / "ball.mask.png").unlink()
    with pytest.raises(DatasetError, match="no mask"):
        score_photo_set(model, str(lit), surround="black")


def test_calibrate_fits_only_the_ood_detector_in_mode_none(tmp_path):
    """``relight calibrate --mode none --ood``: the kappa head and its temperature stay as they
    came, the detector is fitted and travels in the file; mode none alone is refused."""
    from conftest import tiny_dataset, untrained_model

    from relight.errors import TrainingError
    from relight.net.calibrate import CalibrationConfig, calibrate_model_file
    from relight.net.io import load_model_file
    data = tiny_dataset(tmp_path / "d", count=70, seed=3, res=32)
    model_path = untrained_model(tmp_path / "m.safetensors", res=32)
    before = load_model_file(model_path)
    out = tmp_path / "ood.safetensors"
    report = calibrate_model_file(model_path, data, out, CalibrationConfig(split="all", mode="none", ood=True))
    after = load_model_file(out)
    assert report["ood"]["n"] == 70 and after.config.ood_dims == report["ood"]["ood_dims"]
    assert float(after.ood_threshold) == pytest.approx(report["ood"]["ood_threshold"], rel=1e-6)
    for k, v in before.state_dict().items():
        assert torch.equal(v, after.state_dict()[k]), k
    with pytest.raises(TrainingError):
        calibrate_model_file(model_path, data, tmp_path / "x.safetensors", CalibrationConfig(split="all", mode="none"))


def test_fine_tuning_drops_a_stale_ood_detector():
    """Training moves the embedding, so a model grown from one with a detector carries none
    (it is fitted again with ``relight calibrate --ood``), and keeps every network weight."""
    from relight.net.ood import fit_ood
    from relight.net.train import with_heads
    fitted, _ = fit_ood(_net(), torch.rand(40, 3, 32, 32), dims=4)
    plain = with_heads(fitted, ood_dims=0)
    assert plain.config.ood_dims == 0 and not any(k.startswith("ood_") for k in plain.state_dict())
    for k, v in plain.state_dict().items():
        assert torch.equal(v, fitted.state_dict()[k]), k


def test_resuming_an_older_run_with_a_camera_head_is_one_error(tmp_path):
    """A run saved before ``camera_weight`` existed had none (0.0): resuming it with a camera
    head is refused with a TrainingError naming the setting, never a KeyError."""
    from relight.errors import TrainingError
    from relight.net.train import TrainConfig, _check_resume_compatible
    cfg = TrainConfig(data_dir=str(tmp_path), camera_weight=1.0)
    saved = {k: v for k, v in cfg.to_dict().items() if k != "camera_weight"}
    with pytest.raises(TrainingError, match="camera_weight was 0.0"):
        _check_resume_compatible(saved, cfg)
    _check_resume_compatible(saved, dataclasses.replace(cfg, camera_weight=0.0))   # the same run: fine


# ----------------------------------------------------------------------------- camera-frame target
ROUND_TRIP_ATOL = 1e-9   # float64 trigonometry of a few operations: far below any error we report


def _lights(n=200, seed=3):
    """Random lights (pan_rel, tilt in [-20, 90]) and cameras (tilt in [-10, 80]), unit colours."""
    rng = np.random.default_rng(seed)
    pan, tilt = rng.uniform(0, 360, n), rng.uniform(-20, 90, n)
    tilt_c = rng.uniform(-10, 80, n)
    rgb = rng.uniform(0.1, 1.0, (n, 3))
    return pan, tilt, tilt_c, rgb / np.linalg.norm(rgb, axis=1, keepdims=True)


def test_camera_frame_target_is_the_light_seen_from_the_camera_and_decodes_back():
    """The camera-frame target decoded with tilt 0 (a level camera) is the light's
    camera-frame direction (world_to_camera with the true tilt); decoded with the true camera
    tilt it is the world light again; the world frame is the paper's y untouched."""
    from relight.net.evaluate import decode_outputs
    pan, tilt, tilt_c, rgb = _lights()
    y = frames.encode_y(pan, tilt, rgb, tilt_c)
    target = frames.y_to_target(y, tilt_c, "camera")
    assert np.array_equal(frames.y_to_target(y, tilt_c, "world"), y)
    p0, t0, rgb0 = frames.decode_y(target, 0.0)
    seen = frames.world_to_camera(frames.direction(p0, t0), 0.0)
    for i in range(len(pan)):
        truth = frames.world_to_camera(frames.direction(pan[i], tilt[i]), tilt_c[i])
        assert np.allclose(seen[i], truth, atol=ROUND_TRIP_ATOL)
    assert np.allclose(rgb0, rgb, atol=ROUND_TRIP_ATOL)
    p, t, c = decode_outputs(target, tilt_c, "camera")
    assert np.allclose(frames.direction(p, t), frames.direction(pan, tilt), atol=ROUND_TRIP_ATOL)
    assert np.allclose(c, rgb, atol=ROUND_TRIP_ATOL)
    assert np.allclose(frames.target_to_y(target, tilt_c, "camera"), y, atol=ROUND_TRIP_ATOL)
    # unnormalised outputs decode alike (the network's sin/cos pairs are raw)
    scaled = target * np.array([2.0, 2.0, 0.3, 0.3, 5.0, 5.0, 5.0])
    p2, t2, _ = decode_outputs(scaled, tilt_c, "camera")
    assert np.allclose(frames.direction(p2, t2), frames.direction(pan, tilt), atol=ROUND_TRIP_ATOL)


def test_camera_frame_angles_are_the_true_angles():
    """The kappa loss and calibration measure angles between targets decoded with
    target_tilt_deg (0 in the camera frame): the same angles as between the world lights."""
    from relight.net.uncertainty import direction_from_y
    pan, tilt, tilt_c, rgb = _lights(100)
    other = frames.encode_y(pan + 25.0, tilt - 15.0, rgb, tilt_c)
    y = frames.encode_y(pan, tilt, rgb, tilt_c)
    true_angle = np.degrees(np.arccos(np.clip(np.sum(
        frames.direction(pan, tilt) * frames.direction(*frames.decode_y(other, tilt_c)[:2]), 1), -1, 1)))
    zero = torch.from_numpy(frames.target_tilt_deg(tilt_c, "camera"))
    a = direction_from_y(torch.from_numpy(frames.y_to_target(y, tilt_c, "camera")), zero)
    b = direction_from_y(torch.from_numpy(frames.y_to_target(other, tilt_c, "camera")), zero)
    angle = np.degrees(np.arccos(np.clip((a * b).sum(1).numpy(), -1, 1)))
    assert np.allclose(angle, true_angle, atol=1e-6)


def test_mirroring_a_camera_frame_target_is_flip_y():
    """The mirror image is lit by the mirrored light (pan_rel -> 360 - pan_rel): its
    camera-frame target is flip_y of the original's, and its camera-frame direction has
    x negated."""
    from relight.net.data import flip_y
    pan, tilt, tilt_c, rgb = _lights()
    target = frames.y_to_target(frames.encode_y(pan, tilt, rgb, tilt_c), tilt_c, "camera")
    mirrored = frames.y_to_target(frames.encode_y(360.0 - pan, tilt, rgb, tilt_c), tilt_c, "camera")
    assert np.allclose(flip_y(target), mirrored, atol=ROUND_TRIP_ATOL)
    v = frames.world_to_camera(frames.direction(*frames.decode_y(target, 0.0)[:2]), 0.0)
    w = frames.world_to_camera(frames.direction(*frames.decode_y(mirrored, 0.0)[:2]), 0.0)
    assert np.allclose(w, v * [-1.0, 1.0, 1.0], atol=ROUND_TRIP_ATOL)


def test_dataset_targets_follow_the_target_frame(tmp_path):
    """LightDataset's targets in the camera frame are y_to_target of the stored labels, with
    target tilts 0; the stored labels and the truth stay the paper's."""
    from conftest import tiny_dataset

    from relight.net.data import LightDataset
    data = tiny_dataset(tmp_path / "d", count=6, seed=4, res=16)
    world = LightDataset(data, "all", 16)
    camera = LightDataset(data, "all", 16, target_frame="camera")
    tilts = world.truth()["camera_tilt_deg"]
    for i in range(len(world)):
        assert np.array_equal(world.target(i), np.asarray(world.records[i]["y"]))
        assert np.array_equal(camera.target(i), frames.y_to_target(world.target(i), tilts[i], "camera"))
    assert np.array_equal(world.target_tilts(range(6)), tilts)
    assert np.array_equal(camera.target_tilts(range(6)), np.zeros(6))
    with pytest.raises(ValueError):
        LightDataset(data, "all", 16, target_frame="sky")


def test_a_camera_frame_model_is_decoded_as_one(tmp_path):
    """A model saved with target_frame camera keeps it through its file; predict reads its
    outputs as the light in the camera frame, so the answer there does not depend on the
    camera tilt, and the written y is the paper's 7-vector of the decoded light."""
    from relight.net.io import load_model_file, save_model
    from relight.net.predict import _predict_inputs, load_model
    path = tmp_path / "camera.safetensors"
    save_model(path, _net(camera_head=True, target_frame="camera"), {})
    assert load_model_file(path).config.target_frame == "camera"
    net = load_model(path)
    x = [torch.rand(3, 32, 32, generator=torch.Generator().manual_seed(k)) for k in range(3)]
    with torch.no_grad():
        raw = net(torch.stack(x)).double().numpy()
    seen = frames.world_to_camera(frames.direction(*frames.decode_y(raw, 0.0)[:2]), 0.0)
    for tilt_c in (0.0, 30.0, 60.0):
        preds = _predict_inputs(net, x, [tilt_c] * 3)
        for p, v in zip(preds, seen):
            assert np.allclose(p["to_light_camera"], v, atol=ROUND_TRIP_ATOL)
            assert np.allclose(frames.direction(*frames.decode_y(p["y"], tilt_c)[:2]),
                               frames.direction(p["pan_deg"], p["tilt_deg"]), atol=ROUND_TRIP_ATOL)
    own = _predict_inputs(net, x, None)   # the camera head's tilt turns the same answer into the world
    assert all(np.allclose(p["to_light_camera"], v, atol=ROUND_TRIP_ATOL) for p, v in zip(own, seen))


def test_model_files_without_a_target_frame_decode_as_world(tmp_path):
    """A model file written before target_frame existed (its config has no such key) is a
    world-frame model: predict decodes its outputs as the paper's y."""
    import json

    from safetensors.torch import save_file

    from relight.net.io import MODEL_FORMAT, load_model_file
    from relight.net.predict import _predict_inputs
    net = _net()
    config = net.config.to_dict()
    del config["target_frame"]
    path = str(tmp_path / "old.safetensors")
    save_file({k: v.contiguous() for k, v in net.state_dict().items()}, path,
              metadata={"format": MODEL_FORMAT, "arch": net.config.arch_name, "config": json.dumps(config),
                        "info": "{}"})
    old = load_model_file(path)
    assert old.config.target_frame == "world" and NetConfig.from_dict(config).target_frame == "world"
    x = [torch.rand(3, 32, 32, generator=torch.Generator().manual_seed(1))]
    with torch.no_grad():
        raw = old(torch.stack(x)).double().numpy()[0]
    p = _predict_inputs(old, x, [40.0])[0]
    pan, tilt, _ = frames.decode_y(raw, 40.0)
    assert p["pan_deg"] == pytest.approx(float(pan), abs=1e-9) and p["tilt_deg"] == pytest.approx(float(tilt), abs=1e-9)
    assert np.allclose(p["y"], raw, atol=0)
    with pytest.raises(ValueError):
        NetConfig(target_frame="sky")


def test_resuming_with_another_target_frame_is_one_error(tmp_path):
    """A run saved before target_frame existed was a world run: resuming it in the camera
    frame is refused with a TrainingError naming the setting."""
    from relight.errors import TrainingError
    from relight.net.train import TrainConfig, _check_resume_compatible, net_config
    cfg = TrainConfig(data_dir=str(tmp_path), target_frame="camera")
    saved = {k: v for k, v in cfg.to_dict().items() if k != "target_frame"}
    with pytest.raises(TrainingError, match="target_frame was 'world'"):
        _check_resume_compatible(saved, cfg)
    assert net_config(cfg).target_frame == "camera" and net_config(cfg, saved).target_frame == "world"
    with pytest.raises(TrainingError):
        TrainConfig(data_dir=str(tmp_path), target_frame="sky")


def test_shared_data_dir_explicit_then_environment_then_next_to_the_checkout(monkeypatch, tmp_path):
    from relight.net.photos import SHARED_DATA_ENV, shared_data_dir
    monkeypatch.delenv(SHARED_DATA_ENV, raising=False)
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    assert shared_data_dir() == os.path.normpath(os.path.join(repo, "..", "shared", "data"))
    monkeypatch.setenv(SHARED_DATA_ENV, str(tmp_path))
    assert shared_data_dir() == str(tmp_path)
    assert shared_data_dir("/elsewhere") == "/elsewhere"


def test_follows_light_tells_a_reading_from_a_well_placed_constant():
    from relight.net.photos import follows_light
    rng = np.random.default_rng(3)
    truth = rng.normal(size=(40, 3)) * [0.3, 0.3, 0.1] + [0, 0, 1]
    truth /= np.linalg.norm(truth, axis=1, keepdims=True)
    noisy = truth + rng.normal(scale=0.03, size=truth.shape)
    rx, ry = follows_light(noisy, truth)
    assert rx > 0.9 and ry > 0.9                               # tracks the light
    constant = np.tile(truth.mean(0), (40, 1))                 # the set's mean light: low error, no reading
    assert all(np.isnan(follows_light(constant, truth)))
    shuffled = truth[rng.permutation(40)]                      # right spread, wrong images
    assert all(abs(r) < 0.5 for r in follows_light(shuffled, truth))
    mirrored = truth * [-1, 1, 1]                              # left and right swapped
    rx, ry = follows_light(mirrored, truth)
    assert rx < -0.9 and ry > 0.9


def test_shading_split_separates_the_bas_relief_slant_from_the_image_direction():
    from relight import metrics
    from relight.net.photos import shading_split, summary
    rng = np.random.default_rng(5)
    truth = rng.normal(size=(30, 3)) * [0.4, 0.4, 0.2] + [0, 0, 1]
    truth /= np.linalg.norm(truth, axis=1, keepdims=True)
    slant = np.degrees(np.arccos(truth[:, 2]))
    # the bas-relief light (x, y, z / lambda) of a deepened object: same in-image direction, larger slant
    relief = truth * [1, 1, 0.3]
    relief /= np.linalg.norm(relief, axis=1, keepdims=True)
    split = shading_split(relief, truth)
    np.testing.assert_allclose(split["image_angle_deg"], 0, atol=1e-9)
    expected = np.degrees(np.arctan2(np.hypot(truth[:, 0], truth[:, 1]), 0.3 * truth[:, 2])) - slant
    np.testing.assert_allclose(split["slant_error_deg"], expected, atol=1e-9)
    assert np.all(split["slant_error_deg"] > 0)
    # a turn about the view axis by 25 degrees: in-image error 25, slant unchanged, total error below 25
    c, s = np.cos(np.radians(25)), np.sin(np.radians(25))
    turned = truth @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])
    split = shading_split(turned, truth)
    np.testing.assert_allclose(split["image_angle_deg"], 25, atol=1e-9)
    np.testing.assert_allclose(split["slant_error_deg"], 0, atol=1e-9)
    assert np.all(metrics.angle_deg(turned, truth) < 25)
    # across -180/180, and a light on the view axis has no in-image direction
    a = np.array([[np.cos(np.radians(175)), np.sin(np.radians(175)), 1.0], [0, 0, 1.0]])
    b = np.array([[np.cos(np.radians(-175)), np.sin(np.radians(-175)), 1.0], [1.0, 0, 1.0]])
    split = shading_split(a, b)
    assert split["image_angle_deg"][0] == pytest.approx(10)
    assert np.isnan(split["image_angle_deg"][1])
    out = summary({"direction_deg": metrics.angle_deg(relief, truth), "covered": np.ones(30, bool),
                   "ood": np.zeros(30, bool), "to_light_camera": relief, "true_to_light_camera": truth})
    assert out["image_angle_deg_median"] == pytest.approx(0, abs=1e-9)
    assert out["slant_bias_deg"] == pytest.approx(np.median(expected))


def test_shrinkage_reads_the_slope_and_the_shift_of_answers_pulled_to_an_average():
    from relight import metrics
    from relight.net.photos import shrinkage, summary
    rng = np.random.default_rng(9)
    truth = rng.normal(size=(36, 3)) * [0.25, 0.2, 0.1] + [0, 0.3, 1]
    truth /= np.linalg.norm(truth, axis=1, keepdims=True)
    groups = np.repeat(["owl", "cat", "rock"], 12)
    offset = {"owl": 0.05, "cat": -0.1, "rock": 0.0}          # each object's own shift: not a slope
    # answers pulled toward each object's mean by 0.4 in x and 0.1 in y, then shifted
    pred = np.zeros_like(truth)
    for g in offset:
        k = groups == g
        m = truth[k].mean(0)
        pred[k, 0] = m[0] + 0.4 * (truth[k, 0] - m[0]) + offset[g] - 0.2
        pred[k, 1] = m[1] + 0.1 * (truth[k, 1] - m[1]) + 0.15
    pred[:, 2] = np.sqrt(1 - (pred[:, :2] ** 2).sum(1))
    out = shrinkage(pred, truth, groups)
    assert out["slope_x"] == pytest.approx(0.4) and out["slope_y"] == pytest.approx(0.1)
    assert out["bias_x"] == pytest.approx(np.mean(pred[:, 0] - truth[:, 0]))
    assert out["bias_y"] == pytest.approx(0.15)
    # answers that are the truth shifted by a constant in x and y: slopes 1, nothing left once unshifted
    shifted = truth.copy()
    shifted[:, :2] += [0.1, -0.12]
    shifted[:, 2] = np.sqrt(1 - (shifted[:, :2] ** 2).sum(1))
    out = shrinkage(shifted, truth, groups)
    assert out["slope_x"] == pytest.approx(1) and out["slope_y"] == pytest.approx(1)
    assert out["bias_free_median_deg"] == pytest.approx(0, abs=1e-6)
    assert np.median(metrics.angle_deg(shifted, truth)) > 5                     # the shift itself costs
    # a constant answer does not move with the light at all
    assert shrinkage(np.tile(truth.mean(0), (36, 1)), truth, groups)["slope_x"] == pytest.approx(0, abs=1e-12)
    s = summary({"direction_deg": metrics.angle_deg(pred, truth), "covered": np.ones(36, bool),
                 "ood": np.zeros(36, bool), "to_light_camera": pred, "true_to_light_camera": truth,
                 "group": list(groups)})
    assert s["slope_x"] == pytest.approx(0.4)
    assert all(np.isnan(v) for v in shrinkage(np.zeros((0, 3)), np.zeros((0, 3))).values())


# --- benchmarks/proxy_mode_head.py: the mode-seeking read-out study (docs/photo.md, ninth round)

def test_mode_head_bins_and_camera_vectors():
    """The bins cover the sphere evenly, and the study's camera-frame truth is the frames
    module's: a camera-frame target decodes to ``world_to_camera`` of the light."""
    from conftest import load_script
    bench = load_script("benchmarks/proxy_mode_head.py")
    bins = bench.fibonacci_sphere(1024)
    np.testing.assert_allclose(np.linalg.norm(bins, axis=1), 1.0, atol=1e-12)
    assert np.linalg.norm(bins.mean(axis=0)) < 1e-2
    nearest = np.degrees(np.arccos(np.clip(np.sort(bins @ bins.T, axis=1)[:, -2], -1.0, 1.0)))
    spacing = np.degrees(np.sqrt(4.0 * np.pi / len(bins)))   # 6.3 degrees
    assert 0.6 * spacing < nearest.min() and nearest.max() < 1.4 * spacing
    rng = np.random.default_rng(3)
    for _ in range(20):
        pan, tilt, tilt_c = rng.uniform(0, 360), rng.uniform(-80, 85), rng.uniform(0, 70)
        y = frames.encode_y(pan, tilt, [0.6, 0.6, 0.5], tilt_c_deg=tilt_c)
        got = bench.camera_vectors(frames.y_to_target(y, tilt_c, "camera")[None])[0]
        want = frames.world_to_camera(frames.direction(pan, tilt), tilt_c)
        np.testing.assert_allclose(got, want, atol=1e-9)


def test_mode_head_reads_the_mode_not_the_mean():
    """Two lobes of probability 0.6 and 0.4, 90 degrees apart: the mode read-out lands on
    the larger lobe (within a bin), the mean read-out between the two (its closed form here:
    the normalised 0.6 d1 + 0.4 d2, 33.7 degrees from d1)."""
    from conftest import load_script
    bench = load_script("benchmarks/proxy_mode_head.py")
    bins = bench.fibonacci_sphere(1024)
    d1, d2 = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    lobe = lambda d: np.exp(400.0 * (bins @ d - 1.0)) / np.exp(400.0 * (bins @ d - 1.0)).sum()
    p = 0.6 * lobe(d1) + 0.4 * lobe(d2)
    logits = torch.from_numpy(np.log(p)[None].astype(np.float32))
    out = bench.read_bins(lambda e: logits, np.zeros((1, 4), np.float32), bins, mode_radius_deg=15.0)
    angle = lambda a, b: float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))
    assert angle(out["bins-mode"][0], d1) < 3.0
    assert abs(angle(out["bins-mean"][0], d1) - np.degrees(np.arctan2(0.4, 0.6))) < 3.0
    assert abs(out["peak_prob"][0] - 0.6) < 0.02


def _lambert_ball(to_light, gamma, size=96, a=0.8, b=0.03):
    """A diffuse ball filling most of a square image, seen orthographically, its codes
    ``a * max(0, n . l) ** (1 / gamma) + b`` (the closed form response_gamma fits)."""
    yy, xx = np.mgrid[0:size, 0:size]
    r = 0.4 * size
    nx, ny = (xx + 0.5 - size / 2) / r, -(yy + 0.5 - size / 2) / r
    inside = nx ** 2 + ny ** 2 < 1.0
    nz = np.sqrt(np.clip(1.0 - nx ** 2 - ny ** 2, 0.0, 1.0))
    shade = np.clip(np.stack([nx, ny, nz], -1) @ np.asarray(to_light, float), 0.0, None)
    return np.where(inside, a * shade ** (1.0 / gamma) + b, 0.0), inside


@pytest.mark.parametrize("gamma", [1.0, 2.2])
def test_response_gamma_reads_the_curve_off_a_diffuse_ball(gamma):
    """A linear camera (gamma 1) and a display encoding (2.2) are told apart, from the
    closed-form shading of a Lambertian ball under a known light, 8-bit quantised."""
    from relight.net.photos import response_gamma
    light = np.array([0.3, 0.4, np.sqrt(1 - 0.25)])
    codes, mask = _lambert_ball(light, gamma)
    fit = response_gamma(np.round(codes * 255) / 255, mask, light)
    assert abs(fit["gamma"] - gamma) < 0.05 * gamma and abs(fit["a"] - 0.8) < 0.05 and fit["rms"] < 0.01


def test_replace_surround_keeps_the_object_and_changes_only_what_it_names():
    """Every variant keeps the object's pixels exactly; uniform keeps the surroundings' mean
    and nothing else; rows keep each row's mean (a vertical ramp stays a ramp, a horizontal
    one goes flat); the upside-down variants reverse the vertical profile; bad input is a
    ValueError."""
    from relight.net.photos import SURROUNDS, replace_surround
    h, w = 20, 30
    yy, xx = np.mgrid[:h, :w]
    mask = (yy - 10) ** 2 + (xx - 15) ** 2 < 5 ** 2
    ramp = (0.01 + 0.002 * (h - 1 - yy))[..., None] * np.array([1.0, 0.8, 0.6])   # brighter above
    image = np.where(mask[..., None], 0.5 + 0.01 * xx[..., None], ramp + 0.001 * xx[..., None])
    out = ~mask
    for how in SURROUNDS:
        v = replace_surround(image, mask, how)
        assert v.shape == image.shape and np.array_equal(v[mask], image[mask]), how
    assert not replace_surround(image, mask, "black")[out].any()
    uni = replace_surround(image, mask, "uniform")[out]
    np.testing.assert_allclose(uni, np.broadcast_to(image[out].mean(axis=0), uni.shape), atol=1e-12)
    rows = replace_surround(image, mask, "rows")
    np.testing.assert_allclose(rows[:, 0], rows[:, -1], atol=1e-12)   # flat across a row
    np.testing.assert_allclose(rows[0, 0], image[0][out[0]].mean(axis=0), atol=1e-12)
    assert rows[0, 0, 0] > rows[-1, 0, 0]   # the profile kept: brighter above
    flipped = replace_surround(image, mask, "rows-upside-down")
    np.testing.assert_allclose(flipped[0, 0], rows[-1, 0], atol=1e-12)
    ud = replace_surround(image, mask, "upside-down")
    np.testing.assert_allclose(ud[0, 0], image[-1, 0], atol=1e-12)   # the bottom row's pixel on top
    assert ud[0, 0, 0] < ud[-1, 0, 0]
    with pytest.raises(ValueError, match="surround"):
        replace_surround(image, mask, "sideways")
    with pytest.raises(ValueError, match="expected"):
        replace_surround(image, mask[:-1], "black")


def test_linear_tone_curve_only_in_photo_linear():
    """``photo`` (the shipped recipe) never draws the linear curve; ``photo-linear`` does, and
    with every other effect off its codes are proportional to the light; ``photo-srgb`` draws
    the sRGB transfer and nothing else."""
    from relight.net.augment import AUGMENTS, DISPLAY_CURVES
    assert AUGMENTS["photo"]().tone_curves == DISPLAY_CURVES and "linear" not in DISPLAY_CURVES
    x = _linear(4)
    only_linear = PipelineAugment(exposure_ev=(0.0, 0.0), photon_a=(1e-18, 1e-18), read_sigma=(0.0, 0.0),
                                  vignette=(0.0, 0.0), blur_px=(0.0, 0.0), tone_curves=("linear",), jpeg_p=0.0)
    out = only_linear.apply(x, np.random.default_rng(0)).astype(int)
    assert np.abs(out - np.round(255 * x)).max() <= 1
    off = dict(photon_a=(1e-18, 1e-18), read_sigma=(0.0, 0.0), vignette=(0.0, 0.0), blur_px=(0.0, 0.0),
               jpeg_p=0.0, exposure_ev=(0.0, 0.0))
    grey = np.full((4, 4, 3), 0.2)
    linear_code = round(255 * 0.2)
    draws = {name: [int(PipelineAugment(tone_curves=AUGMENTS[name]().tone_curves, **off)
                        .apply(grey, np.random.default_rng(s))[0, 0, 0]) for s in range(60)]
             for name in ("photo", "photo-linear", "photo-srgb")}
    assert linear_code not in draws["photo"]
    assert 5 <= draws["photo-linear"].count(linear_code) <= 30   # about a quarter of 60
    srgb_code = round(255 * float(colour.srgb_encode(np.array(0.2))))   # 124, the closed form
    assert set(draws["photo-srgb"]) == {srgb_code} and 10 <= draws["photo"].count(srgb_code) <= 35


def test_response_gamma_refuses_what_it_cannot_fit():
    from relight.net.photos import response_gamma
    light = np.array([0.0, 0.0, 1.0])
    codes, mask = _lambert_ball(light, 1.0)
    with pytest.raises(ValueError, match="does not match"):
        response_gamma(codes, mask[:-1], light)
    with pytest.raises(ValueError, match="needs"):
        response_gamma(codes, np.zeros_like(mask), light)
    with pytest.raises(ValueError, match="lit, unclipped"):   # lit from behind: nothing to fit
        response_gamma(codes, mask, -light)


def test_glare_lifts_dark_surroundings_in_the_scene_colour():
    """Veiling glare (``photo-glare``), every other effect off: what it adds is a smooth field
    in [0, 1] times the image's mean colour times g (<= the range's top), so a dark
    surround is lifted by up to that much and a lit patch barely changes; ``photo`` never adds it."""
    from relight.net.augment import AUGMENTS, glare_field
    rng = np.random.default_rng(0)
    for _ in range(5):
        f = glare_field((32, 48), rng)
        assert f.shape == (32, 48) and f.min() >= 0.0 and f.max() <= 1.0
        assert np.abs(np.diff(f, axis=1)).max() < 0.2 and np.abs(np.diff(f, axis=0)).max() < 0.2   # smooth
    off = dict(exposure_ev=(0.0, 0.0), photon_a=(1e-18, 1e-18), read_sigma=(0.0, 0.0), vignette=(0.0, 0.0),
               blur_px=(0.0, 0.0), tone_curves=("linear",), jpeg_p=0.0)
    scene = np.zeros((32, 32, 3))
    scene[8:24, 8:24] = [0.6, 0.4, 0.2]   # a lit warm patch on black
    top = AUGMENTS["photo-glare"]().glare[1]
    lifted = 0
    for seed in range(20):
        out = PipelineAugment(glare_p=1.0, **off).apply(scene, np.random.default_rng(seed)) / 255.0
        added = out[0:6, 0:6]   # the black surround: glare alone
        assert np.all(added <= top * scene.mean(axis=(0, 1)) + 1 / 255)
        patch = out[10:22, 10:22]
        assert np.abs(patch - scene[10:22, 10:22]).max() <= top * scene.mean(axis=(0, 1)).max() + 1 / 255
        lifted += added.max() > 2 / 255
        if added.max() > 10 / 255:   # the scene's colour: red over green over blue, as the mean is
            mean = added.reshape(-1, 3).mean(axis=0)
            assert mean[0] > mean[1] > mean[2]
    assert lifted >= 5
    plain = PipelineAugment(**off)
    assert AUGMENTS["photo"]().glare_p == 0.0
    assert np.array_equal(plain.apply(scene, np.random.default_rng(1)), np.round(scene * 255).astype(np.uint8))

"""Object masks (generator config ``object_masks``) and training on the objects alone
(``relight train --surround black``): the mask against the closed form of a sphere's
silhouette, the generator's files and records, and the dataset's blacked-out images."""
from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from relight import frames
from relight.generator.sampling import GeneratorConfig

from conftest import needs_blender, sphere_scene

CFG = GeneratorConfig(res=24, spp=2, void_fraction=0.5, fov_range_deg=(30.0, 60.0),
                      view_halfwidth_m=(2.5, 4.0), split=(0.5, 0.5, 0.0))


def _sphere_coverage(spec, centre, radius, res: int, n: int) -> np.ndarray:
    """Closed form: the share of each pixel's ``n`` x ``n`` grid of pinhole rays that pass
    within ``radius`` of ``centre`` (the silhouette of a sphere, in perspective)."""
    cam = spec.camera
    f = 0.5 * res / math.tan(math.radians(cam.fov_deg) / 2.0)
    s = (np.arange(res * n) + 0.5) / n                       # sample positions in pixels
    x, y = np.meshgrid(s, s)                                 # rows: y down the image
    d_cam = np.stack([x - res / 2.0, -(y - res / 2.0), -np.full_like(x, f)], axis=-1)
    d_cam /= np.linalg.norm(d_cam, axis=-1, keepdims=True)
    d = frames.camera_to_world_vector(d_cam.reshape(-1, 3), cam.tilt_deg, cam.pan_deg)
    to_c = np.asarray(centre) - cam.position_m
    along = d @ to_c
    miss2 = np.sum(to_c ** 2) - along ** 2                   # squared distance of the ray from the centre
    hit = (miss2 < radius ** 2) & (along > 0)
    return hit.reshape(res, n, res, n).mean(axis=(1, 3))


def test_object_mask_is_the_sphere_silhouette(mi):
    from relight.scene import build
    spec = sphere_scene(res=32, camera_tilt_deg=20.0)
    template = build.build_naive(spec)
    mask = template.object_mask()
    v, _ = build._object_vertices(spec.objects[0], build.object_mesh(spec.objects[0]))
    v = v.astype(np.float64)
    centre = (v.max(axis=0) + v.min(axis=0)) / 2.0
    radius = float(np.median(np.linalg.norm(v - centre, axis=1)))    # vertices lie on the sphere
    truth = _sphere_coverage(spec, centre, radius, 32, build.MASK_SUBSAMPLES)
    assert mask.shape == (32, 32) and mask.dtype == np.float32
    assert truth.sum() > 30                                          # the sphere is well in view
    # the mesh is a tessellated sphere: its silhouette lies within a few % of the radius of the
    # true one, so only boundary pixels may differ, by a few of their 16 rays
    inner = _sphere_coverage(spec, centre, 0.97 * radius, 32, build.MASK_SUBSAMPLES)
    outer = _sphere_coverage(spec, centre, 1.01 * radius, 32, build.MASK_SUBSAMPLES)
    assert np.all(mask >= inner - 1e-6) and np.all(mask <= outer + 1e-6)
    assert abs(mask.sum() - truth.sum()) < 0.04 * truth.sum()
    assert np.any((mask > 0) & (mask < 1))                          # the edge is fractional


def test_object_mask_follows_the_camera(mi):
    """Turning the camera away from the sphere empties the mask (no wall, floor or
    parked slot counts as an object)."""
    from relight.scene import build
    spec = sphere_scene(res=16)
    away = dataclasses.replace(spec, camera=dataclasses.replace(spec.camera, pan_deg=0.0, tilt_deg=-30.0))
    assert build.build_naive(spec).object_mask().sum() > 5
    assert build.build_naive(away).object_mask().sum() == 0


def test_generator_writes_masks_without_changing_the_images(tmp_path, mi):
    from relight.dataset import read_manifest
    from relight.generator.run import generate
    from relight.imageio import read_mask
    plain, masked = tmp_path / "plain", tmp_path / "masked"
    generate(plain, 4, seed=3, cfg=CFG, progress=False)
    generate(masked, 4, seed=3, cfg=dataclasses.replace(CFG, object_masks=True), progress=False)
    assert not (plain / "masks").exists()
    assert all("mask" not in r for r in read_manifest(plain))
    for rec in read_manifest(masked):
        assert rec["mask"] == f"masks/{rec['id']}.png"
        for sub in ("exr", "image"):                                 # the images are untouched
            assert (plain / rec[sub]).read_bytes() == (masked / rec[sub]).read_bytes()
        coverage = read_mask(masked / rec["mask"])
        assert coverage.shape == (24, 24) and 0 < coverage.sum() < 24 * 24
    # the mask is the scene file's own: the same from the template re-built from it
    from relight.scene import build
    from relight.scene.spec import load_scene
    rec = read_manifest(masked)[0]
    again = build.build_naive(load_scene(masked / rec["scene"])).object_mask()
    np.testing.assert_allclose(read_mask(masked / rec["mask"]), again, atol=0.5 / 255 + 1e-6)
    # a card without the setting (made before it) resumes with masks off; with them on it is refused
    card = json.loads((plain / "dataset.json").read_text())
    del card["config"]["object_masks"]
    (plain / "dataset.json").write_text(json.dumps(card))
    assert generate(plain, 5, seed=3, cfg=CFG, progress=False).written == 1
    from relight.dataset import DatasetError
    with pytest.raises(DatasetError, match="object_masks False there, True here"):
        generate(plain, 6, seed=3, cfg=dataclasses.replace(CFG, object_masks=True), progress=False)


def test_object_masks_setting_is_checked():
    from relight.errors import ConfigError
    with pytest.raises(ConfigError, match="object_masks: expected true or false"):
        dataclasses.replace(CFG, object_masks=1)


def test_mask_png_round_trip(tmp_path):
    from relight.imageio import read_mask, write_mask
    coverage = np.linspace(0.0, 1.0, 48, dtype=np.float32).reshape(6, 8)
    write_mask(tmp_path / "m.png", coverage)
    np.testing.assert_allclose(read_mask(tmp_path / "m.png"), coverage, atol=0.5 / 255 + 1e-6)
    with pytest.raises(ValueError):
        write_mask(tmp_path / "bad.png", np.zeros((4, 4, 3)))


def test_surround_black_is_the_image_times_its_mask(tmp_path, mi):
    from relight.dataset import DatasetError
    from relight.generator.run import generate
    from relight.net.data import LightDataset, linear_at_res, mask_at_res
    out = tmp_path / "d"
    generate(out, 3, seed=5, cfg=dataclasses.replace(CFG, object_masks=True), progress=False)
    keep = LightDataset(out, "all", res=16, source="exr")
    black = LightDataset(out, "all", res=16, source="exr", surround="black")
    for i, rec in enumerate(black.records):
        m = mask_at_res(str(out / rec["mask"]), 16)
        full = linear_at_res(str(out / rec["exr"]), 16)
        got = black.linear_image(i)
        assert np.all(got[m == 0] == 0)                                  # outside the objects: black
        inside = m == 1
        assert inside.any()
        np.testing.assert_allclose(got[inside], keep.linear_image(i)[inside], rtol=1e-3)   # float16 cache
        np.testing.assert_allclose(got, full * m[..., None], rtol=1e-3, atol=1e-6)
    with pytest.raises(ValueError, match="surround"):
        LightDataset(out, "all", res=16, source="image", surround="black")
    plain = tmp_path / "plain"
    generate(plain, 1, seed=5, cfg=CFG, progress=False)
    with pytest.raises(DatasetError, match="no object mask"):
        LightDataset(plain, "all", res=16, source="exr", surround="black").linear_image(0)


def test_train_surround_needs_the_exrs(tmp_path, capsys):
    from relight.cli import main
    try:
        code = main(["train", "--data", str(tmp_path), "--out", str(tmp_path / "run"), "--surround", "black"])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and "--surround black works on the linear EXRs" in err and "\n" not in err


def _alone_model(path, surround: str = "black") -> str:
    """An untrained narrow camera-frame network of the objects alone, saved at ``path``."""
    import torch

    from relight.net.io import save_model
    from relight.net.model import LightNet, NetConfig
    torch.manual_seed(0)
    save_model(str(path), LightNet(NetConfig(res=32, width=8, target_frame="camera", surround=surround)), {})
    return str(path)


def test_surround_is_stored_with_the_model_and_older_files_keep_theirs(tmp_path):
    from relight.net.io import load_model_file
    from relight.net.model import NetConfig
    assert load_model_file(_alone_model(tmp_path / "a.safetensors")).config.surround == "black"
    config = NetConfig(res=32, width=8).to_dict()
    del config["surround"]                                           # a file written before it
    assert NetConfig.from_dict(config).surround == "keep"
    with pytest.raises(ValueError, match="surround"):
        NetConfig(surround="grey")


def test_objects_alone_closed_form():
    from relight.colour import srgb_encode
    from relight.errors import ImageError
    from relight.net.predict import objects_alone
    img = np.full((2, 3, 3), 255, np.uint8)
    mask = np.array([[1.0, 0.5, 0.0], [1.0, 1.0, 0.0]])
    out = objects_alone(img, mask)
    half = int(np.round(srgb_encode(np.array(0.5)) * 255.0))        # linear 0.5 in 8-bit sRGB
    assert half in (187, 188)
    assert out[0, 0, 0] == 255 and out[0, 1, 0] == half and out[0, 2, 0] == 0 and out[1, 2, 0] == 0
    with pytest.raises(ImageError, match="mask of 2x2 pixels for an image of 3x2"):
        objects_alone(img, np.ones((2, 2)))


def test_predict_with_a_mask_reads_the_objects_alone(tmp_path, capsys):
    """``relight predict --mask``: the answer of the same photograph saved with its
    surroundings black; a model of the objects alone refuses an image without a mask."""
    from PIL import Image

    from relight.cli import main
    from relight.errors import ImageError
    from relight.net.predict import load_model, predict_files
    rng = np.random.default_rng(4)
    yy, xx = np.mgrid[:40, :56]
    mask = (yy - 20) ** 2 + (xx - 26) ** 2 < 12 ** 2
    shade = (120 + 100 * xx / 56.0)[..., None] * np.ones(3)
    photo = np.where(mask[..., None], shade, rng.integers(30, 200, size=(40, 56, 3))).astype(np.uint8)
    Image.fromarray(photo).save(tmp_path / "p.png")
    Image.fromarray(np.where(mask[..., None], photo, 0).astype(np.uint8)).save(tmp_path / "black.png")
    Image.fromarray((mask * 255).astype(np.uint8)).save(tmp_path / "p.mask.png")
    alone = load_model(_alone_model(tmp_path / "alone.safetensors"))
    masked = predict_files(alone, [str(tmp_path / "p.png")], 20.0, masks=[str(tmp_path / "p.mask.png")])[0]
    ref = predict_files(load_model(_alone_model(tmp_path / "keep.safetensors", "keep")),
                        [str(tmp_path / "black.png")], 20.0)[0]
    np.testing.assert_allclose(masked["to_light_camera"], ref["to_light_camera"], atol=1e-6)
    with pytest.raises(ImageError, match="reads the objects alone"):
        predict_files(alone, [str(tmp_path / "p.png")], 20.0)

    def run(*argv):
        try:
            code = main(list(argv))
        except SystemExit as exc:
            code = exc.code
        return code, capsys.readouterr()
    model = str(tmp_path / "alone.safetensors")
    out = str(tmp_path / "pred.json")
    code, io = run("predict", str(tmp_path / "p.png"), "--model", model, "--camera-tilt", "20", "--out", out)
    assert code == 2 and "reads the objects alone" in io.err and not (tmp_path / "pred.json").exists()
    code, io = run("predict", str(tmp_path / "p.png"), str(tmp_path / "black.png"), "--mask",
                   str(tmp_path / "p.mask.png"), "--model", model, "--out", out)
    assert code == 2 and "1 masks for 2 images" in io.err
    code, io = run("predict", str(tmp_path / "p.png"), "--mask", str(tmp_path / "p.mask.png"), "--model", model,
                   "--camera-tilt", "20", "--out", out)
    assert code == 0
    entry = json.loads((tmp_path / "pred.json").read_text())["predictions"][0]
    assert entry["mask"] == str(tmp_path / "p.mask.png")
    np.testing.assert_allclose(entry["to_light_camera"], masked["to_light_camera"], atol=1e-9)
    code, io = run("predict", str(tmp_path / "p.png"), "--mask", str(tmp_path / "p.png"), "--model", model,
                   "--out", str(tmp_path / "p.png"))
    assert code == 2 and (tmp_path / "p.png").read_bytes() != b""   # an output equal to an input: refused


def test_training_on_the_objects_alone_records_it_in_the_model(tmp_path, mi):
    from relight.generator.run import generate
    from relight.net.io import load_model_file
    from relight.net.train import TrainConfig, train
    data = tmp_path / "d"
    generate(data, 4, seed=6, cfg=dataclasses.replace(CFG, res=32, object_masks=True), progress=False)
    init = _alone_model(tmp_path / "init.safetensors", "keep")
    cfg = TrainConfig(data_dir=str(data), epochs=1, batch_size=2, res=32, width=8, init=init, source="exr",
                      target_frame="camera", surround="black", train_split="all", val_split="all")
    train(cfg, str(tmp_path / "run"), progress=False)
    assert load_model_file(str(tmp_path / "run" / "best.safetensors")).config.surround == "black"


def test_bench_photos_scores_a_model_of_the_objects_alone_only_where_masks_are(tmp_path, mi, capsys):
    import importlib.util
    import os

    from relight.generator.run import generate
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    spec = importlib.util.spec_from_file_location("bench_photos", os.path.join(repo, "benchmarks", "bench_photos.py"))
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    plain, masked = tmp_path / "plain", tmp_path / "masked"
    generate(plain, 2, seed=7, cfg=dataclasses.replace(CFG, res=32), progress=False)
    generate(masked, 2, seed=7, cfg=dataclasses.replace(CFG, res=32, object_masks=True), progress=False)
    model = _alone_model(tmp_path / "alone.safetensors")
    assert bench.main(["--no-devset", "--photos", str(tmp_path / "none"), "--model", model,
                       "--data", str(plain), "--data", str(masked)]) == 0
    out = capsys.readouterr().out
    after_plain = out[out.index(str(plain)):out.index(str(masked))]
    assert "skipped: it reads the objects alone" in after_plain
    after_masked = out[out.index(str(masked)):].splitlines()
    assert any(ln.startswith("  alone.safetensors") and "skipped" not in ln for ln in after_masked)


def test_predict_linear_reads_8bit_codes_as_linear_values(tmp_path, capsys):
    """``--linear``: a PNG's codes are the light's values (a camera proportional to the light);
    the answer is the one for the same values given as a linear array."""
    from PIL import Image

    from relight.cli import main
    from relight.imageio import read_srgb8, to_srgb8
    from relight.net.predict import load_model, predict_arrays, predict_files
    rng = np.random.default_rng(8)
    codes = rng.integers(0, 256, size=(24, 30, 3)).astype(np.uint8)
    Image.fromarray(codes).save(tmp_path / "lin.png")
    srgb8, note = read_srgb8(tmp_path / "lin.png", linear=True)
    assert np.array_equal(srgb8, to_srgb8(codes / 255.0)) and "read as linear" in note
    assert np.array_equal(read_srgb8(tmp_path / "lin.png")[0], codes)          # default: sRGB, as stored
    model = load_model(_alone_model(tmp_path / "keep.safetensors", "keep"))
    got = predict_files(model, [str(tmp_path / "lin.png")], 20.0, linear=True)[0]
    ref = predict_arrays(model, [codes / 255.0], [20.0])[0]
    np.testing.assert_allclose(got["to_light_camera"], ref["to_light_camera"], atol=1e-9)
    plain = predict_files(model, [str(tmp_path / "lin.png")], 20.0)[0]
    assert not np.allclose(plain["to_light_camera"], ref["to_light_camera"], atol=1e-4)   # the reading matters
    out = tmp_path / "p.json"
    assert main(["predict", str(tmp_path / "lin.png"), "--linear", "--model", str(tmp_path / "keep.safetensors"),
                 "--camera-tilt", "20", "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["pixel_codes"] == "linear"
    np.testing.assert_allclose(doc["predictions"][0]["to_light_camera"], ref["to_light_camera"], atol=1e-9)


def test_photo_set_read_as_linear(tmp_path):
    """``score_photo_set(linear=True)``: the photos' codes as linear values, with or without
    a surround change, the same answer as the arrays given directly."""
    from PIL import Image

    from relight.net.photos import score_photo_set
    from relight.net.predict import load_model, predict_arrays
    yy, xx = np.mgrid[:32, :40]
    mask = (yy - 16) ** 2 + (xx - 20) ** 2 < 10 ** 2
    (tmp_path / "lights.txt").write_text("1\n0 0 1\n")
    photo = np.where(mask[..., None], (60 + 150 * xx / 40.0)[..., None] * np.ones(3), 25).astype(np.uint8)
    Image.fromarray(photo).save(tmp_path / "ball.0.png")
    Image.fromarray((mask * 255).astype(np.uint8)).save(tmp_path / "ball.mask.png")
    model = load_model(_alone_model(tmp_path / "alone.safetensors"))       # reads through the mask
    got = score_photo_set(model, str(tmp_path), camera_tilt_deg=10.0, linear=True)
    ref = predict_arrays(model, [photo / 255.0 * mask[..., None]], [10.0])[0]
    np.testing.assert_allclose(got["to_light_camera"][0], ref["to_light_camera"], atol=1e-9)


def test_the_shipped_object_model_reads_the_objects_alone(tmp_path, capsys):
    """``--model object``: the objects alone, in the camera frame with its own camera head;
    an image without a mask is one line and exit 2."""
    from relight.cli import main
    from relight.net.io import load_model_file, resolve_model
    config = load_model_file(resolve_model("object")).config
    assert config.surround == "black" and config.target_frame == "camera" and config.camera_head
    from relight.imageio import write_png
    write_png(str(tmp_path / "p.png"), np.full((20, 30, 3), 0.3, np.float32))
    try:
        code = main(["predict", str(tmp_path / "p.png"), "--model", "object", "--out", str(tmp_path / "o.json")])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and "reads the objects alone" in err and not (tmp_path / "o.json").exists()


@needs_blender
def test_a_cycles_twin_keeps_the_object_masks(tmp_path, mi):
    """benchmarks/cycles_twin.py on a dataset with object masks: the twin's records name the
    same masks (geometry alone sets them), so a model of the objects alone reads it."""
    from conftest import load_script
    from relight.dataset import read_manifest
    from relight.generator.run import generate
    from relight.net.data import LightDataset
    src, twin = tmp_path / "src", tmp_path / "twin"
    generate(src, 2, seed=9, cfg=dataclasses.replace(CFG, res=16, object_masks=True), progress=False)
    assert load_script("benchmarks/cycles_twin.py").cycles_twin(str(src), str(twin), spp=2, progress=False) == 2
    for rec in read_manifest(twin):
        assert (twin / rec["mask"]).read_bytes() == (src / rec["mask"]).read_bytes()
    black = LightDataset(twin, "all", res=16, source="exr", surround="black")
    assert all(np.isfinite(black.linear_image(i)).all() for i in range(len(black)))

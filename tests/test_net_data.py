"""relight.net.data: input encoding, flip augmentation labels, agreement with frames."""
import json
import os

import numpy as np
import pytest
import torch
from PIL import Image

from relight import frames
from relight.dataset import DatasetError
from relight.net.data import LightDataset, flip_y, prepare_srgb8, split_records
from relight.net.evaluate import decode_outputs

ANGLE_TOL_DEG = 1e-9


def _fake_dataset(root, n=6, res=24, green0=0):
    """A dataset folder with synthetic images (a left-right ramp, green ``green0 + 10 * index``)
    and true 7-vectors."""
    os.makedirs(os.path.join(root, "images"))
    rng = np.random.default_rng(0)
    with open(os.path.join(root, "manifest.jsonl"), "w") as f:
        for i in range(n):
            img = np.zeros((res, res, 3), np.uint8)
            img[..., 0] = np.linspace(0, 255, res, dtype=np.uint8)[None, :]  # red ramps left -> right
            img[..., 1] = green0 + 10 * i
            Image.fromarray(img).save(os.path.join(root, "images", f"{i:06d}.png"))
            pan_l, tilt_l, tilt_c = float(rng.integers(0, 360)), float(rng.integers(6, 18) * 5), 40.0
            rgb = [0.6, 0.58, 0.55]
            rec = {"id": f"{i:06d}", "image": f"images/{i:06d}.png", "split": "train" if i < n - 1 else "val",
                   "light": {"pan_deg": pan_l, "tilt_deg": tilt_l, "rgb": rgb},
                   "camera": {"pan_deg": 0.0, "tilt_deg": tilt_c}, "pan_rel_deg": pan_l,
                   "y": frames.encode_y(pan_l, tilt_l, rgb, tilt_c).tolist()}
            f.write(json.dumps(rec) + "\n")
    return root


@pytest.fixture(scope="module")
def fake(tmp_path_factory):
    return _fake_dataset(str(tmp_path_factory.mktemp("fake")))


@pytest.mark.parametrize("pan_rel", [0.0, 30.0, 90.0, 179.0, 250.0, 359.0])
@pytest.mark.parametrize("tilt_c", [10.0, 45.0, 70.0])
def test_flip_label_is_mirrored_light(pan_rel, tilt_c):
    # Mirroring the image left-right swaps the camera's right (+Y) and left, i.e. the
    # light at pan_rel appears at 360 - pan_rel; tilt and colour are unchanged.
    rgb = [0.7, 0.5, 0.5]
    y = frames.encode_y(pan_rel, 55.0, rgb, tilt_c)
    want = frames.encode_y(frames.wrap360(360.0 - pan_rel), 55.0, rgb, tilt_c)
    np.testing.assert_allclose(flip_y(y), want, atol=1e-12)
    np.testing.assert_allclose(flip_y(torch.tensor(y)).numpy(), want, atol=1e-12)
    assert y[0] == frames.encode_y(pan_rel, 55.0, rgb, tilt_c)[0]  # input not modified


@pytest.mark.parametrize("tilt_c", [10.0, 45.0, 70.0])
def test_decode_agrees_with_frames(tilt_c):
    pan = np.array([0.0, 1.0, 90.0, 180.0, 271.0, 359.0])
    tilt = np.array([30.0, 35.0, 50.0, 65.0, 80.0, 90.0])
    rgb = np.array([[3.0, 2.0, 1.0]] * 6)
    y = frames.encode_y(pan, tilt, rgb, tilt_c)
    # an unnormalised network output (sin/cos scaled by 0.7) decodes to the same angles
    y_net = y * np.array([0.7, 0.7, 1.3, 1.3, 1, 1, 1])
    p, t, c = decode_outputs(y_net, tilt_c)
    fp, ft, _ = frames.decode_y(y, tilt_c)
    assert np.max(np.abs(frames.wrap180(p - pan))) < 1e-9 and np.max(np.abs(p - fp)) < 1e-9
    np.testing.assert_allclose(t, tilt, atol=1e-9)
    np.testing.assert_allclose(t, ft, atol=1e-9)
    np.testing.assert_allclose(c, rgb / np.linalg.norm(rgb, axis=1, keepdims=True), atol=1e-12)


def test_dataset_items_match_records(fake):
    ds = LightDataset(fake, "train", res=24)
    assert len(ds) == 5
    x, y, i = ds[2]
    assert x.shape == (3, 24, 24) and x.dtype == torch.float32 and 0 <= x.min() and x.max() <= 1
    np.testing.assert_allclose(y.numpy(), ds.records[2]["y"], atol=1e-6)
    assert x[1, 0, 0].item() == pytest.approx(20 / 255)  # green = 10 * index, exact 8-bit value


def test_flipped_items_mirror_image_and_label(fake):
    ds = LightDataset(fake, "all", res=24, flip=True, seed=3)
    plain = LightDataset(fake, "all", res=24)
    n_flipped = 0
    for epoch in range(4):
        ds.epoch = epoch
        for i in range(len(ds)):
            x, y, _ = ds[i]
            x0, y0, _ = plain[i]
            if ds.flipped(i):
                n_flipped += 1
                assert torch.equal(x, torch.flip(x0, dims=(-1,)))
                # the red ramp now decreases left -> right
                assert x[0, 0, 0] > x[0, 0, -1]
                np.testing.assert_allclose(y.numpy(), flip_y(y0).numpy())
            else:
                assert torch.equal(x, x0) and torch.equal(y, y0)
            assert ds.flipped(i) == ds.flipped(i)  # deterministic per (seed, epoch, index)
    assert 0 < n_flipped < 4 * len(ds)


def test_prepare_resizes_and_centre_crops():
    img = np.zeros((60, 100, 3), np.uint8)
    img[:, 20:80] = 200  # the central 60 x 60 square
    x = prepare_srgb8(img, 30)
    assert x.shape == (3, 30, 30)
    assert torch.allclose(x, torch.full_like(x, 200 / 255), atol=1e-6)  # crop kept only the square
    same = np.random.default_rng(0).integers(0, 256, (16, 16, 3), dtype=np.uint8)
    assert torch.equal(prepare_srgb8(same, 16), torch.from_numpy(same.transpose(2, 0, 1) / 255.0).float())


def test_prepare_rejects_float_images():
    with pytest.raises(ValueError, match="uint8"):
        prepare_srgb8(np.zeros((8, 8, 3), np.float32), 8)


def test_unknown_split_and_missing_image(fake, tmp_path):
    with pytest.raises(DatasetError, match="unknown split"):
        split_records([], "holdout")
    ds = LightDataset(fake, "train", res=24, records=[{"id": "x", "image": "images/none.png", "split": "train"}])
    with pytest.raises(DatasetError, match="missing"):
        ds[0]
    with pytest.raises(DatasetError):
        LightDataset(tmp_path, "train")


def test_several_folders_join_their_splits(fake, tmp_path):
    # Two folders with the same record ids (every dataset numbers from 000000): items
    # follow the folders' order and each image comes from its own folder.
    other = _fake_dataset(str(tmp_path / "other"), n=4, green0=100)
    both = LightDataset([fake, other], "train", res=24)
    one, two = LightDataset(fake, "train", res=24), LightDataset(other, "train", res=24)
    assert len(both) == len(one) + len(two) == 5 + 3 and both.part_sizes() == [5, 3]
    for i in range(len(both)):
        x, y, _ = both[i]
        want_x, want_y, _ = one[i] if i < len(one) else two[i - len(one)]
        assert torch.equal(x, want_x) and torch.equal(y, want_y)
    assert both[5][0][1, 0, 0].item() == pytest.approx(100 / 255)   # other's first image, not fake's
    assert both.truth()["id"][5] == "000000"
    assert len(LightDataset([fake, other], "val", res=24)) == 2


def test_several_folders_refresh_and_agree_per_folder(tmp_path):
    a = _fake_dataset(str(tmp_path / "a"), n=4)
    b = _fake_dataset(str(tmp_path / "b"), n=4, green0=100)
    ds = LightDataset([a, b], "all", res=24)
    ds.keep_first([2, 3])   # what processes that read growing manifests agree on
    assert ds.part_sizes() == [2, 3] and [r["id"] for r in ds.records] == ["000000", "000001", "000000",
                                                                          "000001", "000002"]
    assert ds[2][0][1, 0, 0].item() == pytest.approx(100 / 255)
    with open(os.path.join(a, "manifest.jsonl")) as f:   # folder a grows: b's records keep their images
        first = f.readline()
    with open(os.path.join(a, "manifest.jsonl"), "a") as f:
        f.write(first.replace('"000000"', '"000099"'))
    assert ds.refresh() == 5 + 4 and ds.part_sizes() == [5, 4]
    assert ds[5][0][1, 0, 0].item() == pytest.approx(100 / 255)
    twin = ds.unaugmented()
    assert len(twin) == len(ds) and not twin.flip


def test_same_folder_twice_is_refused(fake):
    with pytest.raises(DatasetError, match="twice"):
        LightDataset([fake, os.path.join(fake, ".")], "train")
    with pytest.raises(DatasetError, match="no dataset folder"):
        LightDataset([], "train")

"""Figures: column choice, Figure 3 / panel files, the sphere and pole commands."""
import json

import numpy as np
import pytest
from PIL import Image

from relight.cli import main
from relight.predictions import write_predictions
from relight.verify import figures
from relight.verify.compare import ImageComparison, Light


def test_pick_columns_sorted_and_spread():
    errs = [5.0, 1.0, 30.0, 12.0, 7.0, 2.0, 40.0, 3.0, 9.0, 20.0]
    cols = figures.pick_columns(errs, max_columns=4)
    picked = [errs[i] for i in cols]
    assert picked == sorted(picked) and len(cols) == 4
    assert picked[0] == min(errs) and picked[-1] == max(errs)
    assert figures.pick_columns([3.0, 1.0, 2.0], 8) == [1, 2, 0]


def test_luminance_difference_sign():
    a = np.zeros((4, 4, 3))
    b = np.ones((4, 4, 3))
    np.testing.assert_allclose(figures.luminance_difference(a, b), 1.0)   # Rec.709 weights sum to 1
    np.testing.assert_allclose(figures.luminance_difference(b, a), -1.0)


def _fake_item(i, rng):
    a = rng.uniform(0, 1, (24, 24, 3)).astype(np.float32)
    b = np.clip(a + rng.normal(0, 0.05 * (i + 1), a.shape), 0, None).astype(np.float32)
    gt, pred = Light(10.0 * i, 45.0, (0.6, 0.6, 0.52)), Light(10.0 * i + 3 * i, 40.0, (0.6, 0.55, 0.58))
    return ImageComparison(id=f"{i:06d}", camera_tilt_deg=30.0, gt=gt, pred=pred,
                           light_errors_deg={"pan": 3.0 * i, "tilt": 5.0, "direction": float(10 - i),
                                             "colour": 1.5},
                           image_errors={"rmse": 0.1, "psnr_db": 20.0, "ssim": 0.9},
                           noise_floor={"rmse": 0.01, "psnr_db": 40.0, "ssim": 0.99},
                           original=a, rerender=b, res=24, spp=4, seed=0)


def test_figure3_and_panel_files(tmp_path):
    rng = np.random.default_rng(0)
    items = [_fake_item(i, rng) for i in range(10)]
    cols = figures.save_figure3(items, [str(tmp_path / "f.png"), str(tmp_path / "f.pdf")], max_columns=5)
    assert len(cols) == 5
    assert [items[i].light_errors_deg["direction"] for i in cols] == sorted(
        items[i].light_errors_deg["direction"] for i in cols)
    assert Image.open(tmp_path / "f.png").size[0] > Image.open(tmp_path / "f.png").size[1]
    assert (tmp_path / "f.pdf").read_bytes()[:4] == b"%PDF"
    figures.save_panel(items[0], str(tmp_path / "p.png"))
    assert Image.open(tmp_path / "p.png").size[0] > 300
    with pytest.raises(ValueError):
        figures.save_figure3([], [str(tmp_path / "g.png")])


def test_spheres_command_for_photographs(tmp_path, capsys, mi):
    # No dataset: the ground truth comes from gt_* fields (a photograph with a stated light).
    entries = [{"id": "photo1", "pan_deg": 100.0, "tilt_deg": 40.0, "rgb": [1.0, 0.9, 0.8],
                "gt_pan_deg": 90.0, "gt_tilt_deg": 40.0, "gt_rgb": [1.0, 0.9, 0.8]},
               {"id": "photo2", "pan_deg": 200.0, "tilt_deg": 60.0, "rgb": [1.0, 1.0, 1.0]}]
    write_predictions(tmp_path / "p.json", entries)
    out = tmp_path / "sph"
    code = main(["figure", "spheres", str(tmp_path / "p.json"), "--out", str(out), "--res", "32", "--spp", "8"])
    assert code == 0
    assert (out / "spheres_000.png").is_file() and (out / "spheres_000.pdf").is_file()
    settings = json.loads((out / "settings.json").read_text())
    # same tilt, pans 10 deg apart at tilt 40: angle = acos(cos^2 40 cos 10 + sin^2 40)
    t, d = np.radians(40.0), np.radians(10.0)
    expected = np.degrees(np.arccos(np.cos(t) ** 2 * np.cos(d) + np.sin(t) ** 2))
    assert settings["errors_deg"]["photo1"]["direction"] == pytest.approx(expected, abs=1e-9)
    assert settings["errors_deg"]["photo1"]["colour"] == pytest.approx(0.0, abs=1e-9)
    assert settings["errors_deg"]["photo2"] is None   # no ground truth: shown as n/a


def test_spheres_command_bad_gt(tmp_path, capsys, mi):
    write_predictions(tmp_path / "p.json", [{"id": "x", "pan_deg": 1.0, "tilt_deg": 40.0, "rgb": [1, 1, 1],
                                             "gt_pan_deg": 3.0}])
    code = main(["figure", "spheres", str(tmp_path / "p.json"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and "'x'" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_pole_command(tmp_path, capsys, mi):
    img = np.full((90, 120, 3), 40, np.uint8)
    Image.fromarray(img).save(tmp_path / "street.png")
    write_predictions(tmp_path / "p.json", [{"id": "street", "pan_deg": 90.0, "tilt_deg": 35.0, "rgb": [1, 1, 1]},
                                            {"id": "other", "pan_deg": 0.0, "tilt_deg": 35.0, "rgb": [1, 1, 1]}])
    out = tmp_path / "pole.png"
    code = main(["figure", "pole", str(tmp_path / "street.png"), str(tmp_path / "p.json"),
                 "--camera-tilt", "45", "--out", str(out)])
    assert code == 0
    res = np.asarray(Image.open(out))
    assert res.shape == img.shape
    assert (res[:30, :30] != 40).any()                    # inset drawn top-left
    np.testing.assert_array_equal(res[45:, 45:], img[45:, 45:])   # rest untouched
    # an image name matching no entry among several is an error naming the choice
    Image.fromarray(img).save(tmp_path / "nomatch.png")
    code = main(["figure", "pole", str(tmp_path / "nomatch.png"), str(tmp_path / "p.json"),
                 "--out", str(tmp_path / "x.png")])
    assert code == 2 and "--id" in capsys.readouterr().err


def test_pole_uses_the_entrys_camera_tilt(tmp_path, capsys, mi):
    """A camera-frame model's entry carries the tilt it predicted; the pole is drawn with it
    (the same image as --camera-tilt that value; another tilt draws another light)."""
    from relight import frames
    img = np.full((48, 48, 3), 40, np.uint8)
    Image.fromarray(img).save(tmp_path / "street.png")
    y = [float(v) for v in frames.encode_y(60.0, 35.0, [1.0, 1.0, 1.0], 20.0)]
    write_predictions(tmp_path / "p.json", [{"id": "street", "y": y, "camera_tilt_deg": 20.0}])
    outs = {}
    for name, opt in (("own", []), ("given", ["--camera-tilt", "20"]), ("paper", ["--camera-tilt", "45"])):
        outs[name] = tmp_path / f"{name}.png"
        assert main(["figure", "pole", str(tmp_path / "street.png"), str(tmp_path / "p.json"), *opt,
                     "--out", str(outs[name])]) == 0
    text = capsys.readouterr().out
    assert "camera tilt 20 deg" in text.splitlines()[0]
    own, given, paper = (np.asarray(Image.open(outs[k])) for k in ("own", "given", "paper"))
    np.testing.assert_array_equal(own, given)
    assert (own != paper).any()

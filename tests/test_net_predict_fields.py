"""Optional prediction fields: a grayscale input is marked ``colour_reliable: false``
with one warning line; the evaluation's per-image table carries kappa and the 90% cone."""
import csv
import json

import numpy as np
import pytest
import torch
from PIL import Image

from relight.cli import main
from relight.errors import PredictionsError
from relight.net.io import save_model
from relight.net.model import LightNet, NetConfig
from relight.net.predict import ACHROMATIC_TOLERANCE, is_achromatic, load_model, predict_arrays
from relight.predictions import read_predictions
from conftest import tiny_dataset, untrained_model

RES = 32


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    return untrained_model(tmp_path_factory.mktemp("m") / "net.safetensors", res=RES)


def _colour_image(seed=0, size=40):
    rng = np.random.default_rng(seed)
    return (rng.random((size, size, 3)) * 255).astype(np.uint8)


def test_is_achromatic_edges():
    grey = np.repeat(_colour_image()[..., :1], 3, axis=2)
    assert is_achromatic(grey)
    near = grey.astype(np.int16)
    near[5, 7, 0] = min(255, near[5, 7, 0] + ACHROMATIC_TOLERANCE) if near[5, 7, 0] < 200 else near[5, 7, 0] - 2
    assert is_achromatic(np.clip(near, 0, 255).astype(np.uint8))       # JPEG-like rounding still grey
    off = grey.copy()
    off[3, 3] = (100, 100, 100 + ACHROMATIC_TOLERANCE + 1)              # one pixel with colour
    assert not is_achromatic(off)
    assert not is_achromatic(_colour_image())


def test_cli_predict_grey_warns_once_and_marks(model_file, tmp_path, capsys):
    d = tmp_path / "imgs"
    d.mkdir()
    rgb = _colour_image(1)
    Image.fromarray(rgb).save(d / "colour.png")
    Image.fromarray(rgb).convert("L").save(d / "grey_l.png")                        # PNG mode L
    Image.fromarray(np.repeat(rgb[..., 1:2], 3, axis=2)).save(d / "grey_rgb.png")    # grey stored as RGB
    out = tmp_path / "pred.json"
    assert main(["predict", str(d), "--model", model_file, "--out", str(out)]) == 0
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "grey_l" in lines[0] and "grey_rgb" in lines[0] and "colour.png" not in lines[0]
    assert "meaningless" in lines[0]
    preds = {p.id: p for p in read_predictions(out).predictions}
    assert preds["grey_l"].extra["colour_reliable"] is False
    assert preds["grey_rgb"].extra["colour_reliable"] is False
    assert "colour_reliable" not in preds["colour"].extra
    raw = json.load(open(out))["predictions"]
    assert sum("colour_reliable" in e for e in raw) == 2


def test_cli_predict_colour_image_no_warning(model_file, tmp_path, capsys):
    Image.fromarray(_colour_image(2)).save(tmp_path / "a.png")
    assert main(["predict", str(tmp_path / "a.png"), "--model", model_file, "--out", str(tmp_path / "p.json")]) == 0
    assert capsys.readouterr().err.strip() == ""


def test_predict_arrays_marks_grey(model_file):
    model = load_model(model_file)
    rng = np.random.default_rng(3)
    lum = rng.random((24, 24, 1)).astype(np.float32)
    preds = predict_arrays(model, [np.repeat(lum, 3, axis=2), rng.random((24, 24, 3)).astype(np.float32)],
                           [30.0, 30.0])
    assert preds[0]["colour_reliable"] is False and "colour_reliable" not in preds[1]


def test_colour_reliable_must_be_boolean(tmp_path):
    path = tmp_path / "p.json"
    entry = {"id": "a", "pan_deg": 10.0, "tilt_deg": 40.0, "rgb": [1, 1, 1], "colour_reliable": "no"}
    path.write_text(json.dumps({"format": "relight.predictions/v1", "predictions": [entry]}))
    with pytest.raises(PredictionsError, match="colour_reliable"):
        read_predictions(path)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    return tiny_dataset(tmp_path_factory.mktemp("tiny"), count=6, seed=13, res=RES)


def test_per_image_csv_has_kappa_and_cone(tiny, model_file, tmp_path):
    from relight.net.uncertainty import cone_radius_deg
    rep = tmp_path / "rep"
    assert main(["evaluate", "--model", model_file, "--data", tiny, "--split", "all", "--out", str(rep)]) == 0
    with open(rep / "per_image.csv") as f:
        rows = list(csv.DictReader(f))
    preds = {p["id"]: p for p in json.load(open(rep / "predictions.json"))["predictions"]}
    assert len(rows) == 6
    for r in rows:
        k, cone = float(r["kappa"]), float(r["cone90_deg"])
        assert k == pytest.approx(preds[r["id"]]["kappa"], rel=1e-5)
        assert cone == pytest.approx(float(cone_radius_deg(k)), abs=1e-3)       # the closed form
        assert cone == pytest.approx(preds[r["id"]]["cone90_deg"], abs=1e-3)


def test_per_image_csv_without_kappa_head(tiny, tmp_path):
    torch.manual_seed(0)
    path = str(tmp_path / "nok.safetensors")
    save_model(path, LightNet(NetConfig(res=RES, width=8, kappa_head=False)), {})
    rep = tmp_path / "rep"
    assert main(["evaluate", "--model", path, "--data", tiny, "--split", "all", "--out", str(rep)]) == 0
    with open(rep / "per_image.csv") as f:
        header = next(csv.reader(f))
    assert "kappa" not in header and "cone90_deg" not in header and header[-1] == "colour_err_deg"

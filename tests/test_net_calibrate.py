"""Fitting the kappa head on held-out errors (relight.net.calibrate): the fit recovers a
known per-sample concentration from vMF draws, and ``relight calibrate`` writes a
calibrated model that never does worse on the check part than the one it read."""
import json
import math

import numpy as np
import pytest
import torch

from relight import frames
from relight.cli import main
from relight.net.calibrate import CalibrationConfig, fit_head
from relight.net.io import load_model_file, read_model_file, save_model
from relight.net.model import LightNet, NetConfig, _head, head_kappa
from relight.net.uncertainty import spearman
from conftest import tiny_dataset, untrained_model

RES = 32
CAMERA_TILT_DEG = 30.0
N_FIT, N_CHECK = 1500, 500
KAPPA_RANGE = (5.0, 500.0)        # true concentrations: 90% cones of about 9 to 60 degrees
RECOVERED_RANK = 0.9              # Spearman between fitted and true kappa
RECOVERED_LOG_RATIO = 0.35        # median |log(fitted / true)|, about 40% (one draw per kappa)


@pytest.fixture(autouse=True)
def one_thread():
    """Small tensors on a shared machine: one torch thread is the fastest."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def _vmf_sample(mu: np.ndarray, kappa: float, rng) -> np.ndarray:
    """One draw of a vMF around unit ``mu``: the angle by inverting
    P(theta <= t) = (1 - exp(-kappa (1 - cos t))) / (1 - exp(-2 kappa)), uniform azimuth."""
    u = rng.random()
    one_minus_cos = -math.log1p(-u * -math.expm1(-2.0 * kappa)) / kappa
    cos_t = 1.0 - one_minus_cos
    sin_t = math.sqrt(max(0.0, 1.0 - cos_t * cos_t))
    phi = rng.random() * 2.0 * math.pi
    local = np.array([sin_t * math.cos(phi), sin_t * math.sin(phi), cos_t])
    return frames.frame_z_to(mu) @ local


def _y(d: np.ndarray) -> np.ndarray:
    _, pan, tilt = frames.cartesian_to_spherical(d)
    return frames.encode_y(pan, tilt, [1.0, 1.0, 1.0], CAMERA_TILT_DEG)


def _synthetic(n: int, rng, w_true: np.ndarray) -> tuple[dict, np.ndarray]:
    """Embeddings e (n, d), true log kappa = w.e (clipped to KAPPA_RANGE), predicted
    directions, and true directions drawn from the vMF around them."""
    e = rng.standard_normal((n, w_true.size))
    kappa = np.clip(np.exp(math.log(50.0) + e @ w_true), *KAPPA_RANGE)
    y_pred, y_true = [], []
    for k in kappa:
        mu = frames.direction(rng.uniform(0, 360), rng.uniform(20, 80))
        y_pred.append(_y(mu))
        y_true.append(_y(_vmf_sample(mu, float(k), rng)))
    out = {"embedding": torch.tensor(e, dtype=torch.float32),
           "y_pred": torch.tensor(np.array(y_pred), dtype=torch.float32),
           "y_true": torch.tensor(np.array(y_true), dtype=torch.float32),
           "target_tilt_deg": torch.full((n,), CAMERA_TILT_DEG)}
    return out, kappa


def test_fit_head_recovers_known_concentration():
    rng = np.random.default_rng(0)
    w_true = np.array([1.0, -0.6, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    fit, _ = _synthetic(N_FIT, rng, w_true)
    check, kappa_check = _synthetic(N_CHECK, rng, w_true)
    torch.manual_seed(0)
    head = _head(w_true.size, 16, 1)
    with torch.no_grad():
        before = head_kappa(head, check["embedding"]).numpy()
    best_step, curve = fit_head(head, fit, check, CalibrationConfig(lr=1e-2, weight_decay=0.0, max_steps=1500,
                                                                    patience=200))
    with torch.no_grad():
        fitted = head_kappa(head, check["embedding"]).numpy()
    assert best_step > 0 and min(curve) < curve[0]
    assert spearman(fitted, kappa_check) > RECOVERED_RANK
    assert np.median(np.abs(np.log(fitted / kappa_check))) < RECOVERED_LOG_RATIO
    assert np.median(np.abs(np.log(before / kappa_check))) > RECOVERED_LOG_RATIO   # the test can fail


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    return tiny_dataset(tmp_path_factory.mktemp("tiny"), count=12, seed=17, res=RES)


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    return untrained_model(tmp_path_factory.mktemp("m") / "net.safetensors", res=RES)


@pytest.mark.parametrize("mode", ["head", "last", "temperature"])
def test_cli_calibrate_writes_calibrated_model(tiny, model_file, tmp_path, capsys, mode, monkeypatch):
    import functools

    from relight.net import calibrate
    monkeypatch.setattr(calibrate, "CalibrationConfig", functools.partial(CalibrationConfig, max_steps=60))
    out = tmp_path / "cal.safetensors"
    assert main(["calibrate", "--run", model_file, "--data", tiny, "--split", "all", "--mode", mode,
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "check part before" in text and "wrote" in text
    _, _, info = read_model_file(out)
    rep = info["kappa_calibration"]
    assert rep["n_images"] == 12 and rep["n_fit"] + rep["n_check"] == 24      # with mirror images
    assert rep["check_after"]["nll_mean"] <= rep["check_before"]["nll_mean"] + 1e-9
    model = load_model_file(out)
    assert float(model.kappa_temperature) == pytest.approx(rep["temperature"])
    assert info["kappa_temperature"] == pytest.approx(rep["temperature"])
    before, after = load_model_file(model_file), model
    same = lambda a, b: all(torch.equal(x, y) for x, y in zip(a.parameters(), b.parameters()))
    body = lambda m: torch.nn.ModuleList([c for n, c in m.named_children() if n != "kappa_head"])
    assert same(body(before), body(after))                     # the network itself is frozen
    if rep["kept"] == "temperature":
        assert same(before.kappa_head, after.kappa_head)
    json.dumps(rep)                                            # the report is JSON-ready


def test_cli_calibrate_refuses_bad_input(tiny, model_file, tmp_path, capsys):
    assert main(["calibrate", "--model", model_file, "--data", tiny, "--out", str(tmp_path / "c.safetensors")]) == 2
    assert "split 'val'" in capsys.readouterr().err          # 12 images: no val split to speak of
    torch.manual_seed(0)
    nok = str(tmp_path / "nok.safetensors")
    save_model(nok, LightNet(NetConfig(res=RES, width=8, kappa_head=False)), {})
    assert main(["calibrate", "--model", nok, "--data", tiny, "--split", "all",
                 "--out", str(tmp_path / "c.safetensors")]) == 2
    assert "no kappa head" in capsys.readouterr().err
    assert main(["calibrate", "--model", model_file, "--data", tiny, "--split", "all", "--out", model_file]) == 2
    assert "input" in capsys.readouterr().err
    assert not (tmp_path / "c.safetensors").exists()


def test_cli_calibrate_on_two_folders_joins_their_splits(tiny, model_file, tmp_path, capsys, monkeypatch):
    # A model trained on several folders is calibrated on their joined held-out splits:
    # the same folder's copy doubles the images and leaves the fit's inputs otherwise equal.
    import functools
    import shutil

    from relight.net import calibrate
    monkeypatch.setattr(calibrate, "CalibrationConfig", functools.partial(CalibrationConfig, max_steps=20))
    twin = str(tmp_path / "twin")
    shutil.copytree(tiny, twin)
    out = tmp_path / "cal.safetensors"
    assert main(["calibrate", "--run", model_file, "--data", tiny, "--data", twin, "--split", "all",
                 "--mode", "temperature", "--out", str(out)]) == 0
    rep = read_model_file(out)[2]["kappa_calibration"]
    assert rep["n_images"] == 24 and rep["n_fit"] + rep["n_check"] == 48
    assert rep["data_dir"] == [tiny, twin]
    capsys.readouterr()
    assert main(["calibrate", "--run", model_file, "--data", tiny, "--data", tiny, "--split", "all",
                 "--out", str(tmp_path / "c2.safetensors")]) == 2
    assert "twice" in capsys.readouterr().err and not (tmp_path / "c2.safetensors").exists()

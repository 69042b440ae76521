"""relight.net.uncertainty: vMF maths against closed forms, quadrature and sampling,
the NLL against scipy and finite differences, temperature scaling on synthetic data,
and the cone / kappa / CCT fields of predictions (new and old model files)."""
import json
import math

import numpy as np
import pytest
import torch

from relight import frames
from relight.net import uncertainty as u
from relight.net.io import read_model_file, save_model
from relight.net.model import LightNet, NetConfig
from relight.predictions import PredictionsError, parse_entry, read_predictions

KAPPAS = [0.05, 0.7, 4.0, 40.0, 400.0, 4000.0]
QUAD_TOL = 1e-8                # probability held by the closed-form cone, by quadrature
N_SAMPLES = 200_000
SAMPLE_SIGMAS = 4.0            # sampled coverage within 4 binomial standard deviations
NLL_TOL = 1e-9
T_TRUE = 2.5
T_REL_TOL = 0.03               # fitted temperature vs the true one, 20 000 samples
RES = 32


def _sample_vmf_angles(kappa, rng):
    """Angles (deg) of vMF samples around the mean by inverting the CDF of 1 - cos."""
    k = np.asarray(kappa, dtype=np.float64)
    w = rng.random(k.shape)
    one_minus_cos = -np.log1p(w * np.expm1(-2.0 * k)) / k
    return np.degrees(np.arccos(np.clip(1.0 - one_minus_cos, -1.0, 1.0)))


@pytest.mark.parametrize("kappa", KAPPAS)
def test_cone_holds_its_probability_by_quadrature(kappa):
    from scipy.integrate import quad
    # density over the polar angle: f(theta) 2 pi sin(theta), f the vMF density per steradian
    c = kappa / (2 * math.pi * -math.expm1(-2 * kappa))
    t = math.radians(float(u.cone_radius_deg(kappa, 0.9)))
    pts = [min(t, 10 / math.sqrt(kappa))] if kappa > 100 else None
    mass, _ = quad(lambda th: c * math.exp(-kappa * (1 - math.cos(th))) * 2 * math.pi * math.sin(th),
                   0.0, t, points=pts, epsabs=1e-12, epsrel=1e-12, limit=200)
    assert mass == pytest.approx(0.9, abs=QUAD_TOL)
    assert float(u.coverage_probability(kappa, math.degrees(t))) == pytest.approx(0.9, abs=1e-12)


def test_cone_limits():
    # kappa -> 0 is the uniform sphere: P(theta <= t) = (1 - cos t) / 2 -> cos t = -0.8
    assert float(u.cone_radius_deg(1e-9)) == pytest.approx(math.degrees(math.acos(-0.8)), abs=1e-4)
    # large kappa: the angle is Rayleigh with scale 1/sqrt(kappa): t90 = sqrt(2 ln 10 / kappa)
    assert float(u.cone_radius_deg(1e6)) == pytest.approx(math.degrees(math.sqrt(2 * math.log(10) / 1e6)), rel=1e-4)
    assert np.all(np.diff(u.cone_radius_deg(np.array(KAPPAS))) < 0)   # wider for less concentration
    with pytest.raises(ValueError):
        u.cone_radius_deg(10.0, 1.0)


@pytest.mark.parametrize("kappa", [2.0, 50.0])
def test_cone_coverage_of_scipy_samples(kappa):
    from scipy.stats import vonmises_fisher
    mu = frames.direction(30.0, 60.0)
    x = vonmises_fisher(mu, kappa).rvs(N_SAMPLES, random_state=np.random.default_rng(3))
    angle = np.degrees(np.arccos(np.clip(x @ mu, -1, 1)))
    inside = np.mean(angle <= u.cone_radius_deg(kappa, 0.9))
    assert abs(inside - 0.9) < SAMPLE_SIGMAS * math.sqrt(0.9 * 0.1 / N_SAMPLES)


def test_nll_matches_scipy_logpdf():
    from scipy.stats import vonmises_fisher
    rng = np.random.default_rng(0)
    mu = frames.direction(200.0, 40.0)
    for kappa in [0.3, 3.0, 30.0, 300.0]:
        x = rng.normal(size=(20, 3))
        x /= np.linalg.norm(x, axis=1, keepdims=True)
        ref = -vonmises_fisher(mu, kappa).logpdf(x)
        ours = u.vmf_nll(torch.full((20,), kappa, dtype=torch.float64), torch.from_numpy(x @ mu)).numpy()
        np.testing.assert_allclose(ours, ref, rtol=0, atol=NLL_TOL * max(1.0, kappa))
        np.testing.assert_allclose(u.vmf_nll_np(kappa, np.degrees(np.arccos(x @ mu))), ref, atol=1e-7 * max(1, kappa))


def test_nll_gradient_finite_differences_and_closed_form():
    k = torch.tensor([0.01, 0.5, 3.0, 80.0], dtype=torch.float64, requires_grad=True)
    c = torch.tensor([0.9, -0.3, 0.99, 0.999], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(u.vmf_nll, (k, c), eps=1e-6, atol=1e-6)
    u.vmf_nll(k, c).sum().backward()
    # d/dkappa [-log k + log(1 - e^{-2k}) + k (1 - c)] = -1/k + 2 / (e^{2k} - 1) + 1 - c
    kd, cd = k.detach(), c.detach()
    np.testing.assert_allclose(k.grad, -1 / kd + 2 / torch.expm1(2 * kd) + 1 - cd, rtol=1e-12)


def test_direction_from_y_matches_frames_including_past_zenith():
    rng = np.random.default_rng(1)
    y = rng.normal(size=(64, 7))
    tilt_c = rng.uniform(10, 70, 64)
    pan, tilt, _ = frames.decode_y(y, tilt_c)      # folded over the zenith where needed
    ref = frames.direction(pan, tilt)
    ours = u.direction_from_y(torch.from_numpy(y), torch.from_numpy(tilt_c)).numpy()
    np.testing.assert_allclose(ours, ref, atol=1e-12)


def test_direction_nll_trains_kappa_only():
    y_pred = torch.randn(8, 7, dtype=torch.float64, requires_grad=True)
    y_true = torch.randn(8, 7, dtype=torch.float64)
    kappa = torch.full((8,), 5.0, dtype=torch.float64, requires_grad=True)
    u.direction_nll(y_pred, y_true, kappa, torch.full((8,), 30.0, dtype=torch.float64)).backward()
    assert y_pred.grad is None and kappa.grad is not None   # the predicted direction is held fixed


def test_temperature_scaling_recovers_known_temperature():
    rng = np.random.default_rng(5)
    kappa_true = np.exp(rng.uniform(math.log(2), math.log(2000), 20_000))
    angle = _sample_vmf_angles(kappa_true, rng)
    t = u.fit_temperature(kappa_true * T_TRUE, angle)     # over-confident by T_TRUE
    assert t == pytest.approx(T_TRUE, rel=T_REL_TOL)
    s = u.uncertainty_summary(kappa_true * T_TRUE / t, angle)
    assert s["cone90_coverage"] == pytest.approx(0.9, abs=0.01)
    np.testing.assert_allclose(s["reliability"]["observed"], s["reliability"]["expected"], atol=0.015)
    assert s["spearman_cone90_error"] > 0.5       # the cone tracks the spread


def test_fit_temperature_bad_input():
    with pytest.raises(ValueError):
        u.fit_temperature([1.0, -1.0], [3.0, 4.0])
    assert u.fit_temperature([], []) == 1.0


# --- predictions: optional fields --------------------------------------------------------

def _entry(**extra):
    return {"id": "a", "pan_deg": 10.0, "tilt_deg": 40.0, "rgb": [0.6, 0.6, 0.5], **extra}


def test_optional_fields_validated():
    p = parse_entry(_entry(cone90_deg=12.0, kappa=35.0, cct_k=5000.0, duv=0.002), 0)
    assert p.extra["cone90_deg"] == 12.0
    parse_entry(_entry(cct_k=None, duv=None), 0)
    for bad in [dict(cone90_deg=0.0), dict(cone90_deg=200.0), dict(kappa=-1.0), dict(kappa=float("inf")),
                dict(cct_k=500.0, duv=0.0), dict(cct_k=5000.0, duv=0.2), dict(cct_k=5000.0),
                dict(cct_k=None, duv=0.001), dict(kappa=True), dict(cone90_deg="10")]:
        with pytest.raises(PredictionsError):
            parse_entry(_entry(**bad), 0)


def _write_png(path, seed):
    from PIL import Image
    rng = np.random.default_rng(seed)
    Image.fromarray((rng.random((40, 48, 3)) * 255).astype(np.uint8)).save(path)


def test_cli_predict_writes_cone_and_cct(tmp_path, capsys):
    from relight.cli import main
    torch.manual_seed(0)
    model = LightNet(NetConfig(res=RES, width=8))
    model.kappa_temperature.fill_(2.0)
    path = str(tmp_path / "m.safetensors")
    save_model(path, model)
    for i in range(3):
        _write_png(tmp_path / f"im{i}.png", i)
    out = tmp_path / "p.json"
    assert main(["predict", str(tmp_path / "im0.png"), str(tmp_path / "im1.png"), str(tmp_path / "im2.png"),
                 "--model", path, "--out", str(out)]) == 0
    preds = read_predictions(out).predictions       # validated, optional fields included
    assert len(preds) == 3
    for p in preds:
        e = p.extra
        assert e["kappa"] > 0 and e["cone90_deg"] == pytest.approx(float(u.cone_radius_deg(e["kappa"])))
        assert ("cct_k" in e) and ("duv" in e)
    # the stored temperature divides the raw kappa
    x = torch.rand(1, 3, RES, RES)
    loaded = LightNet(read_model_file(path)[0])
    loaded.load_state_dict(read_model_file(path)[1])
    loaded.eval()
    with torch.no_grad():
        raw = loaded.forward_with_kappa(x, calibrated=False)[1]
        cal = loaded.forward_with_kappa(x)[1]
    assert float(raw / cal) == pytest.approx(2.0)


def test_old_model_file_without_kappa_head_predicts(tmp_path, capsys):
    """A file as written before the kappa head and arch existed: metadata config without
    them, no kappa tensors. It loads as the small encoder and predicts without cones."""
    from safetensors.torch import save_file

    from relight.cli import main
    from relight.net.io import MODEL_FORMAT
    torch.manual_seed(0)
    old = LightNet(NetConfig(res=RES, width=8, kappa_head=False))
    config = {k: v for k, v in old.config.to_dict().items() if k not in ("arch", "kappa_head")}
    path = str(tmp_path / "old.safetensors")
    save_file({k: v.contiguous() for k, v in old.state_dict().items()}, path,
              metadata={"format": MODEL_FORMAT, "arch": "sid2-inception-small/v1",
                        "config": json.dumps(config), "info": "{}"})
    cfg, state, _ = read_model_file(path)
    assert cfg.arch == "small" and not cfg.kappa_head
    _write_png(tmp_path / "im.png", 0)
    out = tmp_path / "p.json"
    assert main(["predict", str(tmp_path / "im.png"), "--model", path, "--out", str(out)]) == 0
    e = read_predictions(out).predictions[0].extra
    assert "kappa" not in e and "cone90_deg" not in e and "cct_k" in e


def test_shipped_model_still_loads_without_kappa():
    from relight.net.io import SHIPPED_MODEL
    from relight.net.predict import load_model
    import os
    if not os.path.isfile(SHIPPED_MODEL):
        pytest.skip("no shipped model")
    model = load_model("sid2")
    with torch.no_grad():
        y, kappa = model.forward_with_kappa(torch.rand(1, 3, model.config.res, model.config.res))
    assert y.shape == (1, 7) and (kappa is None) == (not model.has_kappa)


def test_pan_halfwidth_of_a_cone():
    # on the horizon a cone of radius r spans pan +- r; at tilt t it spans asin(sin r / cos t)
    assert float(u.pan_halfwidth_deg(10.0, 0.0)) == pytest.approx(10.0)
    assert float(u.pan_halfwidth_deg(10.0, 60.0)) == pytest.approx(math.degrees(math.asin(math.sin(math.radians(10))
                                                                                       / math.cos(math.radians(60)))))
    # a cone reaching the zenith holds every pan
    assert float(u.pan_halfwidth_deg(10.0, 80.0)) == 180.0 and float(u.pan_halfwidth_deg(5.0, 89.0)) == 180.0
    # brute force: the widest pan among directions inside the cone
    mu = frames.direction(0.0, 50.0)
    pan = np.linspace(-90, 90, 3601)
    tilt = np.linspace(30, 70, 801)
    P, T = np.meshgrid(pan, tilt)
    inside = np.degrees(np.arccos(np.clip(frames.direction(P, T) @ mu, -1, 1))) <= 12.0
    assert np.abs(P[inside]).max() == pytest.approx(float(u.pan_halfwidth_deg(12.0, 50.0)), abs=0.1)

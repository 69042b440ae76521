"""relight.net.loss: closed-form values and finite gradients (also at the clamp)."""
import math

import numpy as np
import pytest
import torch

from relight import frames
from relight.net.loss import COS_CLAMP, LossWeights, angular_error_rad, light_loss

EXACT = 1e-6
CLAMP_FLOOR_RAD = math.acos(1.0 - COS_CLAMP) + 1e-6  # smallest angle the clamped acos reports


def _y(pan_l, tilt_l, rgb, tilt_c):
    return torch.tensor(frames.encode_y(pan_l, tilt_l, rgb, tilt_c), dtype=torch.float64)


def test_angular_error_closed_forms():
    a = torch.tensor([[1.0, 0, 0], [1.0, 1.0, 0], [2.0, 2.0, 2.0], [1.0, 0, 0]], dtype=torch.float64)
    b = torch.tensor([[0, 1.0, 0], [1.0, 0, 0], [1.0, 1.0, 1.0], [-1.0, 0, 0]], dtype=torch.float64)
    got = angular_error_rad(a, b).numpy()
    # orthogonal: pi/2; 45 degrees; same direction at another scale: 0 (up to the clamp); opposite: pi
    want = [math.pi / 2, math.pi / 4, 0.0, math.pi]
    np.testing.assert_allclose(got, want, atol=CLAMP_FLOOR_RAD)


def test_loss_closed_form():
    # pan pair off by (0.1, -0.2), tilt pair off by (0.3, 0): MSEs 0.025 and 0.045;
    # rgb (1,1,0) vs (1,0,0): 45 degrees = pi/4 rad.
    target = torch.tensor([[0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0]], dtype=torch.float64)
    pred = torch.tensor([[0.1, 0.8, 0.3, 1.0, 1.0, 1.0, 0.0]], dtype=torch.float64)
    parts = light_loss(pred, target, LossWeights(2.0, 3.0, 0.5), parts=True)
    assert parts["pan"].item() == pytest.approx(0.025, abs=EXACT)
    assert parts["tilt"].item() == pytest.approx(0.045, abs=EXACT)
    assert parts["colour"].item() == pytest.approx(math.pi / 4, abs=EXACT)
    assert parts["total"].item() == pytest.approx(2 * 0.025 + 3 * 0.045 + 0.5 * math.pi / 4, abs=EXACT)


def test_loss_zero_when_prediction_is_target():
    y = _y([10.0, 200.0], [30.0, 85.0], [[0.6, 0.6, 0.5], [0.5, 0.6, 0.62]], [20.0, 60.0])
    assert light_loss(y, y).item() <= CLAMP_FLOOR_RAD


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_gradient_finite_when_prediction_equals_target(dtype):
    y = _y([10.0, 200.0], [30.0, 85.0], [[0.6, 0.6, 0.5], [0.5, 0.6, 0.62]], [20.0, 60.0]).to(dtype)
    pred = y.clone().requires_grad_(True)
    light_loss(pred, y).backward()
    assert torch.isfinite(pred.grad).all()
    # also a prediction exactly opposite in colour (the other end of the clamp)
    pred2 = torch.cat([y[:, :4], -y[:, 4:]], dim=1).requires_grad_(True)
    light_loss(pred2, y).backward()
    assert torch.isfinite(pred2.grad).all()


def test_gradcheck_float64_away_from_clamp():
    torch.manual_seed(0)
    target = _y([40.0, 300.0, 120.0], [50.0, 35.0, 90.0], [[0.6, 0.6, 0.5]] * 3, [30.0, 45.0, 10.0])
    pred = (target + 0.2 * torch.randn_like(target)).abs().requires_grad_(True)
    assert torch.autograd.gradcheck(lambda p: light_loss(p, target, LossWeights(1.0, 0.5, 2.0)), (pred,))


def test_loss_rejects_bad_shapes():
    with pytest.raises(ValueError, match=r"\(N, 7\)"):
        light_loss(torch.zeros(2, 6), torch.zeros(2, 6))


def test_bad_weights():
    with pytest.raises(ValueError):
        LossWeights(pan=-1.0)

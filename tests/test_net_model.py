"""relight.net.model: shapes, initialisation, parameter/FLOP counts, bad input."""
import math

import pytest
import torch

from relight.net.model import COLOUR_FLOOR, LightNet, NetConfig, count_parameters, flops_per_image

HE_STD_RTOL = 0.15  # sample std of a big He-normal weight vs sqrt(2 / fan_in)


@pytest.fixture(scope="module")
def small_net():
    torch.manual_seed(0)
    return LightNet(NetConfig(res=32, width=16))


@pytest.mark.parametrize("res", [32, 48, 128])
def test_output_shape_any_resolution(res):
    net = LightNet(NetConfig(res=res, width=8))
    y = net(torch.rand(2, 3, res, res))
    assert y.shape == (2, 7)
    assert torch.isfinite(y).all()


def test_colour_output_positive(small_net):
    y = small_net(torch.rand(4, 3, 32, 32) * 10 - 5)
    assert (y[:, 4:7] >= COLOUR_FLOOR).all()  # softplus + floor: valid rgb for predictions files


def test_parameter_count_independent_of_resolution():
    # the adaptive grid pooling before the embedding makes the weights resolution-free
    assert count_parameters(LightNet(NetConfig(res=64))) == count_parameters(LightNet(NetConfig(res=128)))


def test_default_size_is_cpu_friendly():
    net = LightNet()
    n = count_parameters(net)
    flops = flops_per_image(net)
    assert 2e5 < n < 3e6
    assert 1e7 < flops < 1e9
    # FLOPs scale with pixel count (conv layers dominate): 64 px is about 1/4 of 128 px
    assert flops_per_image(net, 64) == pytest.approx(flops / 4, rel=0.1)


def test_he_normal_initialisation():
    torch.manual_seed(1)
    net = LightNet()
    w = net.embed[0].weight  # Linear 1024 -> 256: 262k samples
    fan_in = w.shape[1]
    assert w.std().item() == pytest.approx(math.sqrt(2.0 / fan_in), rel=HE_STD_RTOL)
    assert all((m.bias == 0).all() for m in net.modules() if isinstance(m, torch.nn.Linear))


def test_bad_input_shape_raises(small_net):
    with pytest.raises(ValueError, match="N, 3, H, W"):
        small_net(torch.rand(2, 1, 32, 32))


@pytest.mark.parametrize("bad", [dict(res=8), dict(width=0), dict(res=32.5)])
def test_bad_config_raises(bad):
    with pytest.raises(ValueError):
        NetConfig(**bad)


def test_config_round_trip():
    c = NetConfig(res=64, width=24)
    assert NetConfig.from_dict(c.to_dict()) == c

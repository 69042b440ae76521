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


def test_paper_arch_size_and_shapes():
    from relight.net.model import ARCHES, PAPER_ARCH_NAME
    net = LightNet(NetConfig.for_arch("paper"))
    small = LightNet(NetConfig.for_arch("small"))
    n = count_parameters(net)
    assert 3e6 < n < 1.5e7                        # several million parameters (file <= 50 MB)
    assert 4 * n < 50e6
    assert flops_per_image(net) < 2 * flops_per_image(small)   # CPU-sized despite the parameters
    y, kappa = net.forward_with_kappa(torch.rand(2, 3, 128, 128))
    assert y.shape == (2, 7) and kappa.shape == (2,) and (kappa > 0).all()
    assert net.config.arch_name == PAPER_ARCH_NAME == ARCHES["paper"]
    assert NetConfig.from_dict(net.config.to_dict()) == net.config
    with pytest.raises(ValueError, match="arch"):
        NetConfig(arch="huge")


def test_legacy_config_has_no_kappa_head():
    # a config stored before arch / kappa_head existed: the small encoder, no kappa head
    c = NetConfig.from_dict({"res": 128, "width": 32, "embed": 256, "head_hidden": 128, "grid": 4})
    assert c.arch == "small" and not c.kappa_head
    net = LightNet(c)
    assert not any(k.startswith("kappa") for k in net.state_dict())
    y, kappa = net.forward_with_kappa(torch.rand(1, 3, 64, 64))
    assert kappa is None and y.shape == (1, 7)


def test_kappa_head_sees_the_embedding_detached():
    torch.manual_seed(0)
    net = LightNet(NetConfig(res=32, width=8))
    _, kappa = net.forward_with_kappa(torch.rand(2, 3, 32, 32))
    kappa.sum().backward()
    assert all(p.grad is None for n, p in net.named_parameters() if not n.startswith("kappa_head"))
    assert all(p.grad is not None for n, p in net.named_parameters() if n.startswith("kappa_head"))


@pytest.mark.parametrize("arch", ["small", "paper"])
def test_folded_batchnorm_gives_the_same_outputs(arch, tmp_path):
    """Folding each batch norm into its convolution is exact algebra in eval mode: the
    outputs agree to float32 rounding, no batch norm is left, and the folded network
    refuses training and saving (its state dict no longer matches a model file)."""
    import copy

    from relight.net.io import save_model
    torch.manual_seed(0)
    net = LightNet(NetConfig(res=64, width=8, arch=arch))
    for m in net.modules():   # batch norms far from identity, so folding has work to do
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.5, 0.5)
            m.running_var.uniform_(0.2, 3.0)
            m.weight.data.uniform_(0.5, 2.0)
            m.bias.data.uniform_(-0.3, 0.3)
    net.eval()
    x = torch.rand(3, 3, 64, 64)
    folded = copy.deepcopy(net).fold_batchnorm()
    with torch.no_grad():
        (y0, k0), (y1, k1) = net.forward_with_kappa(x), folded.forward_with_kappa(x)
    assert not any(isinstance(m, torch.nn.BatchNorm2d) for m in folded.modules())
    convs = [m for m in folded.modules() if isinstance(m, torch.nn.Conv2d)]
    assert convs and all(c.weight.is_contiguous(memory_format=torch.channels_last) for c in convs)
    assert any(isinstance(m, torch.nn.BatchNorm2d) for m in net.modules())
    scale = y0.abs().max().item()
    assert (y1 - y0).abs().max().item() <= 1e-4 * scale
    assert torch.allclose(k1, k0, rtol=1e-4)
    assert folded.folded and not net.folded and not folded.training
    with pytest.raises(RuntimeError, match="inference only"):
        folded.train()
    with pytest.raises(ValueError, match="folded"):
        save_model(tmp_path / "m.safetensors", folded)
    assert not (tmp_path / "m.safetensors").exists()


def test_mirror_average_is_mirror_equivariant_and_the_mean_of_two_views():
    """MirrorAveraged: its 7-vector is the mean of the network's for the image and (mapped
    back, y0 -> -y0) for its mirror image, kappa the mean of the two; so the mirror image
    gets exactly the mirrored light (pan sine negated), the same tilt, colour and kappa,
    which the bare network does not."""
    from relight.net.data import flip_image, flip_y
    from relight.net.model import MirrorAveraged
    torch.manual_seed(3)
    net = LightNet(NetConfig(res=32, width=8, kappa_head=True)).eval()
    avg = MirrorAveraged(net).eval()
    assert avg.config is net.config and avg.has_kappa
    x = torch.rand(5, 3, 32, 32)
    with torch.no_grad():
        (y, k), (yf, kf) = net.forward_with_kappa(x), net.forward_with_kappa(flip_image(x))
        ya, ka = avg.forward_with_kappa(x)
        ym, km = avg.forward_with_kappa(flip_image(x))
        assert torch.allclose(avg(x), ya)
    assert torch.allclose(ya, (y + flip_y(yf)) / 2, atol=1e-6) and torch.allclose(ka, (k + kf) / 2, rtol=1e-6)
    assert torch.allclose(ym, flip_y(ya), atol=1e-6) and torch.allclose(km, ka, rtol=1e-6)
    assert not torch.allclose(yf, flip_y(y), atol=1e-3)   # the bare network is not equivariant

"""The paper's regression network: an Inception-based encoder and three heads.

Sial et al., "Our deep architecture": an encoder of five modules combining
inception, convolution and pooling layers, then three decoders for pan (2 outputs),
tilt (2) and colour (3) -- together the 7-vector of ``shared/conventions.md``:
``[sin(pan_c - pan_l), cos(pan_c - pan_l), sin(tilt_c - tilt_l), cos(tilt_c - tilt_l),
r, g, b]``. The inception modules are the "split" ones of Inception-v3 (Szegedy et
al. 2016, "Rethinking the Inception Architecture"): an n x n convolution is replaced
by 1 x n followed by n x 1. Weights use He-normal initialisation.

Sized for a 2-core CPU (0.47 M parameters, 0.127 GFLOP per 128 px image forward);
see ``benchmarks/bench_network.py``. The input resolution is a parameter: an adaptive
pooling before the embedding keeps the parameter count independent of it.

Input: ``(N, 3, res, res)`` float32, 8-bit sRGB scaled to [0, 1] (see
:func:`relight.net.data.prepare_srgb8`). Output: ``(N, 7)``; the sin/cos pairs are raw
(not normalised; decoding uses atan2) and the colour is positive (softplus), any scale.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn
from torch.nn import functional as F

ARCH_NAME = "sid2-inception-small/v1"
COLOUR_FLOOR = 1e-4  # added to the softplus colour output so rgb is never exactly 0


@dataclass(frozen=True)
class NetConfig:
    """Architecture settings (stored with the weights).

    Attributes:
        res: input width = height in pixels (default 128, the dataset's).
        width: base channel count; module widths scale with it.
        embed: embedding size shared by the three heads.
        head_hidden: hidden units in each head.
        grid: spatial size of the feature map flattened into the embedding.
    """
    res: int = 128
    width: int = 32
    embed: int = 256
    head_hidden: int = 128
    grid: int = 4

    def __post_init__(self):
        for name in ("res", "width", "embed", "head_hidden", "grid"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"NetConfig.{name} must be a positive integer, got {v!r}")
        if self.res < 16:
            raise ValueError(f"NetConfig.res must be >= 16 pixels, got {self.res}")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "NetConfig":
        known = {k: d[k] for k in cls.__dataclass_fields__ if k in d}
        return cls(**known)


class ConvBN(nn.Sequential):
    """Convolution (no bias) + batch norm + ReLU; ``kernel`` is (kh, kw) or int."""

    def __init__(self, c_in: int, c_out: int, kernel=1, stride: int = 1):
        kh, kw = (kernel, kernel) if isinstance(kernel, int) else kernel
        super().__init__(
            nn.Conv2d(c_in, c_out, (kh, kw), stride=stride, padding=(kh // 2, kw // 2), bias=False),
            nn.BatchNorm2d(c_out),
            nn.ReLU(inplace=True))


class SplitInception(nn.Module):
    """Inception-v3 style module with factorised (1 x n then n x 1) convolutions.

    Four branches concatenated on channels: 1x1; 1x1 -> 1x3 -> 3x1;
    1x1 -> (1x3 -> 3x1) twice (a factorised 5x5); 3x3 average pool -> 1x1.
    Spatial size is kept; output channels = ``4 * c_branch``.
    """

    def __init__(self, c_in: int, c_branch: int):
        super().__init__()
        c_red = max(8, c_branch // 2)
        self.b1 = ConvBN(c_in, c_branch, 1)
        self.b3 = nn.Sequential(ConvBN(c_in, c_red, 1), ConvBN(c_red, c_branch, (1, 3)),
                                ConvBN(c_branch, c_branch, (3, 1)))
        self.b5 = nn.Sequential(ConvBN(c_in, c_red, 1), ConvBN(c_red, c_branch, (1, 3)),
                                ConvBN(c_branch, c_branch, (3, 1)), ConvBN(c_branch, c_branch, (1, 3)),
                                ConvBN(c_branch, c_branch, (3, 1)))
        self.bp = ConvBN(c_in, c_branch, 1)
        self.out_channels = 4 * c_branch

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        pooled = F.avg_pool2d(x, 3, stride=1, padding=1, count_include_pad=False)
        return torch.cat([self.b1(x), self.b3(x), self.b5(x), self.bp(pooled)], dim=1)


def _head(c_in: int, hidden: int, c_out: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(c_in, hidden), nn.ReLU(inplace=True), nn.Linear(hidden, c_out))


class LightNet(nn.Module):
    """Encoder of five modules + pan / tilt / colour heads -> the 7-vector.

    Modules (spatial size for res 128):
      1. stem: conv 3x3 /2 + conv 3x3 + max pool /2          -> 32 x 32
      2. split inception + max pool /2                         -> 16 x 16
      3. split inception + max pool /2                         -> 8 x 8
      4. split inception + conv 1x1                            -> 8 x 8
      5. adaptive average pool to ``grid`` x ``grid``, flatten, linear -> ``embed``
    Heads: pan (2), tilt (2), colour (3, softplus + COLOUR_FLOOR).
    """

    def __init__(self, config: NetConfig | None = None):
        super().__init__()
        self.config = config = config or NetConfig()
        w = config.width
        self.stem = nn.Sequential(ConvBN(3, w, 3, stride=2), ConvBN(w, w, 3), nn.MaxPool2d(2))
        self.inc1 = SplitInception(w, w // 2 + w // 4)            # 4 * 24 = 96 for w = 32
        self.inc2 = SplitInception(self.inc1.out_channels, w)      # 128
        self.inc3 = SplitInception(self.inc2.out_channels, w + w // 2)  # 192
        self.reduce = ConvBN(self.inc3.out_channels, 2 * w, 1)    # 64
        self.pool = nn.MaxPool2d(2)
        self.grid = nn.AdaptiveAvgPool2d(config.grid)
        self.embed = nn.Sequential(nn.Linear(2 * w * config.grid ** 2, config.embed), nn.ReLU(inplace=True))
        self.pan_head = _head(config.embed, config.head_hidden, 2)
        self.tilt_head = _head(config.embed, config.head_hidden, 2)
        self.colour_head = _head(config.embed, config.head_hidden, 3)
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """He-normal (Kaiming, fan-in, ReLU gain) weights, zero biases, unit BN scale."""
        for m in self.modules():
            if isinstance(m, (nn.Conv2d, nn.Linear)):
                nn.init.kaiming_normal_(m.weight, mode="fan_in", nonlinearity="relu")
                if m.bias is not None:
                    nn.init.zeros_(m.bias)
            elif isinstance(m, nn.BatchNorm2d):
                nn.init.ones_(m.weight)
                nn.init.zeros_(m.bias)

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        """``(N, 3, H, W)`` -> embedding ``(N, embed)``."""
        if x.ndim != 4 or x.shape[1] != 3:
            raise ValueError(f"expected images of shape (N, 3, H, W), got {tuple(x.shape)}")
        x = self.stem(x)
        x = self.pool(self.inc1(x))
        x = self.pool(self.inc2(x))
        x = self.reduce(self.inc3(x))
        return self.embed(torch.flatten(self.grid(x), 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(N, 3, H, W)`` in [0, 1] -> ``(N, 7)`` = pan sin/cos, tilt sin/cos, rgb."""
        e = self.encode(x)
        rgb = F.softplus(self.colour_head(e)) + COLOUR_FLOOR
        return torch.cat([self.pan_head(e), self.tilt_head(e), rgb], dim=1)


def count_parameters(model: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


def flops_per_image(model: LightNet, res: int | None = None) -> int:
    """Forward FLOPs for one image (multiply-add = 2 FLOPs), by torch's flop counter."""
    from torch.utils.flop_counter import FlopCounterMode
    res = res or model.config.res
    was_training = model.training
    model.eval()
    try:
        with torch.no_grad(), FlopCounterMode(display=False) as counter:
            model(torch.zeros(1, 3, res, res))
    finally:
        model.train(was_training)
    return int(counter.get_total_flops())

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

Two encoders, chosen by :attr:`NetConfig.arch` and recorded in the model file:
``"small"`` (:data:`ARCH_NAME`, the one above) and ``"paper"``
(:data:`PAPER_ARCH_NAME`, :class:`PaperEncoder`: the paper's five modules at
Inception-v3 widths, several million parameters, most of them in the embedding so the
FLOPs stay CPU-sized).

Input: ``(N, 3, res, res)`` float32, 8-bit sRGB scaled to [0, 1] (see
:func:`relight.net.data.prepare_srgb8`). Output: ``(N, 7)``; the sin/cos pairs are raw
(not normalised; decoding uses atan2) and the colour is positive (softplus), any scale.
With :attr:`NetConfig.kappa_head` a fourth head gives the von Mises-Fisher
concentration ``kappa`` of the light direction (:meth:`LightNet.forward_with_kappa`;
see :mod:`relight.net.uncertainty`). It reads the embedding *detached*, so it learns
to predict the direction error without changing what the paper's terms train.
"""
from __future__ import annotations

__all__ = [
    "ARCH_NAME", "PAPER_ARCH_NAME", "ARCHES", "COLOUR_FLOOR", "KAPPA_INIT", "LOG_KAPPA_RANGE", "PAPER_SIZES",
    "NetConfig", "ConvBN", "SplitInception", "FactorisedInception7", "ExpandedInception", "GridReduction",
    "PaperEncoder", "LightNet", "MirrorAveraged", "head_kappa", "count_parameters", "flops_per_image",
    "camera_tilt_deg",
]

import math
from dataclasses import asdict, dataclass

import torch
from torch import nn
from torch.nn import functional as F

from relight.frames import check_target_frame
from relight.net.data import NET_SURROUNDS

ARCH_NAME = "sid2-inception-small/v1"
PAPER_ARCH_NAME = "sid2-inception-paper/v1"
ARCHES = {"small": ARCH_NAME, "paper": PAPER_ARCH_NAME}   # NetConfig.arch -> name in model files
COLOUR_FLOOR = 1e-4  # added to the softplus colour output so rgb is never exactly 0
KAPPA_INIT = 20.0      # kappa of a zero head output (90% cone of about 28 degrees)
LOG_KAPPA_RANGE = (math.log(1e-3), math.log(1e5))   # kappa clamped to [1e-3, 1e5]
PAPER_SIZES = {"embed": 1024, "head_hidden": 256}   # NetConfig.for_arch("paper") defaults


@dataclass(frozen=True)
class NetConfig:
    """Architecture settings (stored with the weights).

    Attributes:
        res: input width = height in pixels (default 128, the dataset's).
        width: base channel count; module widths scale with it.
        embed: embedding size shared by the three heads.
        head_hidden: hidden units in each head.
        grid: spatial size of the feature map flattened into the embedding.
        arch: encoder, a key of :data:`ARCHES` ("small" or "paper").
        kappa_head: predict the vMF concentration of the direction too.
        kappa_detach: the kappa head reads the embedding detached (its loss leaves the
            encoder to the paper's terms); False lets it shape the shared features.
        camera_head: predict the camera tilt too (sin, cos of tilt_c), so that a photograph
            needs no assumed camera tilt (:meth:`LightNet.forward_full`).
        ood_dims: principal components of the out-of-distribution detector
            (:mod:`relight.net.ood`; 0: none fitted).
        target_frame: what the 7 outputs mean, a name of :data:`relight.frames.TARGET_FRAMES`:
            ``"world"`` (the paper's y, decoded with the camera tilt) or ``"camera"`` (the
            light in the camera frame, the paper's encoding for a level camera); files
            written before it existed are ``"world"``. Decode through
            :func:`relight.net.evaluate.decode_outputs` (:func:`relight.frames.target_to_y`).
        surround: what the network sees around the objects, a name of :data:`relight.net.data.NET_SURROUNDS`
            (``"black"``: the objects alone, so every image it reads needs an object mask).
    """
    res: int = 128
    width: int = 32
    embed: int = 256
    head_hidden: int = 128
    grid: int = 4
    arch: str = "small"
    kappa_head: bool = True
    kappa_detach: bool = True
    camera_head: bool = False
    ood_dims: int = 0
    target_frame: str = "world"
    surround: str = "keep"

    def __post_init__(self):
        for name in ("res", "width", "embed", "head_hidden", "grid"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"NetConfig.{name} must be a positive integer, got {v!r}")
        if not isinstance(self.ood_dims, int) or isinstance(self.ood_dims, bool) or self.ood_dims < 0:
            raise ValueError(f"NetConfig.ood_dims must be an integer >= 0, got {self.ood_dims!r}")
        if self.res < 16:
            raise ValueError(f"NetConfig.res must be >= 16 pixels, got {self.res}")
        if self.arch not in ARCHES:
            raise ValueError(f"NetConfig.arch must be one of {', '.join(ARCHES)}, got {self.arch!r}")
        for name in ("kappa_head", "kappa_detach", "camera_head"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"NetConfig.{name} must be true or false, got {getattr(self, name)!r}")
        check_target_frame(self.target_frame)
        if self.surround not in NET_SURROUNDS:
            raise ValueError(f"NetConfig.surround must be one of {', '.join(NET_SURROUNDS)}, got {self.surround!r}")

    @classmethod
    def for_arch(cls, arch: str = "small", **kwargs) -> "NetConfig":
        """Config of a named architecture with its default sizes (``kwargs`` override)."""
        defaults = PAPER_SIZES if arch == "paper" else {}
        return cls(arch=arch, **(defaults | kwargs))

    @property
    def arch_name(self) -> str:
        """The architecture's name in model files, e.g. ``sid2-inception-small/v1``."""
        return ARCHES[self.arch]

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "NetConfig":
        """Config of a stored dict; files written before ``arch`` / ``kappa_head`` /
        ``target_frame`` existed are the small encoder without a kappa head, world frame."""
        known = {k: d[k] for k in cls.__dataclass_fields__ if k in d}
        known.setdefault("arch", "small")
        known.setdefault("kappa_head", False)
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


class FactorisedInception7(nn.Module):
    """Inception-v3 module of the middle grid ("B", 17 x 17 there): a 7 x 7 convolution
    factorised into 1 x 7 then 7 x 1.

    Branches: 1x1; 1x1 -> 1x7 -> 7x1; 1x1 -> (7x1 -> 1x7) twice; 3x3 average pool -> 1x1.
    Spatial size is kept; output channels = ``4 * c_branch``.
    """

    def __init__(self, c_in: int, c_branch: int, c_mid: int):
        super().__init__()
        self.b1 = ConvBN(c_in, c_branch, 1)
        self.b7 = nn.Sequential(ConvBN(c_in, c_mid, 1), ConvBN(c_mid, c_mid, (1, 7)),
                                ConvBN(c_mid, c_branch, (7, 1)))
        self.b77 = nn.Sequential(ConvBN(c_in, c_mid, 1), ConvBN(c_mid, c_mid, (7, 1)),
                                 ConvBN(c_mid, c_mid, (1, 7)), ConvBN(c_mid, c_mid, (7, 1)),
                                 ConvBN(c_mid, c_branch, (1, 7)))
        self.bp = ConvBN(c_in, c_branch, 1)
        self.out_channels = 4 * c_branch

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        pooled = F.avg_pool2d(x, 3, stride=1, padding=1, count_include_pad=False)
        return torch.cat([self.b1(x), self.b7(x), self.b77(x), self.bp(pooled)], dim=1)


class ExpandedInception(nn.Module):
    """Inception-v3 module of the coarsest grid ("C", 8 x 8 there): the expanded filter
    bank, 1 x 3 and 3 x 1 side by side instead of one after the other.

    Branches: 1x1 (c); 1x1 -> [1x3, 3x1] (2c); 1x1 -> 3x3 -> [1x3, 3x1] (2c); 3x3
    average pool -> 1x1 (c). Spatial size is kept; output channels = ``6 * c``.
    """

    def __init__(self, c_in: int, c: int, c_mid: int):
        super().__init__()
        self.b1 = ConvBN(c_in, c, 1)
        self.b3_in = ConvBN(c_in, c_mid, 1)
        self.b3_a, self.b3_b = ConvBN(c_mid, c, (1, 3)), ConvBN(c_mid, c, (3, 1))
        self.b33_in = nn.Sequential(ConvBN(c_in, c_mid, 1), ConvBN(c_mid, c_mid, 3))
        self.b33_a, self.b33_b = ConvBN(c_mid, c, (1, 3)), ConvBN(c_mid, c, (3, 1))
        self.bp = ConvBN(c_in, c, 1)
        self.out_channels = 6 * c

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        pooled = F.avg_pool2d(x, 3, stride=1, padding=1, count_include_pad=False)
        b3, b33 = self.b3_in(x), self.b33_in(x)
        return torch.cat([self.b1(x), self.b3_a(b3), self.b3_b(b3), self.b33_a(b33), self.b33_b(b33),
                          self.bp(pooled)], dim=1)


class GridReduction(nn.Module):
    """Inception-v3 grid-size reduction: a strided convolution (1x1 -> 3x3 / 2) and a
    3x3 / 2 max pool side by side, so the grid halves without a representational
    bottleneck. Output channels = ``c_in + c_out``.
    """

    def __init__(self, c_in: int, c_red: int, c_out: int):
        super().__init__()
        self.conv = nn.Sequential(ConvBN(c_in, c_red, 1), ConvBN(c_red, c_out, 3, stride=2))
        self.out_channels = c_in + c_out

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.cat([self.conv(x), F.max_pool2d(x, 3, stride=2, padding=1)], dim=1)


class PaperEncoder(nn.Module):
    """The paper's encoder at Inception-v3 proportions: five modules of inception,
    convolution and pooling layers (spatial size for res 128, ``w`` = width 32).

      1. stem: conv 3x3 /2 + conv 3x3 /2                           -> 32 x 32 x 2w
      2. max pool /2 + split inception (1x3, 3x1)                   -> 16 x 16 x 6w
      3. grid reduction + factorised inception (1x7, 7x1)           -> 8 x 8 x 12w
      4. grid reduction + expanded inception (1x3 beside 3x1)       -> 4 x 4 x 24w
      5. conv 1x1                                                   -> 4 x 4 x 8w
    The embedding (a linear layer on the flattened grid, in :class:`LightNet`) holds
    most of the parameters; the convolutions run on small grids, which keeps the
    FLOPs near the small encoder's.
    """

    def __init__(self, w: int = 32):
        super().__init__()
        self.stem = nn.Sequential(ConvBN(3, w, 3, stride=2), ConvBN(w, 2 * w, 3, stride=2))
        self.inc1 = SplitInception(2 * w, 3 * w // 2)                                   # 6w
        self.red1 = GridReduction(self.inc1.out_channels, 2 * w, 4 * w)                  # 10w
        self.inc2 = FactorisedInception7(self.red1.out_channels, 3 * w, 2 * w)          # 12w
        self.red2 = GridReduction(self.inc2.out_channels, 3 * w, 6 * w)                  # 18w
        self.inc3 = ExpandedInception(self.red2.out_channels, 4 * w, 4 * w)             # 24w
        self.reduce = ConvBN(self.inc3.out_channels, 8 * w, 1)
        self.out_channels = 8 * w

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.inc1(F.max_pool2d(self.stem(x), 2))
        x = self.inc2(self.red1(x))
        x = self.inc3(self.red2(x))
        return self.reduce(x)


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
        if config.arch == "small":
            self.stem = nn.Sequential(ConvBN(3, w, 3, stride=2), ConvBN(w, w, 3), nn.MaxPool2d(2))
            self.inc1 = SplitInception(w, w // 2 + w // 4)            # 4 * 24 = 96 for w = 32
            self.inc2 = SplitInception(self.inc1.out_channels, w)      # 128
            self.inc3 = SplitInception(self.inc2.out_channels, w + w // 2)  # 192
            self.reduce = ConvBN(self.inc3.out_channels, 2 * w, 1)    # 64
            self.pool = nn.MaxPool2d(2)
            c_features = 2 * w
        else:
            self.encoder = PaperEncoder(w)
            c_features = self.encoder.out_channels
        self.grid = nn.AdaptiveAvgPool2d(config.grid)
        self.embed = nn.Sequential(nn.Linear(c_features * config.grid ** 2, config.embed), nn.ReLU(inplace=True))
        self.pan_head = _head(config.embed, config.head_hidden, 2)
        self.tilt_head = _head(config.embed, config.head_hidden, 2)
        self.colour_head = _head(config.embed, config.head_hidden, 3)
        if config.kappa_head:
            self.kappa_head = _head(config.embed, config.head_hidden, 1)
            # temperature of the calibrated kappa (kappa / T), fitted on val: see
            # relight.net.uncertainty.fit_temperature; stored with the weights
            self.register_buffer("kappa_temperature", torch.ones(()))
        if config.camera_head:
            self.camera_head = _head(config.embed, config.head_hidden, 2)
        if config.ood_dims:   # the out-of-distribution detector's statistics (relight.net.ood.fit_ood)
            self.register_buffer("ood_mean", torch.zeros(config.embed))
            self.register_buffer("ood_basis", torch.zeros(config.ood_dims, config.embed))
            self.register_buffer("ood_scale", torch.ones(config.ood_dims))
            self.register_buffer("ood_residual", torch.ones(()))
            self.register_buffer("ood_threshold", torch.full((), 1e4))   # set by fit_ood
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
        if self.folded:   # the inference layout (fold_batchnorm)
            x = x.contiguous(memory_format=torch.channels_last)
        if self.config.arch == "small":
            x = self.stem(x)
            x = self.pool(self.inc1(x))
            x = self.pool(self.inc2(x))
            x = self.reduce(self.inc3(x))
        else:
            x = self.encoder(x)
        return self.embed(torch.flatten(self.grid(x), 1))

    def _light(self, e: torch.Tensor) -> torch.Tensor:
        rgb = F.softplus(self.colour_head(e)) + COLOUR_FLOOR
        return torch.cat([self.pan_head(e), self.tilt_head(e), rgb], dim=1)

    @property
    def has_kappa(self) -> bool:
        """True when the network predicts a direction concentration (kappa head)."""
        return self.config.kappa_head

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(N, 3, H, W)`` in [0, 1] -> ``(N, 7)`` = pan sin/cos, tilt sin/cos, rgb."""
        return self._light(self.encode(x))

    @property
    def has_camera(self) -> bool:
        """True when the network predicts the camera tilt (camera head)."""
        return self.config.camera_head

    def forward_full(self, x: torch.Tensor, calibrated: bool = True):
        """``(y (N, 7), kappa (N,) or None, camera (N, 2) or None)``: :meth:`forward_with_kappa`
        and, with a camera head, ``(sin tilt_c, cos tilt_c)`` of the predicted camera tilt
        (unnormalised; :func:`camera_tilt_deg` turns it into degrees)."""
        return self.heads(self.encode(x), calibrated)

    def heads(self, e: torch.Tensor, calibrated: bool = True):
        """:meth:`forward_full`'s outputs from embeddings ``e`` ``(N, embed)`` (:meth:`encode`),
        for a caller that also needs the embedding (the out-of-distribution flag)."""
        y = self._light(e)
        kappa = None
        if self.config.kappa_head:
            kappa = head_kappa(self.kappa_head, e.detach() if self.config.kappa_detach else e)
            if calibrated:
                kappa = kappa / self.kappa_temperature
        camera = self.camera_head(e) if self.config.camera_head else None
        return y, kappa, camera

    def forward_with_kappa(self, x: torch.Tensor, calibrated: bool = True):
        """``(y (N, 7), kappa (N,))``; kappa is the vMF concentration of the light
        direction (1 / steradian scale; ``None`` without a kappa head), divided by the
        fitted temperature when ``calibrated``. The kappa head reads the embedding
        detached (unless ``config.kappa_detach`` is False): its loss then does not
        reach the encoder or the other heads."""
        y, kappa, _ = self.forward_full(x, calibrated)
        return y, kappa


    @property
    def folded(self) -> bool:
        """True after :meth:`fold_batchnorm`: an inference-only network."""
        return getattr(self, "_folded", False)

    def fold_batchnorm(self) -> "LightNet":
        """Fold every batch norm into the convolution before it, in place, for inference.

        In eval mode a batch norm is an affine map per channel, so ``conv -> bn`` equals
        one convolution with scaled weights and a bias
        (:func:`torch.nn.utils.fusion.fuse_conv_bn_eval`); outputs agree to float32
        rounding. The weights and inputs then go channels-last (NHWC), the layout the
        CPU convolutions run fastest in. Together: single-image latency about 0.7x,
        batches of 64 about 0.5x (``benchmarks/bench_network.py --model sid2``). The
        folded network has no batch norms left, so it cannot be trained or saved
        (:func:`relight.net.io.save_model` refuses it): load the file again for that.
        Returns ``self``, in eval mode.
        """
        from torch.nn.utils.fusion import fuse_conv_bn_eval
        self.eval()
        for m in self.modules():
            if isinstance(m, ConvBN) and isinstance(m[1], nn.BatchNorm2d):
                m[0] = fuse_conv_bn_eval(m[0], m[1])
                m[1] = nn.Identity()
        self.to(memory_format=torch.channels_last)
        self._folded = True
        return self

    def train(self, mode: bool = True) -> "LightNet":
        if mode and self.folded:
            raise RuntimeError("a network with folded batch norms is for inference only; load the model file again to train it")
        return super().train(mode)


class MirrorAveraged(nn.Module):
    """Inference with a network and the left-right mirror image of each input.

    A mirrored scene is lit by the mirrored light (pan_rel -> 360 - pan_rel, the same
    tilt and colour: :func:`relight.net.data.flip_y`), so mapping the mirror image's
    prediction back gives a second estimate; this returns the mean of the two 7-vectors
    (then decoded as usual) and the mean of the two kappas. The result is exactly
    mirror-equivariant, and costs one batch of twice the size (about 1.8x the time of
    one image). ``config``, ``has_kappa`` and the train/eval mode are the network's.
    """

    def __init__(self, net: LightNet):
        super().__init__()
        self.net = net
        self.training = net.training   # the network's mode (a folded network stays in eval)

    @property
    def config(self) -> NetConfig:
        return self.net.config

    @property
    def has_kappa(self) -> bool:
        return self.net.has_kappa

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.forward_with_kappa(x)[0]

    @property
    def has_camera(self) -> bool:
        return self.net.has_camera

    def forward_full(self, x: torch.Tensor, calibrated: bool = True):
        """As :meth:`LightNet.forward_full`, each output the mean over the image and its
        mirror (the camera tilt is the same in both)."""
        from relight.net.data import flip_image, flip_y
        n = x.shape[0]
        y, kappa, camera = self.net.forward_full(torch.cat([x, flip_image(x)]), calibrated)
        y = (y[:n] + flip_y(y[n:])) / 2
        kappa = None if kappa is None else (kappa[:n] + kappa[n:]) / 2
        camera = None if camera is None else (camera[:n] + camera[n:]) / 2
        return y, kappa, camera

    def forward_with_kappa(self, x: torch.Tensor, calibrated: bool = True):
        y, kappa, _ = self.forward_full(x, calibrated)
        return y, kappa


def camera_tilt_deg(camera: torch.Tensor) -> torch.Tensor:
    """Camera tilt in degrees ``(N,)`` from a camera head's ``(N, 2)`` = (sin, cos) output."""
    return torch.rad2deg(torch.atan2(camera[:, 0], camera[:, 1]))


def head_kappa(head: nn.Module, e: torch.Tensor) -> torch.Tensor:
    """Uncalibrated kappa ``(N,)`` of a kappa head on embeddings ``e`` ``(N, embed)``:
    ``exp(head(e) + log KAPPA_INIT)``, clamped to [1e-3, 1e5] (:data:`LOG_KAPPA_RANGE`)."""
    log_kappa = head(e).squeeze(1) + math.log(KAPPA_INIT)
    return torch.exp(log_kappa.clamp(*LOG_KAPPA_RANGE))


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

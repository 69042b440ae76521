"""A learned chrome-sphere locator: where in an image a chrome sphere's centre likely is.

The hand-written detector (:mod:`relight.probe.detect`) proposes circles and scores them
by rules (edge support, a highlight's contrast and shape, the radius). Fitted to the 40
scenes of the harder probe set, its choice among the chrome-looking circles did not carry
to held-out scenes (a circle on another ball, on the wall, on the sphere's own reflection;
docs/probe-history.md, eleventh round). This small network is trained instead on generated probe
scenes, where the sphere's circle is known exactly at no cost, and gives the detector a
prior: its pick score gains :data:`relight.probe.detect.LOCATOR_WEIGHT` times the log of
the probability the network puts near each candidate's centre (:meth:`CentreMap.mass_near`).
It does not draw the outline: the rules' edge fit stays the measurement (the network's
centre is 1-2 px off, the edge fit's 0.2 px).

The network sees the image as 8-bit sRGB codes scaled so that its longer side is
:data:`SIZE` px and, for each cell of a :data:`STRIDE` px grid, says how likely the centre
lies there (a softmax over the grid: one chrome sphere per image), where in the cell, and
the log of the radius in cells. Trained on Mitsuba renders only (with a camera pipeline
drawn on half of them: exposure, noise, blur, tone curve), judged on Cycles renders and
photographs it never saw. The shipped weights (:data:`WEIGHTS`) are reproduced by
``bash scripts/train_locator.sh`` (docs/probe-history.md, twelfth round).
"""
from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass

import numpy as np

from relight.errors import ProbeError

__all__ = [
    "SIZE",
    "STRIDE",
    "WEIGHTS",
    "CentreMap",
    "build_net",
    "camera_pipeline",
    "codes",
    "judges",
    "load_locator",
    "load_weights",
    "save_weights",
    "locate",
    "network_input",
    "train",
]

SIZE = 256          # the network's input: the longer side scaled to this many pixels
STRIDE = 8          # one output cell per 8 x 8 input pixels
TRAINED_RADIUS_FRACTION = 0.15   # the training spheres' radii: at most this share of the image side ...
JUDGED_RADIUS_FRACTION = 1.1 * TRAINED_RADIUS_FRACTION   # ... so circles larger than this (10% over it)
                                 # it has no opinion on (a probe photograph's ball filling the frame)
RADIUS_MASS = 0.05   # where it puts at least 5% of its probability, a sphere's radius is at most
RADIUS_BOUND = 1.25  # 1.25 times the radius it gives there (on the 220 Cycles scenes of the probe
                     # sets, where it put that much at the true centre, the true radius was 0.79-1.45
                     # times its, median 1.01, 97.5th percentile 1.25; docs/probe-history.md, thirteenth round)
WEIGHTS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "models",
                       "probe_locator.safetensors")


def build_net(seed: int = 0):
    """The locator network (330 k weights): nine 3x3 convolutions (three of stride 2, the
    last three dilated 2, 4 and 8 to see a sphere's surroundings), then per cell a centre
    logit, the centre's offset in the cell (x, y) and the log radius in cells."""
    import torch
    from torch import nn

    def block(cin, cout, stride=1, dilation=1):
        return nn.Sequential(nn.Conv2d(cin, cout, 3, stride, dilation, dilation, bias=False),
                             nn.BatchNorm2d(cout), nn.ReLU(inplace=True))
    body = nn.Sequential(block(3, 24, 2), block(24, 32), block(32, 48, 2), block(48, 48), block(48, 64, 2),
                         block(64, 64), block(64, 96, dilation=2), block(96, 96, dilation=4),
                         block(96, 96, dilation=8))
    torch.manual_seed(seed)
    return nn.Sequential(body, nn.Conv2d(96, 4, 1))


def load_weights(net, path: str, name: str, script: str):
    """``net`` with the weights of a safetensors file, in evaluation mode; a one-line
    ProbeError naming ``name`` (and the ``script`` that trains it) when the file is missing,
    truncated or another network's. Shared by the probe's learned networks."""
    if not os.path.exists(path):
        raise ProbeError(f"no {name} weights at {path} (train them: bash {script})")
    from safetensors.torch import load_file
    try:
        net.load_state_dict(load_file(path))
    except Exception as exc:   # a truncated or foreign file: one line, not a traceback
        raise ProbeError(f"{path}: not the {name}'s weights ({type(exc).__name__})") from None
    return net.eval()


def save_weights(net, path: str, meta: dict) -> None:
    """``net``'s weights to a safetensors file with ``meta`` (strings) as its metadata,
    written whole or not at all (:func:`relight.fileio.atomic_write`). Shared by the
    scripts that train the probe's learned networks; :func:`load_weights` reads them."""
    from safetensors.torch import save_file

    from relight.fileio import atomic_write
    state = {k: v.contiguous() for k, v in net.state_dict().items()}
    atomic_write(path, lambda tmp: save_file(state, tmp, metadata={k: str(v) for k, v in meta.items()}))


@functools.lru_cache(maxsize=2)
def load_locator(path: str = WEIGHTS):
    """The trained network from a safetensors file (evaluation mode); ProbeError when the
    file is missing or unreadable."""
    return load_weights(build_net(), path, "sphere locator", "scripts/train_locator.sh")


def network_input(codes: np.ndarray) -> tuple[np.ndarray, tuple[float, float]]:
    """``(H, W, 3)`` 8-bit sRGB codes scaled to 0-1 -> the network's ``(3, h, w)`` float32
    input (the longer side :data:`SIZE`, both sides multiples of :data:`STRIDE`; area
    averaged, or each pixel repeated when enlarged, as the training images were) and the
    image pixels per input pixel across and down (they differ a little when a side is
    rounded to the grid)."""
    import cv2
    h, w = codes.shape[:2]
    scale = max(h, w) / SIZE
    nh = max(STRIDE, int(round(h / scale / STRIDE)) * STRIDE)
    nw = max(STRIDE, int(round(w / scale / STRIDE)) * STRIDE)
    how = cv2.INTER_NEAREST if nw > w else cv2.INTER_AREA
    small = cv2.resize(np.asarray(codes, np.float32), (nw, nh), interpolation=how)
    return np.ascontiguousarray(small.transpose(2, 0, 1)), (w / nw, h / nh)


@dataclass(frozen=True)
class CentreMap:
    """The locator's answer on one image: ``prob`` the probability that the chrome
    sphere's centre lies in each cell (sums to 1), ``centres`` ``(h, w, 2)`` where in the
    image each cell puts it, ``radii`` ``(h, w)`` the radius each cell gives it, ``circle``
    the most likely circle ``(cx, cy, r)``, in image pixels; ``seen`` the image as it saw
    it (:func:`codes`; the outline check looks at the same)."""
    prob: np.ndarray
    centres: np.ndarray
    radii: np.ndarray
    circle: tuple[float, float, float]
    seen: np.ndarray | None = None

    def _near(self, cx: float, cy: float, r: float) -> np.ndarray:
        d2 = (self.centres[..., 0] - cx) ** 2 + (self.centres[..., 1] - cy) ** 2
        s = max(r / 6.0, 1.0)
        return self.prob * np.exp(-d2 / (2.0 * s * s))

    def mass_near(self, cx: float, cy: float, r: float) -> float:
        """How much of the probability puts the centre at ``(cx, cy)``, for a sphere of radius
        ``r``: each cell's probability weighted by ``exp(-d^2 / 2 s^2)``, ``d`` the distance
        from its centre to ``(cx, cy)``, ``s`` a sixth of ``r`` (at least 1 px): 1 when all of
        it lies there, exp(-2) = 0.14 a third of the radius away (the benchmark's miss distance)."""
        return float(self._near(cx, cy, r).sum())

    def radius_near(self, cx: float, cy: float, r: float) -> tuple[float, float]:
        """The radius the locator gives a sphere centred at ``(cx, cy)`` (the geometric mean
        of the cells' radii, weighted as in :meth:`mass_near`, ``r`` the radius that sets the
        weighting) and that weighting's total, :meth:`mass_near` (the radius means little
        where the locator puts little probability)."""
        w = self._near(cx, cy, r)
        total = float(w.sum())
        if total <= 0.0:
            return float("nan"), 0.0
        return float(math.exp((w * np.log(self.radii)).sum() / total)), total

    def radius_bound(self, cx: float, cy: float, r: float, width: int, height: int) -> float | None:
        """The largest radius a chrome sphere centred at ``(cx, cy)`` likely has by the
        locator (:data:`RADIUS_BOUND` times :meth:`radius_near`), for a circle of radius ``r``
        it judges (:func:`judges`) and near which it puts at least :data:`RADIUS_MASS`;
        otherwise None (no opinion)."""
        if not judges(r, width, height):
            return None
        radius, mass = self.radius_near(cx, cy, r)
        return RADIUS_BOUND * radius if mass >= RADIUS_MASS else None


def judges(radius_px: float, width: int, height: int) -> bool:
    """Whether the locator can speak for a circle of this radius: no larger than
    :data:`JUDGED_RADIUS_FRACTION` of the image's longer side (it was trained on spheres
    up to :data:`TRAINED_RADIUS_FRACTION`; on psm_spheres' ball, 23% of the side, it puts
    its centre on small bright things instead)."""
    return radius_px <= JUDGED_RADIUS_FRACTION * max(width, height)


def codes(image: np.ndarray, clip_level: float | None) -> np.ndarray:
    """A linear ``(H, W, 3)`` image as the learned networks see it: 8-bit sRGB codes scaled
    to 0-1 (``clip_level`` None: a linear HDR image, exposed first as a camera would,
    :func:`relight.probe.detect.exposed_like_a_camera`)."""
    from relight.imageio import to_srgb8
    from relight.probe.detect import exposed_like_a_camera
    img = exposed_like_a_camera(image) if clip_level is None else np.asarray(image) / clip_level
    return to_srgb8(img) / 255.0


def locate(image: np.ndarray, clip_level: float | None, path: str = WEIGHTS) -> CentreMap:
    """Run the locator on a linear ``(H, W, 3)`` image (``clip_level`` None: a linear HDR
    image, exposed first as a camera would, :func:`relight.probe.detect.exposed_like_a_camera`)."""
    import torch
    seen = codes(image, clip_level)     # 8-bit codes, as it was trained on
    x, (sx, sy) = network_input(seen)
    net = load_locator(path)
    with torch.no_grad():
        out = net(torch.from_numpy(x[None])).numpy()[0].astype(np.float64)
    logit = out[0]
    prob = np.exp(logit - logit.max())
    prob /= prob.sum()
    gy, gx = np.mgrid[0:logit.shape[0], 0:logit.shape[1]]
    centres = np.stack([(gx + out[1]) * STRIDE * sx, (gy + out[2]) * STRIDE * sy], -1)
    y, x = np.unravel_index(int(np.argmax(logit)), logit.shape)
    radii = np.exp(out[3]) * STRIDE * sx
    circle = (centres[y, x, 0], centres[y, x, 1], radii[y, x])
    return CentreMap(prob, centres, radii, tuple(float(v) for v in circle), seen)


def camera_pipeline(linear: np.ndarray, rng: np.random.Generator, ranges) -> np.ndarray:
    """``(n, H, W, 3)`` linear renders -> ``(n, 3, H, W)`` 8-bit codes in 0-1 as a camera
    might have written them, one draw per image of (``ranges``: a
    :class:`relight.net.augment.PipelineAugment`, given by the caller, as the probe stage does
    not import the network stage; its defaults): an exposure of -2 to +2 stops,
    Poisson-Gaussian noise, a Gaussian blur of 0.05-1 px (one per batch), the sRGB curve or
    a gamma of 1.8-2.6.
    Vectorised: the per-image pipeline of :mod:`relight.net.augment` costs more than the
    network's step here."""
    import torch
    from torch.nn import functional as F

    from relight.colour import SRGB_LINEAR_KNEE
    n = len(linear)
    x = torch.from_numpy(np.ascontiguousarray(linear.transpose(0, 3, 1, 2))).float()
    x = x * torch.from_numpy(2.0 ** rng.uniform(*ranges.exposure_ev, (n, 1, 1, 1))).float()
    a = torch.from_numpy(np.exp(rng.uniform(math.log(ranges.photon_a[0]), math.log(ranges.photon_a[1]), (n, 1, 1, 1)))).float()
    b = torch.from_numpy(rng.uniform(*ranges.read_sigma, (n, 1, 1, 1)) ** 2).float()
    gen = torch.Generator().manual_seed(int(rng.integers(2 ** 31)))
    x = x.clamp(min=0) + torch.sqrt(a * x.clamp(min=0) + b) * torch.randn(x.shape, generator=gen)
    sigma = float(rng.uniform(max(ranges.blur_px[0], 0.05), ranges.blur_px[1]))
    t = torch.arange(-3, 4, dtype=torch.float32)
    k = torch.exp(-t ** 2 / (2 * sigma ** 2))
    k = (k / k.sum()).repeat(3, 1, 1, 1)
    x = F.conv2d(F.pad(x, (3, 3, 0, 0), mode="replicate"), k.reshape(3, 1, 1, 7), groups=3)
    x = F.conv2d(F.pad(x, (0, 0, 3, 3), mode="replicate"), k.reshape(3, 1, 7, 1), groups=3)
    x = x.clamp(0, 1)
    # relight.colour.srgb_encode, on tensors (it is numpy's)
    srgb = torch.where(x <= SRGB_LINEAR_KNEE, 12.92 * x, 1.055 * x.clamp(min=1e-8) ** (1 / 2.4) - 0.055)
    gamma = x ** (1.0 / torch.from_numpy(rng.uniform(*ranges.gamma, (n, 1, 1, 1))).float())
    y = torch.where(torch.from_numpy(rng.random((n, 1, 1, 1)) < 0.5), srgb, gamma)
    return (torch.round(y.clamp(0, 1) * 255) / 255).numpy()


def _targets(circles: np.ndarray, cells: int):
    """Cell index, in-cell offset (0-1) and log radius (in cells) of each circle (input px)."""
    gx = np.clip((circles[:, 0] / STRIDE).astype(int), 0, cells - 1)
    gy = np.clip((circles[:, 1] / STRIDE).astype(int), 0, cells - 1)
    off = np.stack([circles[:, 0] / STRIDE - gx, circles[:, 1] / STRIDE - gy], 1)
    return gy * cells + gx, off.astype(np.float32), np.log(circles[:, 2] / STRIDE).astype(np.float32)


def train(images: np.ndarray, circles: np.ndarray, epochs: int, linear: np.ndarray | None = None,
          augment_p: float = 0.0, ranges=None, seed: int = 0, batch: int = 32, progress=print):
    """Train the locator on ``(n, 3, S, S)`` 8-bit codes in 0-1 with their chrome circles
    ``(n, 3)`` in input pixels: cross-entropy of the centre's cell, L1 of its offset and log
    radius; AdamW, one-cycle rate 2e-3; left-right mirroring, an exposure gain of 0.6-1.4
    on the codes, and (with ``augment_p``) :func:`camera_pipeline` of ``ranges`` drawn on
    that share of the images from their ``linear`` renders ``(n, S, S, 3)``."""
    import torch
    from torch.nn import functional as F
    if augment_p > 0 and (linear is None or ranges is None):
        raise ValueError("augment_p > 0 needs the linear renders and the pipeline's ranges")
    net = build_net(seed)
    opt = torch.optim.AdamW(net.parameters(), 2e-3, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, 2e-3, total_steps=epochs * math.ceil(len(images) / batch))
    rng = np.random.default_rng(seed)
    size = images.shape[-1]
    cells = size // STRIDE
    for epoch in range(epochs):
        net.train()
        order = rng.permutation(len(images))
        total = 0.0
        for b in range(0, len(order), batch):
            sel = order[b:b + batch]
            x, c = images[sel].copy(), circles[sel].copy()
            if augment_p > 0:
                pick = rng.random(len(sel)) < augment_p
                if pick.any():
                    x[pick] = camera_pipeline(linear[sel[pick]], rng, ranges)
            flip = rng.random(len(sel)) < 0.5
            x[flip] = x[flip][..., ::-1]
            c[flip, 0] = size - c[flip, 0]
            x = np.clip(x * rng.uniform(0.6, 1.4, (len(sel), 1, 1, 1)), 0.0, 1.0).astype(np.float32)
            idx, off, logr = _targets(c, cells)
            out = net(torch.from_numpy(np.ascontiguousarray(x)))
            n = len(sel)
            rows = torch.arange(n)
            gy, gx = torch.from_numpy(idx // cells), torch.from_numpy(idx % cells)
            loss = (F.cross_entropy(out[:, 0].reshape(n, -1), torch.from_numpy(idx))
                    + F.l1_loss(out[rows, 1:3, gy, gx], torch.from_numpy(off))
                    + F.l1_loss(out[rows, 3, gy, gx], torch.from_numpy(logr)))
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach()) * n
        progress(f"epoch {epoch + 1}/{epochs}: loss {total / len(images):.3f}")
    return net.eval()

"""A learned reading of where a chrome sphere's outline lies, from the image across its rim.

A mirror's rim reflects what lies right behind it, so the image is nearly continuous across
the outline, and the edge the detector fits there (:func:`relight.probe.detect.outer_rim_fit`)
is the nearest change in what the mirror shows: a reflection's edge, some tenths of a pixel
inside the outline, more where the surroundings are even (a wall, the dark above a room).
The detector moves its fitted outline out by one shift for the whole rim
(:func:`relight.probe.detect.chrome_rim_shift_px`), so the arcs where the edge lies deeper
pull the circle: on the team-like Cycles renders its centre sat low by 0.02-0.08 px at the
median, and the circle alone put 1.2 deg into the light's direction (docs/probe-history.md,
twenty-fifth round).

This small network reads each of :data:`LINES` radial lines across the rim fit's outline:
the smoothed linear image (:func:`relight.probe.detect.edge_image`) sampled at
:data:`OFFSETS` px from it, each line scaled by its own mean and spread, and says how far
out the outline lies on that line. The outline is then fitted to those points with a
robust loss (:func:`read_outline`). It never sees where a line is around the sphere (no
"up"): only the profile. Trained on Mitsuba and Cycles renders of generated probe scenes
(the true outline known exactly), rim fits drawn a little off on purpose
(:data:`TRAIN_JITTER_PX`) so that it reads the outline's place from the profile rather than
learning one shift. The shipped weights (:data:`WEIGHTS`) are reproduced by
``bash scripts/train_rim.sh``.
"""
from __future__ import annotations

import functools
import math
import os

import numpy as np

__all__ = [
    "GUARD_PX",
    "LINES",
    "OFFSETS",
    "TRAIN_JITTER_PX",
    "WEIGHTS",
    "build_net",
    "features",
    "line_offsets",
    "load_rim",
    "profiles",
    "read_outline",
    "train",
]

OFFSETS = np.arange(-3.0, 3.0 + 1e-9, 0.25)   # each line's samples: px from the rim fit's outline (+ outside)
LINES = 360                                  # radial lines around the outline
GUARD_PX = 1.0           # a reading that moves the outline's centre or radius further than this from the
                         # shifted rim fit is not trusted (an image unlike any it was trained on)
TRAIN_JITTER_PX = 0.25   # training: the rim fit's centre moved by this (sigma, px; the radius by half)
WEIGHTS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "models",
                       "probe_rim.safetensors")


def profiles(smoothed: np.ndarray, camera, sphere) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The image across ``sphere``'s outline: ``(LINES, len(OFFSETS), C)`` samples of
    ``smoothed`` (:func:`relight.probe.detect.edge_image`) along radial lines from the
    outline's centre, at :data:`OFFSETS` px from the outline, and each line's outline point
    ``(LINES, 2)`` and outward unit direction ``(LINES, 2)``."""
    from relight.probe.detect import radial_samples
    samples, cx, cy, theta, r_theta = radial_samples(smoothed, camera, sphere, OFFSETS, LINES)
    u = np.stack([np.cos(theta), np.sin(theta)], 1)
    return samples, np.stack([cx + r_theta * u[:, 0], cy + r_theta * u[:, 1]], 1), u


def features(samples: np.ndarray) -> np.ndarray:
    """The network's input from profiles ``(..., len(OFFSETS), C)``: each line's samples less
    their mean and over their spread (so that a dark photograph's rim reads as a bright
    one's), then the log of that spread and of that mean: ``(..., len(OFFSETS) * C + 2)``
    float32."""
    p = np.asarray(samples, np.float32)
    mean = p.mean(axis=(-2, -1), keepdims=True)
    spread = p.std(axis=(-2, -1), keepdims=True) + 1e-3
    x = ((p - mean) / spread).reshape(*p.shape[:-2], -1)
    return np.concatenate([x, np.log(spread[..., 0, 0])[..., None], np.log(mean[..., 0, 0] + 1e-3)[..., None]],
                          -1).astype(np.float32)


def build_net(inputs: int = len(OFFSETS) * 3 + 2, seed: int = 0):
    """The network (about 18 k weights): two hidden layers of 128 and 64, to one number, how
    far out (px) the outline lies from where the line's samples are centred."""
    import torch
    from torch import nn
    torch.manual_seed(seed)
    return nn.Sequential(nn.Linear(inputs, 128), nn.ReLU(), nn.Linear(128, 64), nn.ReLU(), nn.Linear(64, 1))


@functools.lru_cache(maxsize=2)
def load_rim(path: str = WEIGHTS):
    """The trained network from a safetensors file (evaluation mode); ProbeError when the
    file is missing or unreadable."""
    from relight.probe.locator import load_weights
    return load_weights(build_net(), path, "rim reader", "scripts/train_rim.sh")


def line_offsets(smoothed: np.ndarray, camera, sphere, path: str = WEIGHTS) -> tuple[np.ndarray, np.ndarray]:
    """Where the outline lies on each radial line across ``sphere``'s: the outline points
    ``(LINES, 2)`` the network reads (pixels)."""
    import torch
    samples, points, u = profiles(smoothed, camera, sphere)
    with torch.no_grad():
        out = load_rim(path)(torch.from_numpy(features(samples)))[:, 0].numpy().astype(np.float64)
    return points + out[:, None] * u


def read_outline(smoothed: np.ndarray, camera, rim_fit, shifted, path: str = WEIGHTS):
    """A chrome sphere's outline read across its rim: ``(sphere, read)``. The outline points
    the network reads on each line across ``rim_fit``'s outline (the fit to the rim's edges,
    :func:`relight.probe.detect.outer_rim_fit`), fitted with a robust loss; ``shifted`` (that
    fit moved out by one shift, :func:`relight.probe.detect.outline_from_rim`) and False
    when that fit fails or ends further than :data:`GUARD_PX` from it."""
    from relight.errors import ProbeError
    from relight.probe.geometry import Sphere, fit_sphere, outline_circle
    points = line_offsets(smoothed, camera, rim_fit, path)
    try:
        read = fit_sphere(camera, points[:, 0], points[:, 1], robust=True)
    except ProbeError:
        return shifted, False
    a, b = outline_circle(camera, shifted), outline_circle(camera, read)
    if not (math.hypot(b[0] - a[0], b[1] - a[1]) <= GUARD_PX and abs(b[2] - a[2]) <= GUARD_PX):
        return shifted, False
    return Sphere(read.centre, read.radius, rim_fit.outline_rms_px, rim_fit.outline_points), True


def train(inputs: np.ndarray, targets: np.ndarray, epochs: int, seed: int = 0, batch: int = 512, progress=print):
    """Train on :func:`features` rows ``(n, k)`` and targets ``(n,)`` (px, how far out the
    true outline lies): smooth L1 (beta 0.1); AdamW, one-cycle rate 2e-3."""
    import torch
    from torch.nn import functional as F
    net = build_net(inputs.shape[1], seed)
    x, y = torch.from_numpy(np.ascontiguousarray(inputs, np.float32)), torch.from_numpy(np.asarray(targets, np.float32))
    opt = torch.optim.AdamW(net.parameters(), 2e-3, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, 2e-3, total_steps=epochs * math.ceil(len(x) / batch))
    gen = torch.Generator().manual_seed(seed)
    for epoch in range(epochs):
        net.train()
        order = torch.randperm(len(x), generator=gen)
        total = 0.0
        for b in range(0, len(order), batch):
            sel = order[b:b + batch]
            loss = F.smooth_l1_loss(net(x[sel])[:, 0], y[sel], beta=0.1)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach()) * len(sel)
        progress(f"epoch {epoch + 1}/{epochs}: loss {total / len(x):.4f}")
    return net.eval()

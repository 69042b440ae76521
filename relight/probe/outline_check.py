"""A learned check of a chrome sphere's outline: where, seen around a candidate circle, the
sphere's own outline lies.

The detector's edge fit (:mod:`relight.probe.detect`) measures an outline to a fraction of a
pixel, but which outline it settles on depends on where it starts: a sphere standing on a
floor has a contact shadow beside it whose edge, with the sphere's far side, draws a circle
20-30% larger and a few pixels off, as well supported by edges as the sphere's own (the
commonest wrong detection left after the thirteenth round, docs/probe-history.md). The learned
locator (:mod:`relight.probe.locator`) sees the whole image at 8 px a cell and cannot tell
the two apart. This network looks at one candidate: a window of :data:`WINDOW` radii around
it, resampled to :data:`SIZE` px, and says where the sphere's circle lies relative to it
(centre offset in radii, log radius ratio). The detector uses that as a second start for
its edge fit (:func:`relight.probe.detect.find_spheres`, ``outline_check``): the network
chooses the basin, the edges the measurement.

Trained on the Mitsuba renders the locator was trained on (candidate circles drawn around
the true one: up to :data:`TRAIN_MAX_OFFSET` radii off, :data:`TRAIN_RADIUS_RANGE` times its
radius), 8-bit as stored or through a camera pipeline; judged on Cycles renders and
photographs it never saw. The shipped weights (:data:`WEIGHTS`) are reproduced by
``bash scripts/train_outline_check.sh``.
"""
from __future__ import annotations

import functools
import math
import os

import numpy as np

__all__ = [
    "SIZE",
    "WEIGHTS",
    "WINDOW",
    "build_net",
    "check_circles",
    "crop",
    "judges",
    "load_check",
    "predict",
    "sample_candidates",
    "train",
]

SIZE = 64                 # the network's input: SIZE x SIZE px ...
WINDOW = 4.0              # ... showing a square WINDOW candidate radii across, centred on the candidate
TRAIN_MAX_OFFSET = 0.45   # training candidates: centre up to this many (true) radii off ...
TRAIN_RADIUS_RANGE = (0.7, 1.5)   # ... radius this many times the true one (log-uniform)
WEIGHTS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "models",
                       "probe_outline_check.safetensors")


def judges(radius_px: float, width: int, height: int) -> bool:
    """Whether the check can speak for a candidate of this radius: no larger than the
    largest it was trained on (:data:`TRAIN_RADIUS_RANGE`'s top times the locator's largest
    training sphere, :data:`relight.probe.locator.TRAINED_RADIUS_FRACTION` of the longer side)."""
    from relight.probe.locator import TRAINED_RADIUS_FRACTION
    return radius_px <= TRAIN_RADIUS_RANGE[1] * TRAINED_RADIUS_FRACTION * max(width, height)


def build_net(seed: int = 0):
    """The network (about 0.3 M weights): seven 3x3 convolutions, four of stride 2 (64 -> 4
    px), then two fully connected layers to the circle's offset ``(dx, dy)`` in candidate
    radii and ``log(r / candidate r)``."""
    import torch
    from torch import nn

    def block(cin, cout, stride=1):
        return nn.Sequential(nn.Conv2d(cin, cout, 3, stride, 1, bias=False), nn.BatchNorm2d(cout),
                             nn.ReLU(inplace=True))
    torch.manual_seed(seed)
    return nn.Sequential(block(3, 24, 2), block(24, 32), block(32, 48, 2), block(48, 48), block(48, 64, 2),
                         block(64, 64), block(64, 96, 2), nn.Flatten(), nn.Linear(96 * 16, 128),
                         nn.ReLU(inplace=True), nn.Linear(128, 3))


@functools.lru_cache(maxsize=2)
def load_check(path: str = WEIGHTS):
    """The trained network from a safetensors file (evaluation mode); ProbeError when the
    file is missing or unreadable."""
    from relight.probe.locator import load_weights
    return load_weights(build_net(), path, "outline check", "scripts/train_outline_check.sh")


def crop(image: np.ndarray, circle) -> np.ndarray:
    """The network's view of ``circle`` ``(cx, cy, r)`` (pixels, centres at +0.5) in an
    ``(H, W, C)`` image: ``(SIZE, SIZE, C)`` float32, a square :data:`WINDOW` radii across
    centred on the circle, bilinear, Gaussian-filtered first where it shrinks the image
    (sigma ``0.5 sqrt(s^2 - 1)`` for ``s`` image px per output px), edges replicated."""
    import cv2
    cx, cy, r = (float(v) for v in circle)
    s = WINDOW * r / SIZE
    half = 0.5 * WINDOW * r
    sigma = 0.5 * math.sqrt(max(s * s - 1.0, 0.0))
    pad = int(math.ceil(3 * sigma)) + 2
    h, w = image.shape[:2]
    x0, x1 = max(0, int(math.floor(cx - half)) - pad), min(w, int(math.ceil(cx + half)) + pad)
    y0, y1 = max(0, int(math.floor(cy - half)) - pad), min(h, int(math.ceil(cy + half)) + pad)
    if x1 - x0 < 2 or y1 - y0 < 2:
        x0, x1 = min(max(0, int(cx)), w - 2), min(max(0, int(cx)), w - 2) + 2
        y0, y1 = min(max(0, int(cy)), h - 2), min(max(0, int(cy)), h - 2) + 2
    sub = np.ascontiguousarray(image[y0:y1, x0:x1], np.float32)
    if sigma > 0.05:
        sub = cv2.GaussianBlur(sub, (0, 0), sigma, borderType=cv2.BORDER_REPLICATE)
    off = (0.5 - SIZE / 2) * s
    m = np.array([[s, 0.0, cx - 0.5 - x0 + off], [0.0, s, cy - 0.5 - y0 + off]], np.float64)
    out = cv2.warpAffine(sub, m, (SIZE, SIZE), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                         borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(SIZE, SIZE, -1)


def predict(codes: np.ndarray, circles, path: str = WEIGHTS) -> np.ndarray:
    """Where the network puts the chrome sphere's circle, seen from each of ``circles``
    ``(n, 3)``, in an image of 8-bit codes scaled to 0-1 ``(H, W, 3)``: ``(n, 3)`` circles."""
    import torch
    circles = np.asarray(circles, np.float64).reshape(-1, 3)
    if len(circles) == 0:
        return circles
    x = np.stack([crop(codes, c).transpose(2, 0, 1) for c in circles]).astype(np.float32)
    with torch.no_grad():
        out = load_check(path)(torch.from_numpy(x)).numpy().astype(np.float64)
    r = circles[:, 2]
    return np.stack([circles[:, 0] + out[:, 0] * r, circles[:, 1] + out[:, 1] * r, r * np.exp(out[:, 2])], 1)


def check_circles(codes: np.ndarray, circles, path: str = WEIGHTS) -> np.ndarray:
    """:func:`predict` for the circles the check can judge (:func:`judges`), each other one
    as it is (no opinion): the detector's ``outline_check``
    (:func:`relight.probe.detect.find_spheres`)."""
    circles = np.asarray(circles, np.float64).reshape(-1, 3)
    h, w = codes.shape[:2]
    judged = np.array([judges(r, w, h) for r in circles[:, 2]], bool)
    out = circles.copy()
    if judged.any():
        out[judged] = predict(codes, circles[judged], path)
    return out


def sample_candidates(truth, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``n`` training candidates around the true circle ``(cx, cy, r)`` (centre uniform in a
    disc of :data:`TRAIN_MAX_OFFSET` radii, radius log-uniform in :data:`TRAIN_RADIUS_RANGE`
    times the truth) and the network's targets for them ``(n, 3)``: the true centre's offset
    in candidate radii, ``log(true r / candidate r)``."""
    tx, ty, tr = (float(v) for v in truth)
    rho = TRAIN_MAX_OFFSET * tr * np.sqrt(rng.random(n))
    phi = rng.uniform(0, 2 * np.pi, n)
    r = tr * np.exp(rng.uniform(math.log(TRAIN_RADIUS_RANGE[0]), math.log(TRAIN_RADIUS_RANGE[1]), n))
    cands = np.stack([tx + rho * np.cos(phi), ty + rho * np.sin(phi), r], 1)
    targets = np.stack([(tx - cands[:, 0]) / r, (ty - cands[:, 1]) / r, np.log(tr / r)], 1)
    return cands, targets.astype(np.float32)


def train(crops: np.ndarray, targets: np.ndarray, epochs: int, seed: int = 0, batch: int = 64, progress=print):
    """Train on ``(n, 3, SIZE, SIZE)`` crops (8-bit codes in 0-1) and their targets ``(n, 3)``:
    smooth L1 (beta 0.02); AdamW, one-cycle rate 2e-3; left-right mirroring and an exposure
    gain of 0.6-1.4 on the codes."""
    import torch
    from torch.nn import functional as F
    net = build_net(seed)
    opt = torch.optim.AdamW(net.parameters(), 2e-3, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, 2e-3, total_steps=epochs * math.ceil(len(crops) / batch))
    rng = np.random.default_rng(seed)
    for epoch in range(epochs):
        net.train()
        order = rng.permutation(len(crops))
        total = 0.0
        for b in range(0, len(order), batch):
            sel = order[b:b + batch]
            x, t = crops[sel].astype(np.float32) / 255.0, targets[sel].copy()
            flip = rng.random(len(sel)) < 0.5
            x[flip] = x[flip][..., ::-1]
            t[flip, 0] = -t[flip, 0]
            x = np.clip(x * rng.uniform(0.6, 1.4, (len(sel), 1, 1, 1)), 0.0, 1.0).astype(np.float32)
            out = net(torch.from_numpy(np.ascontiguousarray(x)))
            loss = F.smooth_l1_loss(out, torch.from_numpy(t), beta=0.02)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach()) * len(sel)
        progress(f"epoch {epoch + 1}/{epochs}: loss {total / len(crops):.4f}")
    return net.eval()

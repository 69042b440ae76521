"""The paper's loss: ``a1 * MSE(pan sin/cos) + a2 * MSE(tilt sin/cos) + a3 * mean
angular error of the RGB colour``.

The colour term is the recovery angular error of colour constancy, in **radians**
(so with the default weights 1, 1, 1 a 1 degree colour error weighs 0.0175, about the
MSE of a 7.6 degree pan error on one sin/cos pair). It is scale invariant and
numerically safe: the cosine is clamped to ``[-1 + COS_CLAMP, 1 - COS_CLAMP]`` so
``acos`` never sees +-1, and its gradient stays finite (zero) when the prediction
equals the target.

Beside the paper's terms, a fourth (weight ``kappa``) trains the network's direction
concentration: the von Mises-Fisher negative log-likelihood of the true direction
around the predicted one (:func:`relight.net.uncertainty.direction_nll`). It sees
the predicted direction and the embedding detached, so it leaves what the paper's
three terms train unchanged; ``total`` stays the paper's loss and ``objective``
(what training minimises) adds the NLL.
"""
from __future__ import annotations

__all__ = [
    "COS_CLAMP", "NORM_EPS", "angular_error_rad", "LossWeights", "light_loss", "LightLoss",
]

from dataclasses import dataclass

import torch
from torch import nn

COS_CLAMP = 1e-6   # keeps acos away from its infinite slope at +-1 (float32 safe)
NORM_EPS = 1e-12   # guards the division by |pred| |target|


def angular_error_rad(pred_rgb: torch.Tensor, true_rgb: torch.Tensor) -> torch.Tensor:
    """Angle between RGB vectors, radians, shape ``(N,)``; inputs ``(N, 3)``, any scale.

    Uses ``acos`` of the clamped cosine: exact away from 0 / pi (for float32 it
    bottoms out at about ``sqrt(2 * COS_CLAMP)`` = 0.08 degrees, far below the
    errors we report, which use :func:`relight.metrics.colour_error_deg`).
    """
    dot = (pred_rgb * true_rgb).sum(dim=-1)
    norms = pred_rgb.norm(dim=-1) * true_rgb.norm(dim=-1)
    cos = dot / norms.clamp_min(NORM_EPS)
    return torch.acos(cos.clamp(-1.0 + COS_CLAMP, 1.0 - COS_CLAMP))


@dataclass(frozen=True)
class LossWeights:
    """alpha_1 (pan), alpha_2 (tilt), alpha_3 (colour, per radian) of the paper's loss,
    and the weight of the direction vMF NLL (``kappa``; 0 trains no kappa head)."""
    pan: float = 1.0
    tilt: float = 1.0
    colour: float = 1.0
    kappa: float = 1.0

    def __post_init__(self):
        for name in ("pan", "tilt", "colour", "kappa"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and v >= 0 and v == v and v != float("inf")):
                raise ValueError(f"LossWeights.{name} must be a finite number >= 0, got {v!r}")


def light_loss(pred: torch.Tensor, target: torch.Tensor, weights: LossWeights = LossWeights(),
               parts: bool = False, kappa: torch.Tensor | None = None,
               camera_tilt_deg: torch.Tensor | None = None):
    """The paper's loss on ``(N, 7)`` predictions and targets (the 7-vector).

    Returns the scalar loss, or with ``parts=True`` a dict with ``total``, ``pan``
    (MSE over y0, y1), ``tilt`` (MSE over y2, y3) and ``colour`` (mean angular error,
    radians), plus ``objective``: ``total`` + ``weights.kappa`` x ``kappa_nll`` when
    ``kappa`` (``(N,)``) and ``camera_tilt_deg`` (``(N,)``, degrees: the tilt the targets decode
    with, :meth:`relight.net.data.LightDataset.target_tilts`) are given, else
    ``total`` (``kappa_nll`` is then None).
    """
    if pred.shape != target.shape or pred.ndim != 2 or pred.shape[1] != 7:
        raise ValueError(f"expected pred and target of shape (N, 7), got {tuple(pred.shape)} "
                         f"and {tuple(target.shape)}")
    pan = torch.mean((pred[:, 0:2] - target[:, 0:2]) ** 2)
    tilt = torch.mean((pred[:, 2:4] - target[:, 2:4]) ** 2)
    colour = angular_error_rad(pred[:, 4:7], target[:, 4:7]).mean()
    total = weights.pan * pan + weights.tilt * tilt + weights.colour * colour
    if parts:
        nll, objective = None, total
        if kappa is not None and weights.kappa > 0:
            from relight.net.uncertainty import direction_nll
            if camera_tilt_deg is None:
                raise ValueError("the kappa term needs the camera tilts of the images")
            nll = direction_nll(pred, target, kappa, camera_tilt_deg)
            objective = total + weights.kappa * nll
        return {"total": total, "pan": pan, "tilt": tilt, "colour": colour, "kappa_nll": nll,
                "objective": objective}
    return total


class LightLoss(nn.Module):
    """``nn.Module`` wrapper of :func:`light_loss`."""

    def __init__(self, weights: LossWeights = LossWeights()):
        super().__init__()
        self.weights = weights

    def forward(self, pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        return light_loss(pred, target, self.weights)

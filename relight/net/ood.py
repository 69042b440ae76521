"""Out-of-distribution flag: is an image unlike the renders the network learnt from?

A calibrated cone is only calibrated on images like the ones it was calibrated on; on a
photograph unlike any training render the network can be confidently wrong. The flag is
the feature-space Mahalanobis distance of the image's embedding (Lee, Lee, Lee & Shin,
"A Simple Unified Framework for Detecting Out-of-Distribution Samples and Adversarial
Attacks", NeurIPS 2018), taken in the embedding's top ``ood_dims`` principal components
(the rest is noise on a few thousand held-out images) plus the energy outside them:

    z = B (e - mu) / s          (B: top principal directions, s: their standard deviations)
    score = sqrt(mean(z ** 2) + r / r_ref)   r = |e - mu|^2 - |B (e - mu)|^2 (the residual)

fitted on a held-out split of renders (``relight calibrate --ood``). An image whose score
exceeds :data:`OOD_QUANTILE` of the held-out scores is ``ood: true``: its direction and
colour are not to be trusted, and its 90% cone is widened to the whole sphere
(``cone90_deg`` 180), so that a user never gets a narrow cone on such an image.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import torch

from relight.errors import DatasetError

OOD_DIMS = 32          # principal components of the embedding kept
OOD_QUANTILE = 0.99    # held-out renders above the threshold: 1%
OOD_CONE_DEG = 180.0   # the cone of an out-of-distribution image: no direction excluded

__all__ = ["OOD_DIMS", "OOD_QUANTILE", "OOD_CONE_DEG", "embeddings", "ood_scores", "fit_ood", "ood_fields"]


def _net(model):
    return getattr(model, "net", model)   # MirrorAveraged wraps a LightNet


def embeddings(model, x: torch.Tensor, batch_size: int = 64) -> torch.Tensor:
    """Embeddings ``(N, embed)`` of network inputs ``x`` ``(N, 3, H, W)`` (eval mode, no grad)."""
    net = _net(model)
    was_training = net.training
    net.eval()
    try:
        with torch.no_grad():
            out = [net.encode(x[s:s + batch_size]) for s in range(0, len(x), batch_size)]
    finally:
        net.train(was_training)
    return torch.cat(out) if out else torch.zeros((0, net.config.embed))


def _scores(net, e: torch.Tensor) -> np.ndarray:
    d = e.double() - net.ood_mean.double()
    proj = d @ net.ood_basis.double().T
    z = proj / net.ood_scale.double()
    residual = (d ** 2).sum(1) - (proj ** 2).sum(1)
    return torch.sqrt((z ** 2).mean(1) + residual.clamp(min=0) / net.ood_residual.double()).numpy()


def ood_scores(model, x: torch.Tensor | None, embedding: torch.Tensor | None = None) -> np.ndarray | None:
    """OOD score of each input ``(N,)`` (None for a model without a fitted detector);
    ``embedding``: the inputs' embeddings when the caller has them (``x`` is then not read)."""
    net = _net(model)
    if not getattr(net.config, "ood_dims", 0):
        return None
    return _scores(net, embedding if embedding is not None else embeddings(net, x))


def fit_ood(model, x: torch.Tensor, dims: int = OOD_DIMS, quantile: float = OOD_QUANTILE):
    """A copy of ``model`` (a :class:`~relight.net.model.LightNet`, not folded) with the
    detector fitted on held-out renders ``x`` ``(N, 3, H, W)``: mean, top ``dims``
    principal directions and scales, residual reference, and the ``quantile`` threshold.
    Returns ``(model, summary)``."""
    from relight.net.model import LightNet
    net = _net(model)
    e = embeddings(net, x).double()
    n, width = e.shape
    dims = int(min(dims, width, max(n - 1, 1)))
    if n < 2 * dims + 2:
        raise DatasetError(f"fitting the OOD detector needs at least {2 * dims + 2} images, got {n}")
    mu = e.mean(0)
    d = e - mu
    _, sv, vt = torch.linalg.svd(d, full_matrices=False)
    basis = vt[:dims]
    scale = (sv[:dims] / np.sqrt(n - 1)).clamp(min=1e-12)
    proj = d @ basis.T
    residual = ((d ** 2).sum(1) - (proj ** 2).sum(1)).clamp(min=0)
    grown = LightNet(dataclasses.replace(net.config, ood_dims=dims))
    state = {k: v for k, v in net.state_dict().items() if not k.startswith("ood_")}
    grown.load_state_dict(state, strict=False)
    grown.ood_mean.copy_(mu.float())
    grown.ood_basis.copy_(basis.float())
    grown.ood_scale.copy_(scale.float())
    grown.ood_residual.fill_(float(residual.mean().clamp(min=1e-12)))
    scores = _scores(grown, e.float())
    threshold = float(np.quantile(scores, quantile))
    grown.ood_threshold.fill_(threshold)
    if hasattr(net, "info"):
        grown.info = net.info
    return grown.eval(), {"ood_dims": dims, "ood_threshold": threshold, "n": n, "quantile": quantile}


def ood_fields(model, x: torch.Tensor | None, embedding: torch.Tensor | None = None) -> list[dict] | None:
    """Per input: ``ood`` (bool), ``ood_score``; for a flagged image also ``cone90_deg`` =
    :data:`OOD_CONE_DEG`. None for a model without a fitted detector. ``embedding``: the
    inputs' embeddings when the caller has them (no second pass through the encoder)."""
    scores = ood_scores(model, x, embedding)
    if scores is None:
        return None
    threshold = float(_net(model).ood_threshold)
    out = []
    for s in scores:
        flag = bool(s > threshold)
        out.append({"ood": flag, "ood_score": round(float(s), 4), **({"cone90_deg": OOD_CONE_DEG} if flag else {})})
    return out

"""Fitting the direction-confidence (kappa) head on held-out images, network frozen.

During training the kappa head learns from the *training* split, where the network's
direction errors are smaller than on unseen images and differently distributed: its
kappa ranks images poorly on new data, and temperature scaling
(:func:`relight.net.uncertainty.fit_temperature`) only rescales it. Here the encoder and
the pan/tilt/colour heads stay fixed and only the kappa head is fitted again, by
minimising the mean von Mises-Fisher negative log-likelihood
(:func:`relight.net.uncertainty.vmf_nll`) of the direction errors on a held-out split
(``val`` by default; never the test split one reports on).

Procedure (:func:`calibrate_kappa`):
    1. Embeddings and outputs of every image of the split (and of its mirror image,
       ``flip``: another held-out error of the same network; pan_rel -> 360 - pan_rel).
    2. The images are divided by a seeded permutation into a *fit* part and a *check*
       part (``check_fraction``); both copies of an image go to the same part.
    3. The head, starting from its trained weights, is fitted with full-batch Adam (weight
       decay) on the fit part; the weights with the lowest check-part NLL are kept
       (early stopping after ``patience`` steps without improvement).
    4. A temperature is fitted on the check part (:func:`fit_temperature`), so the
       stored kappa is calibrated on images the head was not fitted to. Should the
       refitted head still do worse there than the model as it came, the trained head
       is kept (with its own fitted temperature): calibration never raises the check
       part's NLL.
    5. ``mode="last"`` fits only the head's last linear layer (its hidden features
       stay those learnt in training: fewer parameters for a small split);
       ``mode="temperature"`` skips 3: the training-time calibration, for comparison.

The report holds the check part's figures before (the model as it came, with its
stored temperature) and after: mean NLL, 90% cone coverage and the Spearman rank
correlation between cone radius and direction error; ``kept`` says which head the
model now has (``head``/``last``: the refitted one; ``temperature``: the trained one).
"""
from __future__ import annotations

__all__ = [
    "MODES", "MIN_IMAGES", "CalibrationConfig", "held_out_outputs", "fit_head", "calibrate_kappa",
    "calibrate_model_file",
]

import copy
import math
import os
from dataclasses import asdict, dataclass

import numpy as np
import torch

from relight.errors import DatasetError, TrainingError
from relight.net.data import LightDataset, dataset_folders, flip_image, flip_y, folders_record, model_dataset
from relight.net.model import head_kappa
from relight.net.uncertainty import direction_from_y, fit_temperature, uncertainty_summary, vmf_nll

MODES = ("head", "last", "temperature", "none")   # none: the kappa head as it is (with ood=True)
MIN_IMAGES = 10   # fewer held-out images than this cannot calibrate anything


@dataclass(frozen=True)
class CalibrationConfig:
    """Settings of :func:`calibrate_kappa`.

    Attributes:
        split: the held-out split of the dataset (``val``; ``all`` for a dataset made
            for calibration alone).
        mode: ``"head"`` (refit the kappa head, then a temperature), ``"last"`` (refit
            its last linear layer only) or ``"temperature"`` (temperature only).
        check_fraction: share of the images held out of the head fit, in (0, 1):
            early stopping and the temperature are decided on them.
        flip: add each image's mirror image (its own prediction and error).
        lr, weight_decay: Adam on the head's parameters.
        max_steps, patience: full-batch steps at most; stop after ``patience`` steps
            without a lower check NLL.
        seed: the fit/check division.
        batch_size: images per forward pass of the frozen network.
        ood: also fit the out-of-distribution detector (:mod:`relight.net.ood`) on the
            split's images (:func:`calibrate_model_file`).
    """
    split: str = "val"
    mode: str = "head"
    check_fraction: float = 0.3
    flip: bool = True
    lr: float = 1e-4
    weight_decay: float = 1e-2
    max_steps: int = 3000
    patience: int = 200
    seed: int = 0
    batch_size: int = 64
    ood: bool = False

    def __post_init__(self):
        if self.mode not in MODES:
            raise TrainingError(f"calibration mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        if not 0.0 < self.check_fraction < 1.0:
            raise TrainingError(f"check_fraction must be in (0, 1), got {self.check_fraction!r}")
        if not (0.0 < self.lr < 1.0 and 0.0 <= self.weight_decay < math.inf):
            raise TrainingError("lr must be in (0, 1) and weight_decay >= 0")
        for name in ("max_steps", "patience", "batch_size"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < 1:
                raise TrainingError(f"{name} must be a positive integer, got {v!r}")


def held_out_outputs(model, dataset: LightDataset, flip: bool = True, batch_size: int = 64,
                     progress: bool = False) -> dict:
    """The frozen network on every image of ``dataset`` (and its mirror image with
    ``flip``): ``{"embedding" (M, embed), "y_pred" (M, 7), "y_true" (M, 7) (in the dataset's
    target frame), "target_tilt_deg" (M,) (the camera tilt they decode with:
    :meth:`LightDataset.target_tilts`), "image" (M,) index of the source image}`` (torch, float32),
    M = N or 2N; ``progress`` shows a bar. The model's train/eval mode is restored."""
    from tqdm import tqdm
    was_training = model.training
    model.eval()
    emb, ys = [], []
    targets = np.stack([dataset.target(i) for i in range(len(dataset))]) if len(dataset) else np.zeros((0, 7))
    cams = dataset.target_tilts(range(len(dataset)))
    views = [False, True] if flip else [False]
    batches = [(m, start) for m in views for start in range(0, len(dataset), batch_size)]
    try:
        with torch.no_grad():
            for mirrored, start in tqdm(batches, desc="held-out images", unit="batch", disable=not progress,
                                        leave=False, dynamic_ncols=True):
                idx = range(start, min(start + batch_size, len(dataset)))
                x = dataset.batch(idx)
                e = model.encode(flip_image(x) if mirrored else x)
                emb.append(e)
                ys.append(model._light(e))
    finally:
        model.train(was_training)
    y_true = torch.from_numpy(np.concatenate([flip_y(targets) if m else targets for m in views])).float()
    n = len(dataset)
    return {"embedding": torch.cat(emb) if emb else torch.zeros((0, model.config.embed)),
            "y_pred": torch.cat(ys) if ys else torch.zeros((0, 7)), "y_true": y_true,
            "target_tilt_deg": torch.from_numpy(np.tile(cams, len(views))).float(),
            "image": torch.from_numpy(np.tile(np.arange(n), len(views)))}


def _cos_error(out: dict) -> torch.Tensor:
    mu = direction_from_y(out["y_pred"], out["target_tilt_deg"])
    x = direction_from_y(out["y_true"], out["target_tilt_deg"])
    return (mu * x).sum(dim=1).clamp(-1.0, 1.0)


def _subset(out: dict, mask: torch.Tensor) -> dict:
    return {k: v[mask] for k, v in out.items()}


def _summary(kappa: np.ndarray, angle_deg: np.ndarray) -> dict:
    s = uncertainty_summary(kappa, angle_deg)
    return {k: s[k] for k in ("n", "nll_mean", "cone90_coverage", "cone90_mean_deg", "spearman_cone90_error")}


def fit_head(head: torch.nn.Module, fit: dict, check: dict, cfg: CalibrationConfig) -> tuple[int, list[float]]:
    """Fit ``head`` in place (full-batch Adam on the vMF NLL of ``fit``, the weights of the
    lowest NLL on ``check`` kept). Returns ``(best step, check NLL per step)``."""
    torch.manual_seed(cfg.seed)
    cos_fit, cos_check = _cos_error(fit), _cos_error(check)
    e_fit, e_check = fit["embedding"], check["embedding"]
    params = [p for p in head.parameters() if p.requires_grad]
    opt = torch.optim.Adam(params, lr=cfg.lr, weight_decay=cfg.weight_decay)

    def check_nll() -> float:
        with torch.no_grad():
            return float(vmf_nll(head_kappa(head, e_check), cos_check).mean())
    best_state, best, best_step, curve = copy.deepcopy(head.state_dict()), check_nll(), 0, []
    curve.append(best)
    for step in range(1, cfg.max_steps + 1):
        loss = vmf_nll(head_kappa(head, e_fit), cos_fit).mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        now = check_nll()
        curve.append(now)
        if now < best:
            best, best_step, best_state = now, step, copy.deepcopy(head.state_dict())
        elif step - best_step >= cfg.patience:
            break
    head.load_state_dict(best_state)
    return best_step, curve


def calibrate_kappa(model, data_dir, cfg: CalibrationConfig = CalibrationConfig(),
                    progress: bool = False) -> dict:
    """Calibrate ``model``'s direction confidence on the held-out ``cfg.split`` of
    ``data_dir`` (a dataset folder, or a sequence of folders whose splits are joined, as
    for a model trained on several); see the module docstring. ``model`` is changed in
    place (kappa head weights and ``kappa_temperature``). Returns the report (dict,
    JSON-ready; ``data_dir`` is one absolute path, or a list of them)."""
    if not getattr(model, "has_kappa", False):
        raise TrainingError("the model has no kappa head (trained with --kappa-weight 0): nothing to calibrate")
    folders = dataset_folders(data_dir)
    dataset = model_dataset(model, folders, cfg.split, cache=False, target_frame=model.config.target_frame)
    if len(dataset) < MIN_IMAGES:
        raise DatasetError(f"{', '.join(folders)}: split {cfg.split!r} holds {len(dataset)} images; calibration needs "
                           f"at least {MIN_IMAGES}")
    for p in model.parameters():
        p.requires_grad_(False)
    out = held_out_outputs(model, dataset, cfg.flip, cfg.batch_size, progress=progress)
    g = torch.Generator().manual_seed(cfg.seed)
    order = torch.randperm(len(dataset), generator=g)
    n_check = max(1, min(len(dataset) - 1, round(cfg.check_fraction * len(dataset))))
    is_check_image = torch.zeros(len(dataset), dtype=torch.bool)
    is_check_image[order[:n_check]] = True
    in_check = is_check_image[out["image"]]
    fit, check = _subset(out, ~in_check), _subset(out, in_check)
    angle_check = np.degrees(np.arccos(_cos_error(check).double().numpy()))
    head = model.kappa_head
    old_temperature = float(model.kappa_temperature)
    with torch.no_grad():
        before = _summary((head_kappa(head, check["embedding"]) / old_temperature).double().numpy(), angle_check)
    best_step, curve, trained_head = 0, [], copy.deepcopy(head.state_dict())
    if cfg.mode in ("head", "last"):
        head.train()
        for p in (head if cfg.mode == "head" else head[-1]).parameters():
            p.requires_grad_(True)
        best_step, curve = fit_head(head, fit, check, cfg)
        for p in head.parameters():
            p.requires_grad_(False)

    def with_temperature():
        with torch.no_grad():
            raw = head_kappa(head, check["embedding"]).double().numpy()
        t = fit_temperature(raw, angle_check)
        return t, _summary(raw / t, angle_check)
    temperature, after = with_temperature()
    kept = cfg.mode
    if cfg.mode != "temperature" and not after["nll_mean"] <= before["nll_mean"]:
        head.load_state_dict(trained_head)   # the refit did not generalise to the check part
        temperature, after = with_temperature()
        kept = "temperature"
    model.kappa_temperature.fill_(temperature)
    for p in model.parameters():
        p.requires_grad_(True)
    model.eval()
    return {"data_dir": folders_record(folders), "split": cfg.split, "n_images": len(dataset),
            "n_fit": int((~in_check).sum()), "n_check": int(in_check.sum()), "settings": asdict(cfg),
            "kept": kept, "best_step": best_step, "steps": max(0, len(curve) - 1), "temperature": temperature,
            "temperature_before": old_temperature, "check_before": before, "check_after": after}


def calibrate_model_file(model_path: str | os.PathLike, data_dir, out_path: str | os.PathLike,
                         cfg: CalibrationConfig = CalibrationConfig(), progress: bool = False) -> dict:
    """Load a model file (or run folder), :func:`calibrate_kappa` it, and write the result
    to ``out_path`` (a model file; its ``info`` gains ``kappa_calibration``, the report).
    Returns the report."""
    from relight.net.io import load_model_file, save_model
    model = load_model_file(model_path)
    info = dict(getattr(model, "info", {}) or {})
    if cfg.mode == "none":   # only the out-of-distribution detector; kappa as it came
        if not cfg.ood:
            raise TrainingError("calibration mode none changes nothing: add --ood")
        report = {"data_dir": folders_record(dataset_folders(data_dir)), "split": cfg.split, "mode": "none"}
    else:
        report = calibrate_kappa(model, data_dir, cfg, progress=progress)
        info["kappa_temperature"] = report["temperature"]
        info["kappa_calibration"] = report | {"model": os.path.abspath(os.fspath(model_path))}
    if cfg.ood:
        from relight.net.ood import fit_ood
        dataset = model_dataset(model, dataset_folders(data_dir), cfg.split, cache=False)
        model, report["ood"] = fit_ood(model, dataset.batch(range(len(dataset))))
        info["ood"] = report["ood"] | {"data_dir": folders_record(dataset_folders(data_dir)), "split": cfg.split}
    from relight.net.io import stored_float_dtype
    save_model(out_path, model, info, dtype=stored_float_dtype(model_path))   # the precision it came in
    return report

"""Evaluation of a model on a dataset split: the paper's Tables 1-3 (degrees), colour
constancy statistics, a per-image CSV and a ``relight.predictions/v1`` file.

Report folder contents:
    report.md          Tables 1-3 (mean, median) + trimean / best 25% / worst 25%
    metrics.json       the same numbers, machine-readable (relight.metrics.error_tables)
    per_image.csv      id, truth, prediction and the four errors of every image
    predictions.json   relight.predictions/v1 (pan_deg = predicted pan_rel, tilt_deg,
                       rgb unit norm, and the raw y), the input of ``relight compare``
"""
from __future__ import annotations

import csv
import json
import os

import numpy as np
import torch

from relight import frames, metrics
from relight.dataset import DatasetError
from relight.net.data import LightDataset

COLOUR_STATS = ("mean", "median", "trimean", "best25", "worst25")


def run_model(model, dataset: LightDataset, batch_size: int = 64) -> np.ndarray:
    """Raw network outputs ``(N, 7)`` float64 for every item of ``dataset`` (eval mode,
    no augmentation); the model's train/eval mode is restored afterwards."""
    was_training = model.training
    model.eval()
    out = []
    try:
        with torch.no_grad():
            for start in range(0, len(dataset), batch_size):
                idx = range(start, min(start + batch_size, len(dataset)))
                x = torch.stack([torch.from_numpy(dataset.image_srgb8(i).transpose(2, 0, 1).astype(np.float32)
                                                  / 255.0) for i in idx])
                out.append(model(x).double().numpy())
    finally:
        model.train(was_training)
    return np.concatenate(out) if out else np.zeros((0, 7))


def decode_outputs(y_pred: np.ndarray, camera_tilt_deg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(pan_rel_deg, tilt_deg, rgb unit norm)`` of raw outputs ``(N, 7)`` for cameras
    at pan 0 and tilt ``camera_tilt_deg`` (degrees, (N,) or scalar)."""
    pan, tilt, rgb = frames.decode_y(y_pred, camera_tilt_deg, 0.0)
    rgb = np.clip(np.asarray(rgb, dtype=np.float64), 0.0, None)
    rgb = rgb / np.maximum(np.linalg.norm(rgb, axis=-1, keepdims=True), 1e-300)
    return pan, tilt, rgb


def errors_from_y(y_pred: np.ndarray, truth: dict) -> dict:
    """Per-image errors in degrees (pan, tilt, direction, colour; arrays (N,))."""
    pan, tilt, rgb = decode_outputs(y_pred, truth["camera_tilt_deg"])
    return metrics.light_errors(pan, tilt, rgb, truth["pan_rel_deg"], truth["tilt_deg"], truth["rgb"])


def _stats_table(errors: dict) -> str:
    labels = metrics.STAT_LABELS
    lines = ["**Colour-constancy style statistics, all images (degrees)**", "",
             "| Stat | " + " | ".join(m.capitalize() for m in metrics.METRICS) + " |",
             "|---|" + "---:|" * len(metrics.METRICS)]
    for s in COLOUR_STATS:
        cells = [f"{metrics.summary_stats(errors[m])[s]:.2f}" for m in metrics.METRICS]
        lines.append(f"| {labels[s]} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def evaluate(model, data_dir: str | os.PathLike, out_dir: str | os.PathLike, split: str = "test",
             model_name: str = "", batch_size: int = 64) -> dict:
    """Evaluate ``model`` on ``split`` of ``data_dir``; write the report folder.

    Returns ``error_tables`` (nested dict of statistics, degrees) with ``n``.
    """
    data_dir, out_dir = os.fspath(data_dir), os.fspath(out_dir)
    dataset = LightDataset(data_dir, split, model.config.res, cache=False)
    if len(dataset) == 0:
        raise DatasetError(f"{data_dir}: no records in split {split!r} (try --split all)")
    y_pred = run_model(model, dataset, batch_size)
    truth = dataset.truth()
    pan, tilt, rgb = decode_outputs(y_pred, truth["camera_tilt_deg"])
    errors = metrics.light_errors(pan, tilt, rgb, truth["pan_rel_deg"], truth["tilt_deg"], truth["rgb"])
    tables = metrics.error_tables(errors, truth["tilt_deg"], truth["pan_rel_deg"])

    os.makedirs(out_dir, exist_ok=True)
    header = (f"# Evaluation of {model_name or 'model'}\n\ndataset: {os.path.abspath(data_dir)} "
              f"(split {split}, {len(dataset)} images)\n\n")
    with open(os.path.join(out_dir, "report.md"), "w") as f:
        f.write(header + metrics.format_tables(tables) + "\n" + _stats_table(errors))
    with open(os.path.join(out_dir, "metrics.json"), "w") as f:
        json.dump({"model": model_name, "dataset": os.path.abspath(data_dir), "split": split,
                   "n": len(dataset), "tables": tables}, f, indent=1)
    with open(os.path.join(out_dir, "per_image.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "camera_tilt_deg", "pan_rel_gt_deg", "tilt_gt_deg", "r_gt", "g_gt", "b_gt",
                    "pan_rel_pred_deg", "tilt_pred_deg", "r_pred", "g_pred", "b_pred",
                    "pan_err_deg", "tilt_err_deg", "direction_err_deg", "colour_err_deg"])
        for i, pid in enumerate(truth["id"]):
            w.writerow([pid, truth["camera_tilt_deg"][i], truth["pan_rel_deg"][i], truth["tilt_deg"][i],
                        *np.round(truth["rgb"][i], 6), round(float(pan[i]), 4), round(float(tilt[i]), 4),
                        *np.round(rgb[i], 6), *(round(float(errors[m][i]), 4) for m in metrics.METRICS)])
    from relight.predictions import write_predictions
    entries = [{"id": pid, "pan_deg": float(pan[i]), "tilt_deg": float(tilt[i]),
                "rgb": [float(v) for v in rgb[i]], "y": [float(v) for v in y_pred[i]]}
               for i, pid in enumerate(truth["id"])]
    write_predictions(os.path.join(out_dir, "predictions.json"), entries, dataset=os.path.abspath(data_dir),
                      model=model_name, split=split)
    return tables

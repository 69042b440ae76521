"""Evaluation of a model on a dataset split: the paper's Tables 1-3 (degrees), colour
constancy statistics, a per-image CSV and a ``relight.predictions/v1`` file.

Report folder contents:
    report.md          Tables 1-3 (mean, median) + trimean / best 25% / worst 25%; pan is
                       scored over the lights below the zenith (tilt < 90), the zenith
                       lights left out counted beside it, the all-lights pan its own column
    metrics.json       the same numbers, machine-readable (relight.metrics.error_tables:
                       "pan" with "zenith_left_out", and "pan_all"),
                       plus ``cct`` (CCT error in kelvin and mireds) and, for a model
                       with a kappa head, ``uncertainty`` (relight.net.uncertainty)
    per_image.csv      id, truth, prediction and the four errors of every image; for a
                       model with a kappa head also ``kappa`` and ``cone90_deg``
    predictions.json   relight.predictions/v1 (pan_deg = predicted pan_rel, tilt_deg,
                       rgb unit norm, y: the raw outputs as the paper's 7-vector (of a
                       camera-frame model: turned into it); cct_k, duv; kappa, cone90_deg),
                       the input of ``relight compare``
    reliability.png    reliability diagram of the direction cones (kappa head only)
"""
from __future__ import annotations

__all__ = [
    "COLOUR_STATS", "run_model", "target_frame_of", "paper_y", "decode_outputs", "extra_fields", "cct_errors", "errors_from_y",
    "run_model_on_engine", "evaluate",
]

import csv
import json
import os

import numpy as np
import torch

from relight import frames, metrics
from relight.dataset import DatasetError
from relight.net.data import LightDataset, model_dataset

COLOUR_STATS = ("mean", "median", "trimean", "best25", "worst25")


def run_model(model, dataset: LightDataset, batch_size: int = 64, with_kappa: bool = False,
              with_camera: bool = False):
    """Raw network outputs ``(N, 7)`` float64 for every item of ``dataset`` (eval mode,
    no augmentation); the model's train/eval mode is restored afterwards. With
    ``with_kappa``: ``(y, kappa)``, kappa the calibrated direction concentration ``(N,)``
    (None for a model without a kappa head). With ``with_camera`` too: ``(y, kappa,
    camera_tilt_deg)``, the predicted camera tilt ``(N,)`` in degrees (None for a model
    without a camera head)."""
    from relight.net.model import camera_tilt_deg
    was_training = model.training
    model.eval()
    out, kappas, cameras = [], [], []
    try:
        with torch.no_grad():
            for start in range(0, len(dataset), batch_size):
                idx = range(start, min(start + batch_size, len(dataset)))
                x = dataset.batch(idx)
                if with_camera:
                    y, kappa, camera = model.forward_full(x)
                else:
                    y, kappa = model.forward_with_kappa(x) if with_kappa else (model(x), None)
                    camera = None
                out.append(y.double().numpy())
                if kappa is not None:
                    kappas.append(kappa.double().numpy())
                if camera is not None:
                    cameras.append(camera_tilt_deg(camera).double().numpy())
    finally:
        model.train(was_training)
    y = np.concatenate(out) if out else np.zeros((0, 7))
    if not with_kappa and not with_camera:
        return y
    has_kappa = getattr(model, "has_kappa", False)
    kappa = (np.concatenate(kappas) if kappas else np.zeros(0)) if has_kappa else None
    if not with_camera:
        return y, kappa
    has_camera = getattr(model, "has_camera", False)
    return y, kappa, (np.concatenate(cameras) if cameras else np.zeros(0)) if has_camera else None


def target_frame_of(model) -> str:
    """What a model's 7 outputs mean (:attr:`relight.net.model.NetConfig.target_frame`):
    ``"world"`` (the paper's y; also any model without the setting) or ``"camera"``."""
    return getattr(getattr(model, "config", None), "target_frame", "world")


def paper_y(y_pred: np.ndarray, camera_tilt_deg, target_frame: str = "world") -> np.ndarray:
    """The paper's 7-vectors of raw outputs ``(N, 7)`` of a model of ``target_frame``
    (:func:`relight.frames.target_to_y`), for cameras at pan 0 and tilt ``camera_tilt_deg``:
    the outputs themselves in the world frame; what a predictions file stores as ``y``."""
    return frames.target_to_y(y_pred, camera_tilt_deg, target_frame)


def decode_outputs(y_pred: np.ndarray, camera_tilt_deg, target_frame: str = "world"
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(pan_rel_deg, tilt_deg, rgb unit norm)`` of raw outputs ``(N, 7)`` of a model of
    ``target_frame`` (:func:`target_frame_of`) for cameras at pan 0 and tilt
    ``camera_tilt_deg`` (degrees, (N,) or scalar). Every decoding of a network's outputs
    goes through here."""
    pan, tilt, rgb = frames.decode_y(paper_y(y_pred, camera_tilt_deg, target_frame), camera_tilt_deg, 0.0)
    rgb = np.clip(np.asarray(rgb, dtype=np.float64), 0.0, None)
    rgb = rgb / np.maximum(np.linalg.norm(rgb, axis=-1, keepdims=True), 1e-300)
    return pan, tilt, rgb


def extra_fields(rgb: np.ndarray, kappa: np.ndarray | None) -> list[dict]:
    """Optional predictions-file fields of each image: ``cct_k`` and ``duv`` of the
    predicted colour (None = null where it is far from the Planckian locus, see
    :func:`relight.colour.rgb_to_cct_duv_near_locus`), and with a kappa head ``kappa``
    and ``cone90_deg`` (radius of the 90% cone of the direction, degrees)."""
    from relight.colour import rgb_to_cct_duv_near_locus
    from relight.net.uncertainty import CONE_LEVEL, cone_radius_deg
    cct, duv = rgb_to_cct_duv_near_locus(rgb)
    out = [{"cct_k": None if np.isnan(c) else round(float(c), 1),
            "duv": None if np.isnan(d) else round(float(d), 5)} for c, d in zip(cct, duv)]
    if kappa is not None:
        cone = cone_radius_deg(kappa, CONE_LEVEL)
        for o, k, c in zip(out, kappa, cone):
            o["kappa"], o["cone90_deg"] = float(k), float(c)
    return out


def cct_errors(cct_pred_k, cct_true_k) -> dict:
    """CCT errors where the prediction has a CCT: ``{"n", "n_no_cct", "kelvin": {mean,
    median}, "mired": {mean, median}}`` (absolute differences; mired = 1e6 / K)."""
    p, t = np.asarray(cct_pred_k, dtype=np.float64), np.asarray(cct_true_k, dtype=np.float64)
    ok = np.isfinite(p) & np.isfinite(t)
    dk, dm = np.abs(p[ok] - t[ok]), np.abs(1e6 / p[ok] - 1e6 / t[ok])
    stat = (lambda a: {"mean": float(np.mean(a)), "median": float(np.median(a))} if a.size
            else {"mean": None, "median": None})
    return {"n": int(ok.sum()), "n_no_cct": int((~ok).sum()), "kelvin": stat(dk), "mired": stat(dm)}


def _format_cct(c: dict, colour: dict) -> str:
    f = (lambda v: "-" if v is None else f"{v:.1f}")
    return ("**Colour as correlated colour temperature**\n\n"
            "| Error | Mean | Median |\n|---|---:|---:|\n"
            f"| Colour, angular (deg) | {colour['mean']:.2f} | {colour['median']:.2f} |\n"
            f"| CCT (K) | {f(c['kelvin']['mean'])} | {f(c['kelvin']['median'])} |\n"
            f"| CCT (mired) | {f(c['mired']['mean'])} | {f(c['mired']['median'])} |\n\n"
            f"{c['n']} images; {c['n_no_cct']} predicted colours far from the Planckian locus "
            "(|Duv| > 0.05 or CCT outside 1000-25000 K) have no CCT and are left out.\n")


def errors_from_y(y_pred: np.ndarray, truth: dict, target_frame: str = "world") -> dict:
    """Per-image errors in degrees (pan, tilt, direction, colour; arrays (N,)) of raw outputs
    of a model of ``target_frame``, decoded with the true camera tilts."""
    pan, tilt, rgb = decode_outputs(y_pred, truth["camera_tilt_deg"], target_frame)
    return metrics.light_errors(pan, tilt, rgb, truth["pan_rel_deg"], truth["tilt_deg"], truth["rgb"])


def _stats_table(errors: dict, tilt_gt_deg) -> str:
    """Colour-constancy statistics of every column of Table 1 (pan below the zenith, the
    all-lights pan last)."""
    labels = metrics.STAT_LABELS
    values = metrics.table_values(errors, tilt_gt_deg)
    stats = {m: metrics.summary_stats(v) for m, v in values.items()}
    lines = ["**Colour-constancy style statistics, all images (degrees; pan over the "
             f"{stats['pan']['n']} lights below the zenith)**", "",
             "| Stat | " + " | ".join(metrics.METRIC_LABELS[m] for m in values) + " |",
             "|---|" + "---:|" * len(values)]
    for s in COLOUR_STATS:
        cells = ["n/a" if stats[m]["n"] == 0 else f"{stats[m][s]:.2f}" for m in values]
        lines.append(f"| {labels[s]} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


class _Rows:
    """The items ``indices`` of a dataset, as a dataset (what :func:`run_model` reads)."""

    def __init__(self, dataset, indices: list[int]):
        self.dataset, self.indices = dataset, list(indices)

    def __len__(self) -> int:
        return len(self.indices)

    def batch(self, items):
        return self.dataset.batch([self.indices[i] for i in items])


def _model_shard(context, shard: list[int]):
    """Engine task (in a worker process): :func:`run_model` on items ``shard`` (one
    batch) with the client's torch thread count."""
    model, dataset, batch_size, torch_threads = context
    torch.set_num_threads(torch_threads)
    return run_model(model, _Rows(dataset, shard), batch_size, with_kappa=True)


def run_model_on_engine(model, dataset: LightDataset, batch_size: int, scheduler, progress: bool = True):
    """``run_model(..., with_kappa=True)`` on Dask (``local:N`` or an address): one task
    a batch (the same batches as :func:`run_model`, so the same numbers), run with this
    process's torch thread count, gathered here in item order."""
    from relight import engine
    parts = {}
    engine.map_shards(scheduler, _model_shard, (model, dataset, batch_size, torch.get_num_threads()),
                      list(range(len(dataset))), lambda shard, value: parts.__setitem__(shard[0], value),
                      engine.ShardPlan(mitsuba=False, shard_size=batch_size, progress=progress))
    values = [parts[k] for k in sorted(parts)]
    y = np.concatenate([v[0] for v in values]) if values else np.zeros((0, 7))
    has_kappa = bool(values) and values[0][1] is not None
    return y, np.concatenate([v[1] for v in values]) if has_kappa else None


def evaluate(model, data_dir: str | os.PathLike, out_dir: str | os.PathLike, split: str = "test",
             model_name: str = "", batch_size: int = 64, scheduler=None) -> dict:
    """Evaluate ``model`` on ``split`` of ``data_dir``; write the report folder.

    ``scheduler``: run the network on Dask (``local:N`` or an address, one task a
    batch, :mod:`relight.engine`); the report is written here, the same as without it.
    Returns ``error_tables`` (nested dict of statistics, degrees) with ``n``.
    """
    data_dir, out_dir = os.fspath(data_dir), os.fspath(out_dir)
    dataset = model_dataset(model, data_dir, split, cache=False)
    if len(dataset) == 0:
        raise DatasetError(f"{data_dir}: no records in split {split!r} (try --split all)")
    if scheduler is None:
        y_pred, kappa = run_model(model, dataset, batch_size, with_kappa=True)
    else:
        y_pred, kappa = run_model_on_engine(model, dataset, batch_size, scheduler)
    truth = dataset.truth()
    frame = target_frame_of(model)
    y_paper = paper_y(y_pred, truth["camera_tilt_deg"], frame)
    pan, tilt, rgb = decode_outputs(y_paper, truth["camera_tilt_deg"])
    errors = metrics.light_errors(pan, tilt, rgb, truth["pan_rel_deg"], truth["tilt_deg"], truth["rgb"])
    tables = metrics.error_tables(errors, truth["tilt_deg"], truth["pan_rel_deg"])
    pan_split = metrics.pan_where_defined(errors["pan"], truth["tilt_deg"])
    pan_tilt = metrics.pan_by_tilt(errors["pan"], truth["tilt_deg"])
    extras = extra_fields(rgb, kappa)
    from relight.colour import rgb_to_cct_duv_near_locus
    # the stored CCT where the light's colour is (CCT, Duv) on relight's locus; where it has no
    # Duv (e.g. a Tanner-Helland colour, --preset sid2-paper: its nominal kelvin is not the CCT
    # of its RGB) or no CCT at all, the CCT of the true colour, as of the prediction's
    cct_true = np.array([r["light"].get("cct_k", np.nan)
                         if isinstance(r.get("light"), dict) and r["light"].get("duv") is not None else np.nan
                         for r in dataset.records], dtype=np.float64)
    missing = ~np.isfinite(cct_true)
    if missing.any():
        cct_true[missing] = rgb_to_cct_duv_near_locus(truth["rgb"][missing])[0]
    cct = cct_errors([np.nan if e["cct_k"] is None else e["cct_k"] for e in extras], cct_true)
    uncertainty = None
    if kappa is not None:
        from relight.net.uncertainty import format_summary, plot_reliability, uncertainty_summary
        uncertainty = uncertainty_summary(kappa, errors["direction"], truth["tilt_deg"], tilt_pred_deg=tilt)

    from relight.fileio import Transaction
    from relight.predictions import write_predictions
    header = (f"# Evaluation of {model_name or 'model'}\n\ndataset: {os.path.abspath(data_dir)} "
              f"(split {split}, {len(dataset)} images)\n\n")
    entries = [{"id": pid, "pan_deg": float(pan[i]), "tilt_deg": float(tilt[i]),
                "rgb": [float(v) for v in rgb[i]], "y": [float(v) for v in y_paper[i]], **extras[i]}
               for i, pid in enumerate(truth["id"])]
    with Transaction(inputs=[data_dir]) as t:   # the four files, all or none
        t.makedirs(out_dir)
        t.stage_text(os.path.join(out_dir, "report.md"),
                     header + metrics.format_tables(tables) + "\n"
                     + metrics.format_pan_where_defined(pan_split) + "\n" + metrics.format_pan_by_tilt(pan_tilt)
                     + "\n" + _stats_table(errors, truth["tilt_deg"]) + "\n"
                     + _format_cct(cct, tables["overall"]["colour"])
                     + ("\n" + format_summary(uncertainty) + "\n![reliability](reliability.png)\n"
                        if uncertainty else ""))
        t.stage_text(os.path.join(out_dir, "metrics.json"), json.dumps(
            {"model": model_name, "dataset": os.path.abspath(data_dir), "split": split,
             "n": len(dataset), "tables": tables, "pan_where_defined": pan_split,
             "pan_by_tilt": pan_tilt, "cct": cct,
             **({"uncertainty": uncertainty} if uncertainty else {})}, indent=1))
        if uncertainty:
            t.stage(os.path.join(out_dir, "reliability.png"),
                    lambda tmp: plot_reliability(uncertainty, tmp, f"{model_name or 'model'}: 90% cone covers "
                                                 f"{100 * uncertainty['cone90_coverage']:.1f}%"))
        t.stage(os.path.join(out_dir, "per_image.csv"),
                lambda tmp: _write_per_image(tmp, truth, pan, tilt, rgb, errors, kappa))
        write_predictions(os.path.join(out_dir, "predictions.json"), entries,
                          dataset=os.path.abspath(data_dir), model=model_name, split=split, transaction=t)
    return tables


def _write_per_image(path: str, truth: dict, pan, tilt, rgb, errors, kappa=None) -> None:
    """The per-image table; with ``kappa`` (calibrated, (N,)) two more columns, ``kappa``
    and ``cone90_deg`` (the radius of the 90% cone, as in the predictions file)."""
    cone = None
    if kappa is not None:
        from relight.net.uncertainty import CONE_LEVEL, cone_radius_deg
        cone = cone_radius_deg(kappa, CONE_LEVEL)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "camera_tilt_deg", "pan_rel_gt_deg", "tilt_gt_deg", "r_gt", "g_gt", "b_gt",
                    "pan_rel_pred_deg", "tilt_pred_deg", "r_pred", "g_pred", "b_pred",
                    "pan_err_deg", "tilt_err_deg", "direction_err_deg", "colour_err_deg"]
                   + (["kappa", "cone90_deg"] if cone is not None else []))
        for i, pid in enumerate(truth["id"]):
            w.writerow([pid, truth["camera_tilt_deg"][i], truth["pan_rel_deg"][i], truth["tilt_deg"][i],
                        *np.round(truth["rgb"][i], 6), round(float(pan[i]), 4), round(float(tilt[i]), 4),
                        *np.round(rgb[i], 6), *(round(float(errors[m][i]), 4) for m in metrics.METRICS)]
                       + ([float(f"{kappa[i]:.6g}"), round(float(cone[i]), 4)] if cone is not None else []))

"""Calibrated uncertainty of the light direction: a von Mises-Fisher (vMF) distribution
on the unit sphere around the predicted direction.

Convention:
    * The direction is the world-frame unit vector toward the light,
      ``(cos t cos p, cos t sin p, sin t)`` with ``p = pan_rel`` and ``t`` the light
      tilt (camera at pan 0), exactly :func:`relight.frames.direction` of the decoded
      7-vector; :func:`direction_from_y` builds it in torch (differentiable, no
      ``atan2``), which also makes a tilt past the zenith the same vector as its fold.
    * The vMF density on the sphere (per steradian), concentration ``kappa > 0``:
      ``f(x) = kappa / (4 pi sinh kappa) exp(kappa mu.x)
             = kappa / (2 pi (1 - exp(-2 kappa))) exp(-kappa (1 - mu.x))``.
    * The angle ``theta`` between a vMF sample and ``mu`` has
      ``P(theta <= t) = (1 - exp(-kappa (1 - cos t))) / (1 - exp(-2 kappa))``, so the
      cone holding probability ``q`` has ``1 - cos t = -log(1 - q (1 - exp(-2 kappa))) / kappa``.
    * Calibration is temperature scaling (Guo et al. 2017, "On Calibration of Modern
      Neural Networks"): one scalar ``T`` with ``kappa_cal = kappa / T``, fitted by
      minimising the mean NLL on the validation split.

Angles are degrees at the edges; kappa is dimensionless (1 / rad^2 near the mean:
for large kappa the angle is Rayleigh with scale ``1 / sqrt(kappa)`` radians).
"""
from __future__ import annotations

__all__ = [
    "CONE_LEVEL", "RELIABILITY_LEVELS", "LOG_T_BOUNDS", "PAIR_EPS", "LOG_2PI", "vmf_nll", "vmf_nll_np",
    "coverage_probability", "cone_radius_deg", "pan_halfwidth_deg", "direction_from_y", "direction_nll",
    "fit_temperature", "spearman", "uncertainty_summary", "format_summary", "plot_reliability",
]

import math
import os

import numpy as np
import torch

from relight import metrics

CONE_LEVEL = 0.9                      # the cone written to predictions (cone90_deg)
RELIABILITY_LEVELS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 0.99)
LOG_T_BOUNDS = (-8.0, 8.0)            # search range of log temperature
PAIR_EPS = 1e-6                       # guards the normalisation of a (sin, cos) pair
LOG_2PI = math.log(2.0 * math.pi)


# --- vMF maths ------------------------------------------------------------------

def vmf_nll(kappa: torch.Tensor, cos_angle: torch.Tensor) -> torch.Tensor:
    """Negative log density (per steradian) of a direction at angle ``acos(cos_angle)``
    from the mean, elementwise: ``-log kappa + log 2 pi + log(1 - exp(-2 kappa))
    + kappa (1 - cos_angle)``. Stable for small and large kappa."""
    return (-torch.log(kappa) + LOG_2PI + torch.log(-torch.expm1(-2.0 * kappa))
            + kappa * (1.0 - cos_angle))


def vmf_nll_np(kappa, angle_deg) -> np.ndarray:
    """:func:`vmf_nll` on numpy arrays, the angle in degrees."""
    k = np.asarray(kappa, dtype=np.float64)
    c = np.cos(np.radians(np.asarray(angle_deg, dtype=np.float64)))
    return -np.log(k) + LOG_2PI + np.log(-np.expm1(-2.0 * k)) + k * (1.0 - c)


def coverage_probability(kappa, angle_deg) -> np.ndarray:
    """``P(theta <= angle)`` for a vMF of concentration ``kappa`` (broadcast)."""
    k = np.asarray(kappa, dtype=np.float64)
    c = np.cos(np.radians(np.asarray(angle_deg, dtype=np.float64)))
    return np.expm1(-k * (1.0 - c)) / np.expm1(-2.0 * k)


def cone_radius_deg(kappa, level: float = CONE_LEVEL) -> np.ndarray:
    """Radius (degrees, [0, 180]) of the cone around the mean direction that holds
    probability ``level`` of a vMF with concentration ``kappa`` (closed form)."""
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    k = np.asarray(kappa, dtype=np.float64)
    one_minus_cos = -np.log1p(level * np.expm1(-2.0 * k)) / k
    return np.degrees(np.arccos(np.clip(1.0 - one_minus_cos, -1.0, 1.0)))


def pan_halfwidth_deg(cone_deg, tilt_deg) -> np.ndarray:
    """Half-width (degrees, [0, 180]) of the pan values inside a cone of radius
    ``cone_deg`` around a direction of elevation ``tilt_deg``: on the sphere a cap of
    angular radius r centred at colatitude c <= r holds the pole, so every pan (180);
    otherwise the widest longitude of the cap is ``asin(sin r / sin c)``. Near the zenith a
    narrow direction cone is a wide pan interval: pan is ill-defined there."""
    r = np.radians(np.asarray(cone_deg, dtype=np.float64))
    colat = np.radians(90.0 - np.abs(np.asarray(tilt_deg, dtype=np.float64)))
    holds_pole = r >= colat
    ratio = np.sin(r) / np.maximum(np.sin(colat), 1e-300)
    return np.where(holds_pole, 180.0, np.degrees(np.arcsin(np.clip(ratio, 0.0, 1.0))))


def direction_from_y(y: torch.Tensor, camera_tilt_deg: torch.Tensor) -> torch.Tensor:
    """World-frame unit vectors toward the light ``(N, 3)`` of 7-vectors ``(N, 7)``
    (raw network outputs are fine) for cameras at pan 0 and tilt ``camera_tilt_deg``
    (``(N,)``, degrees). Same vector as ``frames.direction(*frames.decode_y(y)[:2])``.
    For the targets of a camera-frame model give tilt 0 (:func:`relight.frames.target_tilt_deg`):
    the vectors are then the camera-frame directions in a level camera's world, and the
    angles between them are the directions' true angles."""
    pan = y[:, 0:2] / y[:, 0:2].norm(dim=1, keepdim=True).clamp_min(PAIR_EPS)
    dtilt = y[:, 2:4] / y[:, 2:4].norm(dim=1, keepdim=True).clamp_min(PAIR_EPS)
    # pan_rel = -(pan_c - pan_l): cos p = y1, sin p = -y0
    cos_p, sin_p = pan[:, 1], -pan[:, 0]
    # tilt_l = tilt_c - d with (sin d, cos d) = (y2, y3)
    tc = torch.deg2rad(camera_tilt_deg.to(y.dtype))
    cos_t = torch.cos(tc) * dtilt[:, 1] + torch.sin(tc) * dtilt[:, 0]
    sin_t = torch.sin(tc) * dtilt[:, 1] - torch.cos(tc) * dtilt[:, 0]
    return torch.stack([cos_t * cos_p, cos_t * sin_p, sin_t], dim=1)


def direction_nll(y_pred: torch.Tensor, y_true: torch.Tensor, kappa: torch.Tensor,
                  camera_tilt_deg: torch.Tensor) -> torch.Tensor:
    """Mean vMF NLL of the true directions around the predicted ones, with the
    predicted direction held fixed (detached): this term trains kappa only."""
    mu = direction_from_y(y_pred.detach(), camera_tilt_deg)
    x = direction_from_y(y_true, camera_tilt_deg)
    cos = (mu * x).sum(dim=1).clamp(-1.0, 1.0)
    return vmf_nll(kappa, cos).mean()


# --- calibration ------------------------------------------------------------------

def fit_temperature(kappa, angle_deg) -> float:
    """Temperature ``T`` minimising the mean NLL of ``kappa / T`` at the observed
    direction errors ``angle_deg`` (arrays (N,)); 1.0 for empty input."""
    from scipy.optimize import minimize_scalar
    k = np.asarray(kappa, dtype=np.float64)
    a = np.asarray(angle_deg, dtype=np.float64)
    if k.size == 0:
        return 1.0
    if k.shape != a.shape or not (np.all(np.isfinite(k)) and np.all(k > 0) and np.all(np.isfinite(a))):
        raise ValueError("expected positive finite kappa and finite angles of one shape")
    res = minimize_scalar(lambda log_t: float(np.mean(vmf_nll_np(k * math.exp(-log_t), a))),
                          bounds=LOG_T_BOUNDS, method="bounded", options={"xatol": 1e-6})
    return float(math.exp(res.x))


def spearman(a, b) -> float:
    """Spearman rank correlation (NaN with fewer than 3 values or a constant input)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.size < 3 or np.ptp(a) == 0 or np.ptp(b) == 0:
        return float("nan")
    from scipy.stats import spearmanr
    return float(spearmanr(a, b).statistic)


def _none_if_nan(v: float):
    return None if v != v else v


def uncertainty_summary(kappa, angle_deg, tilt_gt_deg=None, levels=RELIABILITY_LEVELS,
                        tilt_pred_deg=None) -> dict:
    """Calibration figures of calibrated ``kappa`` against the direction errors
    (with ``tilt_pred_deg``, the levels also give the pan half-width of the cones,
    :func:`pan_halfwidth_deg`, and the fraction of cones holding the zenith).

    Returns ``{"n", "nll_mean", "cone90_coverage", "cone90_mean_deg", "cone90_median_deg",
    "spearman_cone90_error" (None when undefined: fewer than 3 images or a constant
    input), "reliability": {"expected": [...], "observed": [...]},
    "cone90_by_tilt_level": {L1: {"n", "cone90_mean_deg", "coverage"}, ...}}``.
    """
    k = np.asarray(kappa, dtype=np.float64)
    a = np.asarray(angle_deg, dtype=np.float64)
    cone = cone_radius_deg(k, CONE_LEVEL)
    observed = [float(np.mean(a <= cone_radius_deg(k, q))) if a.size else float("nan") for q in levels]
    out = {"n": int(a.size), "level": CONE_LEVEL,
           "nll_mean": float(np.mean(vmf_nll_np(k, a))) if a.size else float("nan"),
           "cone90_coverage": float(np.mean(a <= cone)) if a.size else float("nan"),
           "cone90_mean_deg": float(np.mean(cone)) if a.size else float("nan"),
           "cone90_median_deg": float(np.median(cone)) if a.size else float("nan"),
           "spearman_cone90_error": _none_if_nan(spearman(cone, a)),
           "reliability": {"expected": [float(q) for q in levels], "observed": observed}}
    if tilt_gt_deg is not None:
        lev = metrics.tilt_level(tilt_gt_deg)
        pan_hw = None if tilt_pred_deg is None else pan_halfwidth_deg(cone, tilt_pred_deg)

        def pan_stats(mask):
            if pan_hw is None or not np.any(mask):
                return {}
            return {"pan90_halfwidth_mean_deg": float(np.mean(pan_hw[mask])),
                    "holds_zenith": float(np.mean(pan_hw[mask] >= 180.0))}
        out["cone90_by_tilt_level"] = {
            name: {**pan_stats(lev == name), "n": int(np.sum(lev == name)),
                   "cone90_mean_deg": float(np.mean(cone[lev == name])) if np.any(lev == name) else None,
                   "direction_mean_deg": float(np.mean(a[lev == name])) if np.any(lev == name) else None,
                   "coverage": float(np.mean(a[lev == name] <= cone[lev == name])) if np.any(lev == name) else None}
            for name in metrics.TILT_LEVELS}
    return out


def format_summary(s: dict) -> str:
    """Markdown section of :func:`uncertainty_summary`."""
    lines = ["**Direction uncertainty (calibrated vMF kappa)**", "",
             f"- 90% cone coverage: {100 * s['cone90_coverage']:.1f}% of {s['n']} true directions "
             f"(cone radius mean {s['cone90_mean_deg']:.2f}, median {s['cone90_median_deg']:.2f} deg)",
             "- Spearman rank correlation, cone radius vs direction error: "
             + ("-" if s["spearman_cone90_error"] is None else f"{s['spearman_cone90_error']:.3f}"),
             f"- mean vMF negative log-likelihood: {s['nll_mean']:.3f} nats", "",
             "| Expected coverage | " + " | ".join(f"{q:.2f}" for q in s["reliability"]["expected"]) + " |",
             "|---|" + "---:|" * len(s["reliability"]["expected"]),
             "| Observed | " + " | ".join(f"{o:.2f}" for o in s["reliability"]["observed"]) + " |"]
    by_level = s.get("cone90_by_tilt_level")
    if by_level:
        lines += ["", "| Tilt level | n | 90% cone mean (deg) | direction error mean (deg) | coverage "
                      "| pan half-width of the cone, mean (deg) | cones holding the zenith |",
                  "|---|---:|---:|---:|---:|---:|---:|"]
        for name, v in by_level.items():
            lo, hi = metrics.TILT_LEVELS[name]
            cells = [f"{v[k]:.2f}" if v.get(k) is not None else "-"
                     for k in ("cone90_mean_deg", "direction_mean_deg", "pan90_halfwidth_mean_deg")]
            cov = f"{100 * v['coverage']:.1f}%" if v["coverage"] is not None else "-"
            zen = f"{100 * v['holds_zenith']:.0f}%" if v.get("holds_zenith") is not None else "-"
            lines.append(f"| {name} [{lo:g}, {hi:g}{']' if name == 'L3' else ')'} | {v['n']} | {cells[0]} | "
                         f"{cells[1]} | {cov} | {cells[2]} | {zen} |")
    return "\n".join(lines) + "\n"


def plot_reliability(s: dict, path: str | os.PathLike, title: str = "") -> None:
    """Reliability diagram PNG: observed vs expected coverage of the vMF cones
    (diagonal = perfect calibration), written to ``path`` (a plain file write; give
    a temporary name and rename for atomicity)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    exp_, obs = s["reliability"]["expected"], s["reliability"]["observed"]
    fig, ax = plt.subplots(figsize=(4.5, 4.5))
    ax.plot([0, 1], [0, 1], "k--", lw=1, label="perfect calibration")
    ax.plot(exp_, obs, "o-", label=f"observed (n = {s['n']})")
    ax.set_xlim(0, 1), ax.set_ylim(0, 1)
    ax.set_xlabel("expected coverage of the vMF cone"), ax.set_ylabel("observed fraction of true directions inside")
    ax.set_title(title or f"90% cone covers {100 * s['cone90_coverage']:.1f}%", fontsize=10)
    ax.grid(alpha=0.3), ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    try:
        fig.savefig(os.fspath(path), dpi=100, format="png")
    finally:
        plt.close(fig)

"""Error metrics (all in degrees) and the paper's result tables.

Convention (``shared/conventions.md``):
    * pan error: ``|wrap180(pan_pred - pan_gt)|`` in [0, 180].
    * tilt error: ``|tilt_pred - tilt_gt|`` (light elevation).
    * direction error: angle between the world-frame unit vectors
      ``frames.direction(pan, tilt) = (cos t cos p, cos t sin p, sin t)``.
    * colour error: angle between predicted and true RGB (the recovery angular error
      of colour constancy), scale invariant.
    * Table pan (decided in the team's Table 1 issue): the pan error of a *set* is the
      mean over the lights with true tilt < 90 (:data:`ZENITH_TILT_DEG`), where pan is
      defined; the number of zenith lights left out is printed beside it, and the mean
      over all lights stays available as its own column, ``pan_all`` ("Pan, all lights").
      Per-image errors (:func:`light_errors`) are unchanged: a zenith light's pan error
      is still computed, only the tables leave it out of "Pan".
    * Breakdowns: tilt levels L1 [30, 50), L2 [50, 70), L3 [70, 90] on the true tilt;
      pan levels on the true ``pan_rel`` (wrapped to [0, 360)), counted only for true
      tilt in [30, 70] (inclusive): front [315, 45), right [45, 135),
      back [135, 225), left [225, 315).

Angles use ``atan2(|a x b|, a . b)``, accurate for tiny and near-180 angles alike.
Everything is vectorised (numpy broadcasting); angles are degrees at every edge.
"""
from __future__ import annotations

import numpy as np

from relight.frames import direction, wrap180, wrap360

__all__ = [
    "pan_error_deg", "tilt_error_deg", "direction_error_deg", "colour_error_deg",
    "light_errors", "summary_stats", "TILT_LEVELS", "PAN_LEVELS", "PAN_TABLE_TILT_DEG",
    "METRICS", "tilt_level", "pan_level", "error_tables", "format_tables", "pan_where_defined",
    "format_pan_where_defined", "pan_by_tilt", "format_pan_by_tilt",
    "ZENITH_TILT_DEG", "TILT_STEP_DEG", "TABLE_METRICS", "METRIC_LABELS", "pan_defined", "table_values",
    "STATS", "STAT_LABELS", "angle_deg",
]

METRICS = ("pan", "tilt", "direction", "colour")  # keys of light_errors, table order
TABLE_METRICS = METRICS + ("pan_all",)            # the tables' columns: pan where defined ... pan of all lights
METRIC_LABELS = {"pan": "Pan (tilt < 90)", "tilt": "Tilt", "direction": "Direction", "colour": "Colour",
                 "pan_all": "Pan, all lights"}
ZENITH_KEY = "zenith_left_out"   # in a table's "pan" stats: the lights at the zenith left out of them
TILT_LEVELS = {"L1": (30.0, 50.0), "L2": (50.0, 70.0), "L3": (70.0, 90.0)}
PAN_LEVELS = {"front": (315.0, 45.0), "right": (45.0, 135.0),
              "back": (135.0, 225.0), "left": (225.0, 315.0)}
PAN_TABLE_TILT_DEG = (30.0, 70.0)  # true tilt range (inclusive) kept for the pan table
ZENITH_TILT_DEG = 90.0             # a light here has no pan (SID2 draws tilt 90 in 1 of 13 steps)
#                                    tables score pan over true tilt < ZENITH_TILT_DEG only
TILT_STEP_DEG = 5.0                # SID2's light tilt step: the rows of pan_by_tilt
STATS = ("n", "mean", "median", "trimean", "best25", "worst25", "max")
STAT_LABELS = {"mean": "Mean", "median": "Median", "trimean": "Trimean",
               "best25": "Best 25%", "worst25": "Worst 25%", "max": "Max"}


def angle_deg(a, b) -> np.ndarray:
    """Angle in degrees, [0, 180], between vectors ``(..., n)`` of any length (broadcast),
    as ``atan2(|a x b|, a . b)``: accurate at small angles, unlike ``acos``.

    >>> float(angle_deg([1.0, 0.0, 0.0], [0.0, 2.0, 0.0])), float(angle_deg([1.0, 1.0], [1.0, 0.0]))
    (90.0, 45.0)
    """
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    dot = np.sum(a * b, axis=-1)
    if a.shape[-1] == 3 and b.shape[-1] == 3:
        cross = np.linalg.norm(np.cross(a, b), axis=-1)
    else:   # |a x b| = sqrt(|a|^2 |b|^2 - (a . b)^2) in any dimension
        cross = np.sqrt(np.maximum(np.sum(a * a, axis=-1) * np.sum(b * b, axis=-1) - dot * dot, 0.0))
    return np.degrees(np.arctan2(cross, dot))


def pan_error_deg(pan_pred_deg, pan_gt_deg) -> np.ndarray:
    """``|wrap180(pred - gt)|`` in [0, 180] degrees; e.g. 359 vs 1 gives 2.

    >>> pan_error_deg([359.0, 90.0, 10.0], [1.0, 270.0, 350.0]).tolist()
    [2.0, 180.0, 20.0]
    """
    diff = np.asarray(pan_pred_deg, dtype=np.float64) - np.asarray(pan_gt_deg, dtype=np.float64)
    return np.abs(wrap180(diff))


def tilt_error_deg(tilt_pred_deg, tilt_gt_deg) -> np.ndarray:
    """``|pred - gt|`` in degrees (light elevation; no wrapping).

    >>> tilt_error_deg([30.0, 85.0], [45.0, 60.0]).tolist()
    [15.0, 25.0]
    """
    return np.abs(np.asarray(tilt_pred_deg, dtype=np.float64)
                  - np.asarray(tilt_gt_deg, dtype=np.float64))


def direction_error_deg(pan_pred_deg, tilt_pred_deg, pan_gt_deg, tilt_gt_deg) -> np.ndarray:
    """Angle in degrees, [0, 180], between the two world-frame light directions.

    Inputs are pan/tilt in degrees (any real values, broadcast). At the zenith
    (tilt 90) the pan does not matter.

    Opposite horizon directions are 180 apart; at the zenith pan is irrelevant;
    90 deg of pan at tilt 60 gives ``acos(sin^2 60) = acos(0.75)``:

    >>> float(direction_error_deg(0.0, 0.0, 180.0, 0.0))
    180.0
    >>> round(float(direction_error_deg(10.0, 90.0, 200.0, 90.0)), 9)
    0.0
    >>> round(float(direction_error_deg(0.0, 60.0, 90.0, 60.0)), 6)   # acos(0.75)
    41.409622
    """
    return angle_deg(direction(pan_pred_deg, tilt_pred_deg), direction(pan_gt_deg, tilt_gt_deg))


def colour_error_deg(rgb_pred, rgb_gt) -> np.ndarray:
    """Recovery angular error in degrees, [0, 180], between RGB vectors ``(..., 3)``.

    Scale invariant. Zero-length or non-finite vectors raise ValueError.

    >>> float(colour_error_deg([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]))   # orthogonal
    90.0
    >>> round(float(colour_error_deg([0.2, 0.4, 0.6], [1.0, 2.0, 3.0])), 9)   # same up to scale
    0.0
    >>> round(float(colour_error_deg([1.0, 1.0, 0.0], [1.0, 0.0, 0.0])), 9)
    45.0
    """
    return angle_deg(_unit(rgb_pred, "rgb_pred"), _unit(rgb_gt, "rgb_gt"))


def _unit(v, name: str) -> np.ndarray:
    """``(..., 3)`` vectors scaled to unit length without overflow or underflow."""
    v = np.asarray(v, dtype=np.float64)
    if v.shape[-1:] != (3,):
        raise ValueError(f"expected {name} with last axis 3, got shape {v.shape}")
    scale = np.max(np.abs(v), axis=-1, keepdims=True)
    if not np.all(np.isfinite(v)) or np.any(scale == 0.0):
        raise ValueError(f"expected finite, non-zero {name} vectors")
    v = v / scale  # largest component is +-1: squaring can neither overflow nor underflow
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def light_errors(pan_pred_deg, tilt_pred_deg, rgb_pred,
                 pan_gt_deg, tilt_gt_deg, rgb_gt) -> dict[str, np.ndarray]:
    """All four errors in degrees: ``{"pan", "tilt", "direction", "colour"}``.

    Angles have shape ``(...)``; RGB ``(..., 3)``. Pan may be ``pan_rel`` or world pan,
    as long as prediction and truth use the same one (the direction error is then
    the same too, since a common pan offset is a rotation about +Z).

    >>> e = light_errors(100.0, 40.0, [1, 1, 1], 90.0, 40.0, [1, 1, 1])
    >>> float(e["pan"]), float(e["tilt"]), float(e["colour"])
    (10.0, 0.0, 0.0)
    """
    return {
        "pan": pan_error_deg(pan_pred_deg, pan_gt_deg),
        "tilt": tilt_error_deg(tilt_pred_deg, tilt_gt_deg),
        "direction": direction_error_deg(pan_pred_deg, tilt_pred_deg, pan_gt_deg, tilt_gt_deg),
        "colour": colour_error_deg(rgb_pred, rgb_gt),
    }


def summary_stats(values) -> dict:
    """Summary of errors (degrees), flattened.

    Returns ``{"n", "mean", "median", "trimean", "best25", "worst25", "max"}``:
    trimean = (Q1 + 2 median + Q3) / 4 with numpy's default (linear) quantiles;
    best25 / worst25 = mean of the ``k = max(1, n // 4)`` smallest / largest values.
    Empty input gives ``n = 0`` and NaN for the rest; NaN or inf raises ValueError.

    Of [1, 2, 3, 4, 10]: Q1 = 2, median 3, Q3 = 4, so trimean = (2 + 6 + 4) / 4 = 3;
    k = 1, so best25 = 1 and worst25 = 10:

    >>> s = summary_stats([4, 1, 10, 3, 2])
    >>> [s[k] for k in ("n", "mean", "median", "trimean", "best25", "worst25", "max")]
    [5, 4.0, 3.0, 3.0, 1.0, 10.0, 10.0]
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    if not np.all(np.isfinite(v)):
        raise ValueError(f"summary_stats needs finite values; got {np.sum(~np.isfinite(v))} "
                         "NaN/inf of " f"{v.size}")
    n = int(v.size)
    if n == 0:
        return {"n": 0, **{k: float("nan") for k in STATS[1:]}}
    s = np.sort(v)
    q1, med, q3 = np.quantile(s, [0.25, 0.5, 0.75])
    k = max(1, n // 4)
    return {"n": n, "mean": float(s.mean()), "median": float(med),
            "trimean": float((q1 + 2.0 * med + q3) / 4.0),
            "best25": float(s[:k].mean()), "worst25": float(s[-k:].mean()),
            "max": float(s[-1])}


def tilt_level(tilt_gt_deg) -> np.ndarray:
    """Tilt level labels ("L1", "L2", "L3"; "" outside) of true tilts in degrees.

    L1 [30, 50), L2 [50, 70), L3 [70, 90] (90 included). Shape follows the input.

    >>> tilt_level([29.9, 30.0, 50.0, 69.9, 70.0, 90.0]).tolist()
    ['', 'L1', 'L2', 'L2', 'L3', 'L3']
    """
    t = np.asarray(tilt_gt_deg, dtype=np.float64)
    conds, labels = [], []
    for name, (lo, hi) in TILT_LEVELS.items():
        upper = t <= hi if name == "L3" else t < hi
        conds.append((t >= lo) & upper)
        labels.append(name)
    return np.select(conds, labels, default="").astype("<U2")


def pan_level(pan_rel_gt_deg, tilt_gt_deg) -> np.ndarray:
    """Pan level labels ("front", "right", "back", "left"; "" excluded) in degrees.

    ``pan_rel`` is wrapped to [0, 360) first; each level is [lo, hi) and front wraps
    around 0 ([315, 360) or [0, 45)). Only true tilts in [30, 70] (inclusive) get a
    label, as in the paper's pan table. Shape: the broadcast of both inputs.

    >>> pan_level([0.0, 45.0, 180.0, 314.9, -10.0, 90.0], [40, 40, 40, 40, 40, 80]).tolist()
    ['front', 'right', 'back', 'left', 'front', '']
    """
    p = wrap360(pan_rel_gt_deg)
    t = np.asarray(tilt_gt_deg, dtype=np.float64)
    p, t = np.broadcast_arrays(p, t)
    kept = (t >= PAN_TABLE_TILT_DEG[0]) & (t <= PAN_TABLE_TILT_DEG[1])
    conds, labels = [], []
    for name, (lo, hi) in PAN_LEVELS.items():
        inside = ((p >= lo) | (p < hi)) if lo > hi else ((p >= lo) & (p < hi))
        conds.append(kept & inside)
        labels.append(name)
    return np.select(conds, labels, default="").astype("<U5")


def pan_defined(tilt_gt_deg) -> np.ndarray:
    """True where a light's pan is defined: true tilt below the zenith (< 90 deg).

    >>> pan_defined([30.0, 89.5, 90.0]).tolist()
    [True, True, False]
    """
    return np.asarray(tilt_gt_deg, dtype=np.float64) < ZENITH_TILT_DEG


def table_values(errors: dict, tilt_gt_deg) -> dict[str, np.ndarray]:
    """The values each table column summarises, from per-image errors (degrees, (N,)):
    ``"pan"`` only where pan is defined (:func:`pan_defined`), ``"pan_all"`` every
    image's pan error, the other metrics as given. Order: :data:`TABLE_METRICS` first.

    >>> v = table_values({"pan": [2.0, 4.0, 120.0], "tilt": [1.0, 1.0, 1.0]}, [40.0, 85.0, 90.0])
    >>> v["pan"].tolist(), v["pan_all"].tolist(), v["tilt"].tolist()
    ([2.0, 4.0], [2.0, 4.0, 120.0], [1.0, 1.0, 1.0])
    """
    errs = {m: np.asarray(e, dtype=np.float64).ravel() for m, e in errors.items()}
    tilt = np.asarray(tilt_gt_deg, dtype=np.float64).ravel()
    if "pan" in errs:
        if errs["pan"].size != tilt.size:
            raise ValueError(f"table_values needs equal lengths, got {errs['pan'].size} and {tilt.size}")
        errs["pan_all"] = errs["pan"]
        errs["pan"] = errs["pan"][pan_defined(tilt)]
    return {m: errs[m] for m in _metric_order(errs)}


def _stats_by_metric(errors: dict[str, np.ndarray], mask, defined) -> dict:
    """Stats of each metric over the images ``mask``; pan over ``mask & defined`` with the
    count of zenith lights left out (``zenith_left_out``), and ``pan_all`` over ``mask``."""
    out = {}
    for m, e in errors.items():
        if m == "pan":
            out["pan"] = summary_stats(e[mask & defined]) | {ZENITH_KEY: int(np.sum(mask & ~defined))}
        else:
            out[m] = summary_stats(e[mask])
    if "pan" in errors:
        out["pan_all"] = summary_stats(errors["pan"][mask])
    return {m: out[m] for m in _metric_order(out)}


def error_tables(errors: dict[str, np.ndarray], tilt_gt_deg, pan_rel_gt_deg) -> dict:
    """The paper's three tables as nested dicts of :func:`summary_stats`.

    Args:
        errors: metric name -> errors in degrees, all of shape (N,) (e.g. from
            :func:`light_errors`).
        tilt_gt_deg, pan_rel_gt_deg: true light tilt and pan_rel in degrees, shape (N,).

    Returns:
        ``{"overall": {metric: stats}, "tilt_levels": {"L1": {metric: stats}, ...},
        "pan_levels": {"front": {metric: stats}, ...}}``; empty levels have n = 0.
        ``"pan"`` is scored where pan is defined (true tilt < 90) and its stats carry
        ``"zenith_left_out"``, the group's lights at the zenith; ``"pan_all"`` holds the
        pan error over every light of the group.

    Two lights below the zenith (pan errors 2 and 4) and one at it (120): pan 3.0 over 2
    lights with 1 left out, 42.0 over all three:

    >>> t = error_tables({"pan": [2.0, 4.0, 120.0]}, tilt_gt_deg=[40.0, 80.0, 90.0],
    ...                  pan_rel_gt_deg=[90.0, 90.0, 90.0])
    >>> o = t["overall"]
    >>> o["pan"]["mean"], o["pan"]["n"], o["pan"]["zenith_left_out"], o["pan_all"]["mean"]
    (3.0, 2, 1, 42.0)
    >>> t["tilt_levels"]["L3"]["pan"]["n"], t["tilt_levels"]["L3"]["pan"]["zenith_left_out"]
    (1, 1)
    """
    errs = {m: np.asarray(e, dtype=np.float64).ravel() for m, e in errors.items()}
    tilt = np.asarray(tilt_gt_deg, dtype=np.float64).ravel()
    pan = np.asarray(pan_rel_gt_deg, dtype=np.float64).ravel()
    sizes = {m: e.size for m, e in errs.items()} | {"tilt_gt": tilt.size, "pan_rel_gt": pan.size}
    if len(set(sizes.values())) > 1:
        raise ValueError(f"error_tables needs equal lengths, got {sizes}")
    tl, pl, defined = tilt_level(tilt), pan_level(pan, tilt), pan_defined(tilt)
    return {
        "overall": _stats_by_metric(errs, np.ones(tilt.size, dtype=bool), defined),
        "tilt_levels": {name: _stats_by_metric(errs, tl == name, defined) for name in TILT_LEVELS},
        "pan_levels": {name: _stats_by_metric(errs, pl == name, defined) for name in PAN_LEVELS},
    }


def pan_where_defined(pan_error_deg, tilt_gt_deg) -> dict:
    """The pan error split at the zenith, where a light's pan is undefined.

    A light at tilt 90 casts the same image whatever its pan, so its pan error is that of
    a guess (uniform on [0, 180], mean 90) and would lift the mean pan error of a set by
    about 90 deg x its share of zenith lights. The tables score pan over the lights below
    the zenith (:func:`error_tables`); this gives both parts: ``{"zenith": stats of the
    lights at tilt >= 90, "below_zenith": stats of the rest}``.

    >>> d = pan_where_defined([3.0, 5.0, 120.0], [40.0, 85.0, 90.0])
    >>> d["zenith"]["n"], d["zenith"]["mean"], d["below_zenith"]["n"], d["below_zenith"]["mean"]
    (1, 120.0, 2, 4.0)
    """
    e = np.asarray(pan_error_deg, dtype=np.float64).ravel()
    t = np.asarray(tilt_gt_deg, dtype=np.float64).ravel()
    if e.size != t.size:
        raise ValueError(f"pan_where_defined needs equal lengths, got {e.size} and {t.size}")
    at = t >= ZENITH_TILT_DEG
    return {"zenith": summary_stats(e[at]), "below_zenith": summary_stats(e[~at])}


def format_pan_where_defined(split: dict) -> str:
    """One markdown line for :func:`pan_where_defined` (empty when no light is at the zenith)."""
    z, b = split["zenith"], split["below_zenith"]
    if z["n"] == 0:
        return ""
    n = z["n"] + b["n"]
    everything = (z["mean"] * z["n"] + b["mean"] * b["n"]) / n
    return (f"Pan is undefined for a light at the zenith: {z['n']} of {n} images have true tilt 90 and "
            f"are left out of the pan error (theirs is a guess's, mean {z['mean']:.2f}). Pan over the other "
            f"{b['n']}: mean {b['mean']:.2f}, median {b['median']:.2f}; over all {n} lights: mean "
            f"{everything:.2f}.\n")


def pan_by_tilt(pan_error_deg, tilt_gt_deg, step_deg: float = TILT_STEP_DEG) -> list[dict]:
    """Where a set's mean pan error comes from: one row per true-tilt step.

    Near the zenith a small change of direction is a large change of pan (a light at tilt
    ``t`` moves ``cos t`` times its pan change), so the lights at 80-90 deg can carry most of
    the mean pan error. Tilts are binned to the nearest multiple of ``step_deg`` (SID2
    draws them in 5 deg steps; real data falls into the nearest bin). Each row is
    ``{"tilt_deg": bin centre, "n", "mean", "median", "share"}``, ascending tilt, empty bins
    left out; ``share`` is the bin's error sum over the set's size, its part of the set's
    mean, so the shares add up to the overall mean.

    >>> rows = pan_by_tilt([2.0, 4.0, 30.0, 120.0], [30.0, 32.4, 85.0, 90.0])
    >>> [(r["tilt_deg"], r["n"], r["mean"], r["share"]) for r in rows]
    [(30.0, 2, 3.0, 1.5), (85.0, 1, 30.0, 7.5), (90.0, 1, 120.0, 30.0)]
    """
    e = np.asarray(pan_error_deg, dtype=np.float64).ravel()
    t = np.asarray(tilt_gt_deg, dtype=np.float64).ravel()
    if e.size != t.size:
        raise ValueError(f"pan_by_tilt needs equal lengths, got {e.size} and {t.size}")
    if not step_deg > 0:
        raise ValueError(f"pan_by_tilt needs a positive step, got {step_deg}")
    bins = np.floor(t / step_deg + 0.5) * step_deg
    rows = []
    for b in np.unique(bins):
        s = summary_stats(e[bins == b])
        rows.append({"tilt_deg": float(b), "n": s["n"], "mean": s["mean"], "median": s["median"],
                     "share": float(e[bins == b].sum() / e.size)})
    return rows


def format_pan_by_tilt(rows: list[dict]) -> str:
    """Markdown table of :func:`pan_by_tilt` (empty for no rows)."""
    if not rows:
        return ""
    lines = ["**Pan error by true light tilt (degrees; share = the step's part of the overall mean)**", "",
             "| Tilt | n | Mean | Median | Share of the mean |", "|---:|---:|---:|---:|---:|"]
    lines += [f"| {r['tilt_deg']:g} | {r['n']} | {r['mean']:.2f} | {r['median']:.2f} | {r['share']:.2f} |"
              for r in rows]
    return "\n".join(lines) + "\n"


def _metric_order(group: dict) -> list[str]:
    """Metric names of one group ({metric: stats}), the tables' order first."""
    return [m for m in TABLE_METRICS if m in group] + [m for m in group if m not in TABLE_METRICS]


def _label(metric: str) -> str:
    return METRIC_LABELS.get(metric, metric.capitalize())


def _fmt(x) -> str:
    return "n/a" if not np.isfinite(x) else f"{x:.2f}"


def _table(title: str, key_header: str, groups: dict, stats, key_label) -> list[str]:
    """One markdown table; a group's ``n`` counts all its images, and beside the pan
    column (scored below the zenith) a ``Zenith left out`` column gives the lights it skips."""
    metrics = _metric_order(next(iter(groups.values())))
    columns = [c for m in metrics for c in ((m, ZENITH_KEY) if m == "pan" else (m,))]
    head = (([key_header] if key_header else []) + ["Stat", "n"]
            + ["Zenith left out" if c == ZENITH_KEY else _label(c) for c in columns])
    lines = [f"**{title}**", "", "| " + " | ".join(head) + " |",
             "|" + "|".join(["---"] * (len(head) - len(columns)) + ["---:"] * len(columns)) + "|"]
    for key, group in groups.items():
        n = group[metrics[0]]["n"] + group[metrics[0]].get(ZENITH_KEY, 0) if metrics else 0
        for stat in stats:
            cells = ([key_label(key)] if key_header else []) + [STAT_LABELS.get(stat, stat), str(n)]
            cells += [str(group["pan"].get(ZENITH_KEY, "-")) if c == ZENITH_KEY else _fmt(group[c][stat])
                      for c in columns]
            lines.append("| " + " | ".join(cells) + " |")
    return lines + [""]


def format_tables(tables: dict, stats=("mean", "median"), only_table1: bool = False) -> str:
    """Markdown text of the paper's Tables 1-3 from :func:`error_tables` (degrees, 2 decimals);
    Table 1 alone with ``only_table1`` (what the commands print).

    Table 1: overall (rows: one per stat). Table 2: tilt levels L1..L3 x stat.
    Table 3: pan levels front/right/back/left x stat. Every row shows its n (all the
    group's images); pan is scored below the zenith, with the zenith lights left out
    counted beside it and the all-lights pan as the last column; statistics of empty
    groups print as "n/a".

    >>> t = error_tables({"pan": [2.0]}, tilt_gt_deg=[40.0], pan_rel_gt_deg=[90.0])
    >>> format_tables(t).splitlines()[0]
    '**Table 1. Overall errors (degrees)**'
    """
    for stat in stats:
        if stat not in STAT_LABELS:
            raise ValueError(f"unknown statistic {stat!r}; expected one of {list(STAT_LABELS)}")

    def tilt_label(name):
        lo, hi = TILT_LEVELS[name]
        return f"{name} [{lo:g}, {hi:g}{']' if name == 'L3' else ')'}"

    def pan_label(name):
        lo, hi = PAN_LEVELS[name]
        return f"{name} [{lo:g}, {hi:g})"

    lines = _table("Table 1. Overall errors (degrees)", "", {"all": tables["overall"]},
                   stats, str)
    if only_table1:
        return "\n".join(lines).rstrip()
    lines += _table("Table 2. Errors by light tilt level (degrees)", "Tilt level",
                    tables["tilt_levels"], stats, tilt_label)
    lines += _table("Table 3. Errors by light pan relative to the camera, tilt in [30, 70] "
                    "(degrees)", "Pan level", tables["pan_levels"], stats, pan_label)
    return "\n".join(lines)

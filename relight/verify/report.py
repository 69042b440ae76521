"""Write a compare report folder, all at once or not at all.

Layout of ``REPORT/``::

    index.html        everything in one page (open in a browser)
    figure3.png/.pdf  the paper's Figure 3 layout
    panels/ID.png     (a) | (b) | (c) with a colour bar, one per image
    metrics.csv       one row per image: light errors (deg), image errors, noise floor
    summary.json      statistics, the paper's tables, bad entries, notes
    tables.md         the paper's Tables 1-3 (mean and median) + image errors
    settings.json     the command's settings (to repeat the run)

Everything is written into a temporary folder beside ``REPORT`` and renamed at the
end, so an error leaves no partial report. An existing ``REPORT`` is replaced only if
it is itself a compare report (has a ``settings.json`` of this format).
"""
from __future__ import annotations

__all__ = [
    "REPORT_FORMAT", "summarise", "image_table", "markdown_html", "check_out", "write_report",
    "kinds_table",
]

import csv
import html
import json
import math
import os

import numpy as np

from relight import metrics
from relight.fileio import atomic_folder
from relight.verify import figures
from relight.verify.compare import (ENVMAP_NOTE, IMAGE_METRICS, KINDS, LIGHT_SCORES, STRENGTH_NOTE, CompareError,
                                    Comparison)

REPORT_FORMAT = "relight.compare-report/v1"


def _finite_or_none(x):
    return float(x) if isinstance(x, (int, float, np.floating)) and math.isfinite(x) else None


def _clean(obj):
    """JSON-safe copy: inf/NaN become null (JSON has no such literals)."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return _finite_or_none(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def _image_stats(values) -> dict:
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]  # PSNR of identical images is +inf
    return {"n_finite": int(v.size), "mean": float(v.mean()) if v.size else None,
            "median": float(np.median(v)) if v.size else None}


def _kind_stats(items) -> dict:
    """Per kind of prediction: count, light errors (deg), scores after the fitted scale,
    shadow IoU, and their floors (mean / median)."""
    out = {}
    for kind in KINDS:
        group = [it for it in items if it.kind == kind]
        if not group:
            continue
        d = {"n": len(group)}
        for m in ("direction", "colour"):
            d[f"{m}_error_deg"] = _image_stats([it.light_errors_deg[m] for it in group])
        for m in LIGHT_SCORES:
            d[m] = _image_stats([it.scores.get(m, math.nan) for it in group])
            d[f"noise_{m}"] = _image_stats([it.noise_scores.get(m, math.nan) for it in group])
            d[f"map_floor_{m}"] = _image_stats([it.map_floor.get(m, math.nan) for it in group])
        d["shadow_iou"] = _image_stats([it.shadow_iou for it in group])
        d["map_floor_shadow_iou"] = _image_stats([it.map_floor.get("shadow_iou", math.nan) for it in group])
        d["scale"] = _image_stats([it.scores.get("scale", math.nan) for it in group])
        out[kind] = d
    return out


def kinds_table(summary: dict) -> str:
    """Markdown: point-light and environment-map predictions side by side (means;
    medians of the direction error in brackets)."""
    kinds = summary.get("by_kind") or {}
    if not kinds:
        return ""
    names = {"point": "point light", "envmap": "environment map"}
    lines = ["**Every kind of prediction, side by side** (means; direction median in brackets; "
             "image scores after one fitted global scale; floors: two renders of the true light, "
             "and for maps the true light made a map)", "",
             "| Prediction | n | Direction (deg) | Colour (deg) | rel. RMSE | si-RMSE | RGB angle (deg) "
             "| Shadow IoU | rel. RMSE noise floor | rel. RMSE map floor | Shadow IoU map floor | Scale |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]

    def f(stat, digits=4):
        v = stat["mean"] if stat else None
        return "n/a" if v is None else f"{v:.{digits}f}"
    for kind, d in kinds.items():
        med = d["direction_error_deg"]["median"]
        lines.append(f"| {names.get(kind, kind)} | {d['n']} | {f(d['direction_error_deg'], 2)} "
                     f"({'n/a' if med is None else f'{med:.2f}'}) | {f(d['colour_error_deg'], 2)} | "
                     f"{f(d['rel_rmse'])} | {f(d['si_rmse'])} | {f(d['rgb_angle_deg'], 2)} | "
                     f"{f(d['shadow_iou'], 3)} | {f(d['noise_rel_rmse'])} | {f(d['map_floor_rel_rmse'])} | "
                     f"{f(d['map_floor_shadow_iou'], 3)} | "
                     f"{f(d['scale'], 3)} |")
    return "\n".join(lines) + "\n"


def summarise(comparison: Comparison) -> dict:
    """Statistics of a comparison (degrees for light errors, linear units for images)."""
    items = comparison.items
    errors = {m: np.array([it.light_errors_deg[m] for it in items]) for m in metrics.METRICS}
    tables = metrics.error_tables(errors, [it.gt.tilt_deg for it in items],
                                  [it.gt.pan_rel_deg for it in items])
    image = {m: _image_stats([it.image_errors[m] for it in items]) for m in IMAGE_METRICS}
    noise = {m: _image_stats([it.noise_floor[m] for it in items]) for m in IMAGE_METRICS}
    return {"format": REPORT_FORMAT, "n": len(items), "n_bad": len(comparison.bad),
            "bad": [{"entry": e, "reason": r} for e, r in comparison.bad],
            "dataset": comparison.dataset_dir, "predictions": comparison.predictions_path,
            "light_errors_deg": {m: metrics.summary_stats(errors[m]) for m in metrics.METRICS},
            "image_errors": image, "noise_floor": noise, "tables": tables,
            "by_kind": _kind_stats(items),
            "seconds": comparison.seconds, "render_seconds": comparison.render_seconds,
            "seconds_per_image": comparison.seconds / len(items) if items else None,
            "notes": [STRENGTH_NOTE,
                      "Image errors compare (a) the dataset's linear EXR with (b) the re-render in "
                      "linear space (PSNR peak 1.0, SSIM data range 1.0); the noise floor compares "
                      "(a) with a render under the true light and another seed."]
            + ([ENVMAP_NOTE] if any(it.kind == "envmap" for it in items) else [])}


def image_table(summary: dict) -> str:
    """Markdown table of image errors beside their noise floor (mean and median)."""
    lines = ["**Image errors, (a) original vs (b) re-render, linear; noise floor: two renders "
             "of the true light**", "", "| Stat | RMSE | RMSE floor | PSNR (dB) | PSNR floor | SSIM | SSIM floor |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for stat in ("mean", "median"):
        cells = []
        for m in IMAGE_METRICS:
            for group in ("image_errors", "noise_floor"):
                v = summary[group][m][stat]
                cells.append("n/a" if v is None else f"{v:.4f}" if m != "psnr_db" else f"{v:.2f}")
        lines.append(f"| {stat.capitalize()} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _write_json(path: str, data) -> None:
    with open(path, "w") as f:
        json.dump(_clean(data), f, indent=1, allow_nan=False)


def _write_csv(path: str, rows: list[dict]) -> None:
    with open(path, "w", newline="") as f:
        if not rows:
            return
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        for row in rows:
            writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()})


def _inline(text: str) -> str:
    """Escaped text with markdown's ``**bold**`` and ```code``` as HTML."""
    import re
    t = html.escape(text)
    t = re.sub(r"\*\*(.+?)\*\*", r"<b>\1</b>", t)
    return re.sub(r"`(.+?)`", r"<code>\1</code>", t)


def markdown_html(md: str) -> str:
    """HTML of the report's markdown (tables with their column alignment, bold title
    lines, bullet lists, paragraphs): the subset :mod:`relight.metrics` and this module
    write, so no markdown library is needed."""
    out, lines, i = [], md.splitlines(), 0
    while i < len(lines):
        line = lines[i].strip()
        if line.startswith("|"):
            block = []
            while i < len(lines) and lines[i].strip().startswith("|"):
                block.append([c.strip() for c in lines[i].strip().strip("|").split("|")])
                i += 1
            head, body = block[0], block[1:]
            align = ["right" if c.endswith(":") else "left" for c in body[0]] \
                if body and all(set(c) <= set("-:") and c for c in body[0]) else None
            if align is not None:
                body = body[1:]
            align = align or ["left"] * len(head)
            out.append("<table class='stats'><thead><tr>" + "".join(
                f"<th style='text-align:{a}'>{_inline(c)}</th>" for c, a in zip(head, align))
                + "</tr></thead><tbody>")
            out += ["<tr>" + "".join(f"<td style='text-align:{a}'>{_inline(c)}</td>"
                                     for c, a in zip(row, align)) + "</tr>" for row in body]
            out.append("</tbody></table>")
            continue
        if line.startswith("- "):
            out.append("<ul>")
            while i < len(lines) and lines[i].strip().startswith("- "):
                out.append(f"<li>{_inline(lines[i].strip()[2:])}</li>")
                i += 1
            out.append("</ul>")
            continue
        if line:
            out.append(f"<p>{_inline(line)}</p>")
        i += 1
    return "\n".join(out)


# Click a header of the per-image table to sort by it (again: reverse); numbers sort by
# value (data-v), text alphabetically. The last lines count the images that loaded,
# for a look at the page (and the headless-browser test).
_PAGE_SCRIPT = """
document.querySelectorAll('table.sortable').forEach(function (table) {
  table.querySelectorAll('th').forEach(function (th, col) {
    th.addEventListener('click', function () {
      var body = table.tBodies[0], rows = Array.from(body.rows);
      var dir = th.dataset.dir === 'asc' ? -1 : 1;
      table.querySelectorAll('th').forEach(function (h) { delete h.dataset.dir; });
      th.dataset.dir = dir === 1 ? 'asc' : 'desc';
      function key(r) { var c = r.cells[col]; return c.dataset.v !== undefined ? parseFloat(c.dataset.v) : c.textContent; }
      rows.sort(function (a, b) {
        var x = key(a), y = key(b);
        if (typeof x === 'number' && typeof y === 'number') {
          if (isNaN(x)) return 1; if (isNaN(y)) return -1; return dir * (x - y);
        }
        return dir * String(x).localeCompare(String(y));
      });
      rows.forEach(function (r) { body.appendChild(r); });
    });
  });
});
window.addEventListener('load', function () {
  var imgs = Array.from(document.images);
  var ok = imgs.filter(function (im) { return im.complete && im.naturalWidth > 0; }).length;
  var el = document.getElementById('image-check');
  el.dataset.loaded = ok; el.dataset.total = imgs.length;
  el.textContent = ok + ' of ' + imgs.length + ' images loaded';
});
"""


def _index_html(summary: dict, tables_md: str, rows: list[dict], panel_names: list[str]) -> str:
    esc = html.escape
    out = ["<!doctype html><html><head><meta charset='utf-8'><title>relight compare</title>",
           "<style>body{font-family:sans-serif;margin:2em;max-width:1200px}"
           "table{border-collapse:collapse;font-size:12px;margin-bottom:1em}"
           "td,th{border:1px solid #ccc;padding:2px 6px}"
           "table.sortable th{cursor:pointer;background:#f4f4f4}"
           "table.sortable th[data-dir=asc]::after{content:' \\25B2'}"
           "table.sortable th[data-dir=desc]::after{content:' \\25BC'}"
           "#image-check{color:#888;font-size:11px}"
           "img.panel{width:100%;max-width:900px}</style></head><body>",
           "<h1>relight compare</h1>",
           f"<p>Predictions: <code>{esc(str(summary['predictions']))}</code><br>Dataset: "
           f"<code>{esc(str(summary['dataset']))}</code><br>{summary['n']} images compared, "
           f"{summary['n_bad']} bad entries.</p>",
           "".join(f"<p><i>{esc(n)}</i></p>" for n in summary["notes"]),
           "<p id='image-check'></p>"]
    if panel_names:
        out.append("<h2>Figure 3</h2><p>Rows: (a) original, (b) re-rendered under the predicted "
                   "light, (c) luminance difference; columns from smallest to largest direction "
                   "error (<a href='figure3.pdf'>PDF</a>).</p>"
                   "<img id='figure3' src='figure3.png' alt='Figure 3' style='max-width:100%'>")
    out.append(f"<h2>Tables</h2><p><a href='tables.md'>tables.md</a></p>{markdown_html(tables_md)}")
    if summary["bad"]:
        out.append("<h2>Bad entries (skipped)</h2><ul>")
        out += [f"<li><b>{esc(b['entry'])}</b>: {esc(b['reason'])}</li>" for b in summary["bad"]]
        out.append("</ul>")
    if rows:
        keys = ["id", "direction_error_deg", "colour_error_deg", "pan_error_deg", "tilt_error_deg",
                "rmse", "noise_rmse", "ssim", "noise_ssim", "rel_rmse", "rgb_angle_deg", "shadow_iou", "kind"]
        out.append("<h2>Per image</h2><p><a href='metrics.csv'>metrics.csv</a>; click a column "
                   "header to sort.</p><table class='sortable' id='per-image'><thead><tr>"
                   + "".join(f"<th>{k}</th>" for k in keys) + "</tr></thead><tbody>")
        for row, name in zip(rows, panel_names):
            cells = [f"<td><a href='#{esc(row['id'])}'>{esc(row['id'])}</a></td>"]
            for k in keys[1:]:
                v = row[k]
                if isinstance(v, str):
                    cells.append(f"<td>{esc(v)}</td>")
                    continue
                num = float(v) if isinstance(v, (int, float, np.floating)) else float("nan")
                cells.append(f"<td data-v='{num!r}' style='text-align:right'>{v:.4g}</td>"
                             if math.isfinite(num) else f"<td data-v='NaN'>{esc(str(v))}</td>")
            out.append("<tr>" + "".join(cells) + "</tr>")
        out.append("</tbody></table>")
        for row, name in zip(rows, panel_names):
            out.append(f"<h3 id='{esc(row['id'])}'>{esc(row['id'])}</h3>"
                       f"<img class='panel' src='panels/{esc(name)}' alt='{esc(row['id'])}'>")
    out.append(f"<script>{_PAGE_SCRIPT}</script></body></html>")
    return "\n".join(out)


def _is_report(path: str) -> bool:
    try:
        with open(os.path.join(path, "settings.json")) as f:
            return json.load(f).get("format") == REPORT_FORMAT
    except (OSError, ValueError, AttributeError):
        return False


def check_out(out_dir: str) -> None:
    """Refuse an output path that exists and is not a compare report (before any work)."""
    if os.path.lexists(out_dir) and not _is_report(out_dir):
        raise CompareError(f"{out_dir} exists and is not a relight compare report; "
                           "choose another --out")


def write_report(comparison: Comparison, out_dir: str | os.PathLike, settings: dict,
                 max_columns: int = figures.MAX_COLUMNS, progress: bool = False) -> dict:
    """Write the report folder atomically (temporary folder, then rename); returns the summary."""
    from tqdm import tqdm
    out_dir = os.path.abspath(os.fspath(out_dir))
    check_out(out_dir)
    summary = summarise(comparison)

    def write(tmp):
        items = comparison.items
        rows = [it.row() for it in items]
        os.makedirs(os.path.join(tmp, "panels"))
        names = []
        for it in tqdm(items, desc="panels", unit="img", disable=None if progress else True):
            names.append(f"{it.id}.png")
            figures.save_panel(it, os.path.join(tmp, "panels", names[-1]))
        if items:
            cols = figures.save_figure3(items, [os.path.join(tmp, "figure3.png"),
                                                os.path.join(tmp, "figure3.pdf")], max_columns)
            summary["figure3_ids"] = [items[i].id for i in cols]
        tables_md = (metrics.format_tables(summary["tables"]) + "\n" + image_table(summary)
                     + "\n" + kinds_table(summary) + "\n" + STRENGTH_NOTE + "\n") if items \
            else "No image was compared.\n"
        if comparison.bad:
            tables_md += "\n**Bad entries (skipped)**\n\n" + "".join(
                f"- {e}: {r}\n" for e, r in comparison.bad)
        with open(os.path.join(tmp, "tables.md"), "w") as f:
            f.write(tables_md)
        _write_csv(os.path.join(tmp, "metrics.csv"), rows)
        _write_json(os.path.join(tmp, "summary.json"), summary)
        _write_json(os.path.join(tmp, "settings.json"), {"format": REPORT_FORMAT, **settings})
        with open(os.path.join(tmp, "index.html"), "w") as f:
            f.write(_index_html(_clean(summary), tables_md, rows, names))

    atomic_folder(out_dir, write)
    return summary

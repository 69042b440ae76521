"""Figures of the verifier (matplotlib, Agg backend; no display needed).

* :func:`save_panel`: one image, (a) original | (b) re-render | (c) difference with a
  colour bar.
* :func:`save_figure3`: the layout of the paper's Figure 3: rows (a), (b), (c), then
  the direction and colour errors (degrees) as text rows; columns ordered from smallest
  to largest direction error, at most ``max_columns`` picked evenly across that range.
* :func:`save_spheres_figure`: the paper's Figure 4: per image, the photo (if any),
  diffuse + specular spheres under the ground-truth light and under the prediction.
* :func:`pole_overlay`: the paper's Figure 5: a rendered pole and its cast shadow in
  the image's top-left corner.

Linear images are shown as 8-bit sRGB (:func:`relight.imageio.to_srgb8`). The
difference (c) is the *signed* luminance difference ``Y(b) - Y(a)`` of the linear
images (Rec. 709 weights), on a diverging map whose limits are symmetric.
"""
from __future__ import annotations

__all__ = [
    "DIFF_CMAP", "DIFF_PERCENTILE", "PANEL_DPI", "FIG3_DPI", "MAX_COLUMNS", "luminance_difference",
    "diff_limit", "save_panel", "pick_columns", "save_figure3", "save_spheres_figure", "pole_overlay",
]

import os

import numpy as np

from relight.colour import luminance
from relight.imageio import to_srgb8

DIFF_CMAP = "RdBu_r"
DIFF_PERCENTILE = 99.5        # colour bar limit: this percentile of |c| (robust to fireflies)
PANEL_DPI = 110
FIG3_DPI = 120
MAX_COLUMNS = 8


def _plt():
    import matplotlib
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt
    return plt


def luminance_difference(original: np.ndarray, rerender: np.ndarray) -> np.ndarray:
    """``Y(b) - Y(a)`` of two linear ``(H, W, 3)`` images, shape ``(H, W)``."""
    return luminance(np.asarray(rerender, np.float64) - np.asarray(original, np.float64))


def diff_limit(diffs) -> float:
    """Symmetric colour-bar limit for difference maps (linear units, > 0)."""
    values = np.concatenate([np.abs(np.asarray(d)).ravel() for d in diffs])
    lim = float(np.percentile(values, DIFF_PERCENTILE)) if values.size else 0.0
    return lim if lim > 1e-6 else 1e-3


def _atomic_savefig(fig, path: str, **kw) -> None:
    from relight.fileio import atomic_write
    kw.setdefault("format", os.path.splitext(path)[1].lstrip(".").lower() or "png")
    atomic_write(path, lambda tmp: fig.savefig(tmp, **kw))


def _errors_text(item) -> str:
    e, i, n = item.light_errors_deg, item.image_errors, item.noise_floor
    return (f"direction {e['direction']:.1f}°  colour {e['colour']:.1f}°  pan {e['pan']:.1f}°  "
            f"tilt {e['tilt']:.1f}°\nRMSE {i['rmse']:.4f} (noise floor {n['rmse']:.4f})  "
            f"SSIM {i['ssim']:.3f} (floor {n['ssim']:.3f})")


def save_panel(item, path: str) -> None:
    """(a) | (b) | (c) panel of one :class:`~relight.verify.compare.ImageComparison`."""
    plt = _plt()
    diff = luminance_difference(item.original, item.rerender)
    lim = diff_limit([diff])
    fig, axes = plt.subplots(1, 3, figsize=(9.0, 3.6), constrained_layout=True)
    axes[0].imshow(to_srgb8(item.original))
    axes[0].set_title("(a) original")
    axes[1].imshow(to_srgb8(item.rerender))
    axes[1].set_title("(b) re-rendered, predicted light")
    im = axes[2].imshow(diff, cmap=DIFF_CMAP, vmin=-lim, vmax=lim)
    axes[2].set_title("(c) Y(b) − Y(a), linear")
    fig.colorbar(im, ax=axes[2], shrink=0.8)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    g, p = item.gt, item.pred
    fig.suptitle(f"{item.id}: true pan_rel {g.pan_rel_deg:.0f}° tilt {g.tilt_deg:.0f}°, predicted "
                 f"{p.pan_rel_deg:.0f}° / {p.tilt_deg:.0f}°\n{_errors_text(item)}", fontsize=9)
    _atomic_savefig(fig, path, dpi=PANEL_DPI)
    plt.close(fig)


def pick_columns(direction_errors_deg, max_columns: int = MAX_COLUMNS) -> list[int]:
    """Indices of at most ``max_columns`` items, sorted by direction error (ascending),
    picked evenly across the sorted range (always the smallest and the largest)."""
    order = np.argsort(np.asarray(direction_errors_deg, dtype=np.float64), kind="stable")
    if len(order) <= max_columns:
        return [int(i) for i in order]
    picks = np.unique(np.round(np.linspace(0, len(order) - 1, max_columns)).astype(int))
    return [int(order[i]) for i in picks]


def save_figure3(items, paths: list[str], max_columns: int = MAX_COLUMNS, title: str | None = None,
                 dpi: int = FIG3_DPI) -> list[int]:
    """The paper's Figure 3 layout for compared items, saved to each of ``paths``
    (format from the extension, e.g. .png and .pdf; ``dpi`` for raster formats).
    Returns the chosen item indices."""
    plt = _plt()
    if not items:
        raise ValueError("save_figure3 needs at least one compared image")
    cols = pick_columns([it.light_errors_deg["direction"] for it in items], max_columns)
    diffs = [luminance_difference(items[i].original, items[i].rerender) for i in cols]
    lim = diff_limit(diffs)
    n = len(cols)
    fig = plt.figure(figsize=(1.45 * n + 1.4, 5.6))
    grid = fig.add_gridspec(5, n + 1, height_ratios=[1, 1, 1, 0.22, 0.22],
                            width_ratios=[1] * n + [0.08], hspace=0.06, wspace=0.04,
                            left=0.1, right=0.93, top=0.9 if title else 0.97, bottom=0.02)
    labels = ["(a)", "(b)", "(c)", "Direction", "Colour"]
    image = None
    for c, (i, diff) in enumerate(zip(cols, diffs)):
        it = items[i]
        for r, content in enumerate((to_srgb8(it.original), to_srgb8(it.rerender), diff)):
            ax = fig.add_subplot(grid[r, c])
            if r < 2:
                ax.imshow(content)
            else:
                image = ax.imshow(content, cmap=DIFF_CMAP, vmin=-lim, vmax=lim)
            ax.set_xticks([])
            ax.set_yticks([])
            if c == 0:
                ax.set_ylabel(labels[r], rotation=0, ha="right", va="center", fontsize=10)
        for r, key in ((3, "direction"), (4, "colour")):
            ax = fig.add_subplot(grid[r, c])
            ax.axis("off")
            ax.text(0.5, 0.5, f"{it.light_errors_deg[key]:.2f}", ha="center", va="center", fontsize=10)
            if c == 0:
                ax.text(-0.06, 0.5, labels[r], ha="right", va="center", fontsize=10,
                        transform=ax.transAxes)
    cax = fig.add_subplot(grid[2, n])
    fig.colorbar(image, cax=cax)
    cax.tick_params(labelsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    for path in paths:
        _atomic_savefig(fig, path, dpi=dpi)
    plt.close(fig)
    return cols


def save_spheres_figure(rows: list[dict], path: str) -> None:
    """Paper Figure 4 layout, one column per image.

    Each row dict: ``id``, ``image`` (linear (H, W, 3) or None), ``gt_spheres`` and
    ``pred_spheres`` (linear (h, 2h, 3): diffuse | specular, or None), ``errors``
    (dict with "direction" and "colour" in degrees, or None).
    Rows of the figure: (a) image, (b) ground-truth spheres, (c) predicted spheres,
    Direction and Colour errors.
    """
    plt = _plt()
    n = len(rows)
    if n == 0:
        raise ValueError("save_spheres_figure needs at least one image")
    fig = plt.figure(figsize=(2.2 * n + 1.0, 5.4))
    grid = fig.add_gridspec(5, n, height_ratios=[1.6, 0.8, 0.8, 0.2, 0.2], hspace=0.08, wspace=0.05,
                            left=0.1, right=0.99, top=0.95, bottom=0.02)
    labels = ["(a)", "(b) GT", "(c) pred.", "Direction", "Colour"]
    for c, row in enumerate(rows):
        for r, key in enumerate(("image", "gt_spheres", "pred_spheres")):
            ax = fig.add_subplot(grid[r, c])
            ax.set_xticks([])
            ax.set_yticks([])
            if row.get(key) is not None:
                ax.imshow(to_srgb8(row[key]))
            else:
                ax.text(0.5, 0.5, "n/a", ha="center", va="center", transform=ax.transAxes)
            if r == 0:
                ax.set_title(str(row["id"]), fontsize=8)
            if c == 0:
                ax.set_ylabel(labels[r], rotation=0, ha="right", va="center", fontsize=9)
        for r, key in ((3, "direction"), (4, "colour")):
            ax = fig.add_subplot(grid[r, c])
            ax.axis("off")
            errs = row.get("errors")
            ax.text(0.5, 0.5, "n/a" if errs is None else f"{errs[key]:.2f}", ha="center",
                    va="center", fontsize=9)
            if c == 0:
                ax.text(-0.06, 0.5, labels[r], ha="right", va="center", fontsize=9, transform=ax.transAxes)
    _atomic_savefig(fig, path, dpi=FIG3_DPI)
    plt.close(fig)


def pole_overlay(image: np.ndarray, pan_rel_deg: float, tilt_deg: float, rgb,
                 camera_tilt_deg: float, spp: int = 64) -> np.ndarray:
    """A linear ``(H, W, 3)`` image with a pole and its shadow under the given light
    rendered into its top-left corner (inset about a third of the shorter side)."""
    from relight.verify import spheres
    h, w = image.shape[:2]
    size = int(np.clip(min(h, w) // 3, 32, 256))
    inset = spheres.pole_inset(pan_rel_deg, tilt_deg, rgb, camera_tilt_deg, res=size, spp=spp)
    return spheres.overlay_pole(image, inset)

"""Classical colour-constancy baselines: the illuminant colour from image statistics.

All methods take a *linear* ``(H, W, 3)`` image (EXR, or sRGB decoded to linear) and
return the estimated light colour as a unit-norm linear RGB vector; they know nothing
about direction. They are the methods the paper's colour evaluation is compared with:

* Gray World (Buchsbaum 1980): the mean of each channel, ``e_c = mean(I_c)``.
* White Patch / max-RGB (Land 1977): the maximum of each channel.
* Shades of Gray (Finlayson & Trezzi 2004): the Minkowski p-norm mean,
  ``e_c = (mean(I_c^p))^(1/p)``; p = 1 is Gray World, p = inf is White Patch;
  the usual choice p = 6 is our default.
* Gray Edge (van de Weijer, Gevers & Gijsenij 2007): the Minkowski p-norm of the
  gradient magnitude of the Gaussian-smoothed image,
  ``e_c = (mean(|grad G_sigma * I_c|^p))^(1/p)``, first order, p = 6, sigma = 1 px.

Non-finite or negative pixels are excluded (a pixel is used only if all three
channels are finite and >= 0). An image with no usable signal raises
:class:`ColourBaselineError`.

Predictions files: these methods give no direction, and ``relight.predictions/v1``
entries must carry pan/tilt or ``y``. :func:`write_colour_predictions` writes the same
format with a top-level ``"colour_only": true`` and entries ``{"id", "rgb"}``; reading
it with :func:`relight.predictions.read_predictions` needs the small change described
in :func:`write_colour_predictions`; :func:`read_colour_predictions` reads it today.
"""
from __future__ import annotations

__all__ = [
    "SHADES_OF_GRAY_P", "GRAY_EDGE_P", "GRAY_EDGE_SIGMA_PX", "ColourBaselineError", "minkowski_mean",
    "gray_world", "white_patch", "shades_of_gray", "gray_edge", "METHODS", "estimate", "estimate_jobs",
    "dataset_colour_errors", "write_colour_predictions", "read_colour_predictions",
]

import math

import numpy as np

from relight.predictions import PredictionsError, read_predictions, write_predictions

SHADES_OF_GRAY_P = 6.0
GRAY_EDGE_P = 6.0
GRAY_EDGE_SIGMA_PX = 1.0


class ColourBaselineError(PredictionsError):
    """A colour baseline cannot estimate a colour from this image (one-line reason)."""


def _pixels(image: np.ndarray) -> np.ndarray:
    """Usable pixels ``(N, 3)`` float64 of a linear image."""
    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 3 or img.shape[2] != 3:
        raise ColourBaselineError(f"expected an (H, W, 3) linear image, got shape {img.shape}")
    px = img.reshape(-1, 3)
    ok = np.all(np.isfinite(px) & (px >= 0), axis=1)
    if not ok.any():
        raise ColourBaselineError("no finite, non-negative pixels in the image")
    return px[ok]


def _unit(e: np.ndarray, method: str) -> np.ndarray:
    e = np.asarray(e, dtype=np.float64)
    norm = float(np.linalg.norm(e))
    if not math.isfinite(norm) or norm <= 0:
        raise ColourBaselineError(f"{method}: the image has no signal to estimate a colour from")
    return e / norm


def minkowski_mean(values: np.ndarray, p: float) -> np.ndarray:
    """Per-column ``(mean(v^p))^(1/p)`` of non-negative ``(N, C)`` values; p = inf is the
    max. Computed on values scaled by their max, so large p does not overflow."""
    if not p >= 1:
        raise ValueError(f"Minkowski p must be >= 1 (or inf), got {p}")
    v = np.asarray(values, dtype=np.float64)
    top = v.max(axis=0)
    if math.isinf(p):
        return top
    scale = np.where(top > 0, top, 1.0)
    return scale * np.mean((v / scale) ** p, axis=0) ** (1.0 / p)


def gray_world(image: np.ndarray) -> np.ndarray:
    """Gray World: unit-norm per-channel mean of a linear image."""
    return _unit(_pixels(image).mean(axis=0), "gray-world")


def white_patch(image: np.ndarray) -> np.ndarray:
    """White Patch (max-RGB): unit-norm per-channel maximum of a linear image."""
    return _unit(_pixels(image).max(axis=0), "white-patch")


def shades_of_gray(image: np.ndarray, p: float = SHADES_OF_GRAY_P) -> np.ndarray:
    """Shades of Gray: unit-norm per-channel Minkowski p-mean (p >= 1, inf allowed)."""
    return _unit(minkowski_mean(_pixels(image), p), "shades-of-gray")


def gray_edge(image: np.ndarray, p: float = GRAY_EDGE_P, sigma_px: float = GRAY_EDGE_SIGMA_PX) -> np.ndarray:
    """Gray Edge (first order): unit-norm Minkowski p-mean of each channel's gradient
    magnitude after Gaussian smoothing with ``sigma_px`` pixels (0 = plain differences)."""
    from scipy import ndimage
    img = np.asarray(image, dtype=np.float64)
    _pixels(img)  # shape and content check
    ok = np.all(np.isfinite(img) & (img >= 0), axis=2)
    img = np.where(ok[..., None], img, 0.0)
    mags = []
    for c in range(3):
        if sigma_px > 0:
            mag = ndimage.gaussian_gradient_magnitude(img[..., c], sigma=sigma_px, mode="nearest")
        else:
            gy, gx = np.gradient(img[..., c])
            mag = np.hypot(gx, gy)
        mags.append(mag[ok])
    return _unit(minkowski_mean(np.stack(mags, axis=1), p), "gray-edge")


METHODS = {
    "gray-world": gray_world,
    "white-patch": white_patch,
    "shades-of-gray": shades_of_gray,
    "gray-edge": gray_edge,
}


def estimate(name: str, image: np.ndarray) -> np.ndarray:
    """Run the baseline ``name`` (one of :data:`METHODS`) on a linear image."""
    try:
        method = METHODS[name]
    except KeyError:
        raise ColourBaselineError(f"unknown colour baseline {name!r}; valid: {', '.join(METHODS)}") from None
    return method(image)


def estimate_jobs(name: str, jobs: list, progress: bool = True, scheduler=None) -> list[dict]:
    """Colour-only predictions entries ``{"id", "rgb"}`` of ``name`` on each job's image
    (:class:`relight.inverse.jobs.Job`), in job order. ``scheduler``: estimate shards of
    images on Dask (``local:N`` or an address, :mod:`relight.engine`); the same entries."""
    from tqdm import tqdm
    if name not in METHODS:
        raise ColourBaselineError(f"unknown colour baseline {name!r}; valid: {', '.join(METHODS)}")
    paths = [(job.id, job.image_path) for job in jobs]
    if scheduler is None:
        return [_entry(name, *p) for p in tqdm(paths, desc=name, unit="img",
                                               disable=not progress or len(paths) < 50)]
    from relight import engine
    return engine.map_ordered(scheduler, _estimate_shard, (name, paths), len(paths), name,
                              engine.ShardPlan(mitsuba=False, progress=progress), bar=len(paths) >= 50)


def dataset_colour_errors(entries: list[dict], data_dir: str) -> np.ndarray:
    """Colour error in degrees (:func:`relight.metrics.colour_error_deg`) of each entry
    ``{"id", "rgb"}`` whose record in ``data_dir``'s manifest has a light colour, in entry
    order (empty when none has)."""
    from relight.dataset import read_manifest
    from relight.metrics import colour_error_deg
    truth = {r["id"]: (r.get("light") or {}).get("rgb") for r in read_manifest(data_dir)}
    known = [e for e in entries if truth.get(e["id"]) is not None]
    if not known:
        return np.zeros(0)
    return colour_error_deg([e["rgb"] for e in known], [truth[e["id"]] for e in known])


def _entry(name: str, image_id: str, image_path: str) -> dict:
    from relight.imageio import read_image
    return {"id": image_id, "rgb": [float(c) for c in estimate(name, read_image(image_path)[0])]}


def _estimate_shard(context, shard: list[int]) -> list[dict]:
    """Engine task (in a worker process): the entries of images ``shard``."""
    name, paths = context
    return [_entry(name, *paths[k]) for k in shard]


# --- colour-only predictions files ---------------------------------------------------

def write_colour_predictions(path, entries: list[dict], dataset: str | None = None, **meta) -> None:
    """Write colour-only predictions atomically (``relight.predictions/v1`` with
    ``"colour_only": true``, entries ``{"id", "rgb"}``)."""
    write_predictions(path, entries, dataset=dataset, colour_only=True, **meta)


def read_colour_predictions(path) -> dict[str, np.ndarray]:
    """``{id: unit rgb}`` of a predictions file, colour-only or full (direction ignored)."""
    pfile = read_predictions(path)
    out = {}
    for p in pfile.predictions:
        rgb = np.asarray(p.y[4:7] if p.y is not None else p.rgb, dtype=np.float64)
        out[p.id] = rgb / np.linalg.norm(rgb)
    return out

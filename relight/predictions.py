"""Predictions files, formats ``relight.predictions/v1`` and ``/v2`` (see docs/conventions.md).

``v2`` is ``v1`` plus environment-map predictions: an entry may carry ``envmap`` (an
equirectangular linear-RGB EXR, path relative to the predictions file), ``envmap_frame``
(``camera`` or ``world``) and an optional ``envmap_scale`` instead of, or beside, the
point light. A v1 file reads exactly as before (in v1 those keys are unknown extras);
:func:`write_predictions` writes v1 unless an entry carries a map.

A prediction gives either ``pan_deg`` (= pan_rel, the light pan relative to the camera)
+ ``tilt_deg`` (light elevation) + ``rgb``, or the raw 7-vector ``y`` (decoded with the
camera tilt of the image it belongs to). A file with ``"colour_only": true`` (the
colour-constancy baselines) has entries with ``id`` and ``rgb`` only; its direction is
unknown and consumers that need one take the ground truth's and say so. :func:`read_predictions` validates the whole
file and raises :class:`PredictionsError` with one line naming the bad entry; with
``skip_bad`` it returns the bad entries separately instead.
"""
from __future__ import annotations

__all__ = ["resolve_dataset_dir", 
    "PREDICTIONS_FORMAT", "Prediction", "parse_entry", "PredictionsFile", "read_predictions",
    "write_predictions", "entry_for_image",
]

import json
import math
import os
from dataclasses import dataclass, field, replace

import numpy as np

from relight import frames
from relight.errors import PredictionsError

PREDICTIONS_FORMAT = "relight.predictions/v1"
PREDICTIONS_FORMAT_V2 = "relight.predictions/v2"   # v1 + environment maps
PREDICTIONS_FORMATS = (PREDICTIONS_FORMAT, PREDICTIONS_FORMAT_V2)
ENVMAP_KEYS = ("envmap", "envmap_frame", "envmap_scale")
ENVMAP_FRAMES = frames.ENVMAP_FRAMES


@dataclass(frozen=True)
class Prediction:
    """One validated entry. At most one of (pan_deg, tilt_deg, rgb) or y is set; an
    environment-map entry (v2) has ``envmap`` (absolute path once read from a file),
    ``envmap_frame`` and ``envmap_scale`` and may have neither."""
    id: str
    pan_deg: float | None = None
    tilt_deg: float | None = None
    rgb: tuple[float, float, float] | None = None
    y: tuple[float, ...] | None = None
    extra: dict = field(default_factory=dict, compare=False)
    envmap: str | None = None
    envmap_frame: str = "camera"
    envmap_scale: float = 1.0

    @property
    def colour_only(self) -> bool:
        """True for an entry without a direction (a colour-constancy baseline)."""
        return self.y is None and self.pan_deg is None and self.envmap is None

    def camera_tilt(self, default: float) -> float:
        """The camera tilt this entry's estimator used (its ``camera_tilt_deg``: a finite
        number of degrees in (-90, 90)), else ``default``."""
        tilt = self.extra.get("camera_tilt_deg")
        if isinstance(tilt, (int, float)) and not isinstance(tilt, bool) and math.isfinite(tilt) and abs(tilt) < 90:
            return float(tilt)
        return float(default)

    @property
    def has_point_light(self) -> bool:
        """True when the entry gives a point light (angles or ``y``)."""
        return self.y is not None or self.pan_deg is not None

    def resolve(self, camera_tilt_deg: float, direction_if_missing=None) -> tuple[float, float, np.ndarray]:
        """``(pan_rel_deg, tilt_deg, rgb unit norm)``; ``y`` needs the camera tilt.
        A colour-only entry takes ``direction_if_missing`` = (pan_rel_deg, tilt_deg)."""
        if self.envmap is not None and not self.has_point_light:
            raise PredictionsError(f"entry {self.id!r}: an environment-map prediction has no point "
                                   "light here (relight envmap to-light gives its dominant light)")
        if self.colour_only:
            if direction_if_missing is None:
                raise PredictionsError(f"entry {self.id!r}: colour-only prediction has no direction")
            pan, tilt = (float(v) for v in direction_if_missing)
            rgb = self.rgb
        elif self.y is not None:
            pan, tilt, rgb = frames.decode_y(np.asarray(self.y), camera_tilt_deg, 0.0)
            pan, tilt = float(pan), float(tilt)
        else:
            pan, tilt, rgb = float(frames.wrap360(self.pan_deg)), float(self.tilt_deg), np.asarray(self.rgb)
        rgb = np.asarray(rgb, dtype=np.float64)
        if np.isfinite(rgb).all() and rgb.max() > 0:
            rgb = rgb / rgb.max()   # no overflow in the norm of huge values
        norm = np.linalg.norm(rgb)
        if not np.isfinite(norm) or norm <= 0 or (rgb < 0).any():
            raise PredictionsError(f"entry {self.id!r}: rgb must be non-negative and non-zero, got {rgb.tolist()}")
        return pan, tilt, rgb / norm


def _finite_list(value, n: int, what: str, entry: str) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise PredictionsError(f"entry {entry}: {what} must be a list of {n} numbers, got {value!r}")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise PredictionsError(f"entry {entry}: {what} must hold finite numbers, got {value!r}")
        out.append(float(v))
    return tuple(out)


def _optional_number(extra: dict, key: str, entry: str, lo: float, hi: float, nullable: bool,
                     open_lo: bool = False) -> None:
    if key not in extra or (nullable and extra[key] is None):
        return
    v = extra[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
            or not (lo < v if open_lo else lo <= v) or v > hi:
        null = " or null" if nullable else ""
        raise PredictionsError(f"entry {entry}: {key} must be a number in {'(' if open_lo else '['}{lo:g}, {hi:g}]"
                               f"{null}, got {v!r}")


def _check_optional(extra: dict, entry: str) -> None:
    """The optional fields of the conventions: ``cone90_deg`` in (0, 180], ``kappa`` > 0,
    ``cct_k`` in [1000, 25000] K and ``duv`` in [-0.05, 0.05], both null or neither;
    relight's ``colour_reliable`` a boolean."""
    _optional_number(extra, "cone90_deg", entry, 0.0, 180.0, False, open_lo=True)
    _optional_number(extra, "kappa", entry, 0.0, math.inf, False, open_lo=True)
    _optional_number(extra, "cct_k", entry, 1000.0, 25000.0, True)
    _optional_number(extra, "duv", entry, -0.05, 0.05, True)
    if ("cct_k" in extra) != ("duv" in extra) or (extra.get("cct_k") is None) != (extra.get("duv") is None):
        raise PredictionsError(f"entry {entry}: cct_k and duv go together (both numbers or both null)")
    if "colour_reliable" in extra and not isinstance(extra["colour_reliable"], bool):
        raise PredictionsError(f"entry {entry}: colour_reliable must be true or false, "
                               f"got {extra['colour_reliable']!r}")


def _envmap_fields(raw: dict, entry: str) -> dict:
    """The validated environment-map fields of a v2 entry (empty without ``envmap``)."""
    if "envmap" not in raw:
        stray = [k for k in ENVMAP_KEYS if k in raw]
        if stray:
            raise PredictionsError(f"entry {entry}: {', '.join(stray)} without envmap")
        return {}
    path = raw["envmap"]
    if not isinstance(path, str) or not path.strip() or "\0" in path:
        raise PredictionsError(f"entry {entry}: envmap must be a path string, got {path!r}")
    frame = raw.get("envmap_frame", "camera")
    if frame not in ENVMAP_FRAMES:
        raise PredictionsError(f"entry {entry}: envmap_frame must be one of {', '.join(ENVMAP_FRAMES)}, "
                               f"got {frame!r}")
    scale = raw.get("envmap_scale", 1.0)
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not math.isfinite(scale) \
            or scale <= 0:
        raise PredictionsError(f"entry {entry}: envmap_scale must be a positive finite number, got {scale!r}")
    return {"envmap": path, "envmap_frame": frame, "envmap_scale": float(scale)}


def parse_entry(raw, index: int, colour_only: bool = False, version: int = 1) -> Prediction:
    """Validate one raw JSON entry (``index`` is its position, for messages); with
    ``colour_only`` the entry needs only ``id`` and ``rgb``; ``version`` 2 reads the
    environment-map fields (an entry may then carry a map and no point light)."""
    if not isinstance(raw, dict):
        raise PredictionsError(f"entry #{index}: expected a JSON object, got {type(raw).__name__}")
    pid = raw.get("id")
    if not isinstance(pid, str) or not pid:
        raise PredictionsError(f"entry #{index}: missing or non-string 'id'")
    name = f"#{index} (id {pid!r})"
    if "/" in pid or "\\" in pid or pid in (".", "..") or "\0" in pid:
        raise PredictionsError(f"entry {name}: id must be a plain name, not a path")
    env = _envmap_fields(raw, name) if version >= 2 and not colour_only else {}
    extra = {k: v for k, v in raw.items() if k not in ("id", "pan_deg", "tilt_deg", "rgb", "y")
             and not (env and k in ENVMAP_KEYS)}
    _check_optional(extra, name)
    if env and not any(k in raw for k in ("pan_deg", "tilt_deg", "rgb", "y")):
        return Prediction(id=pid, extra=extra, **env)
    if colour_only:
        if "rgb" not in raw:
            raise PredictionsError(f"entry {name}: missing rgb")
        rgb = _finite_list(raw["rgb"], 3, "rgb", name)
        if min(rgb) < 0 or max(rgb) <= 0:
            raise PredictionsError(f"entry {name}: rgb must be non-negative and non-zero, got {list(rgb)}")
        return Prediction(id=pid, rgb=rgb, extra=extra)
    if "y" in raw:
        y = _finite_list(raw["y"], frames.Y_SIZE, "y", name)
        rgb = y[4:7]
        if min(rgb) < 0 or max(rgb) <= 0:
            raise PredictionsError(f"entry {name}: rgb part of y must be non-negative and non-zero")
        if y[0] == 0 and y[1] == 0 or y[2] == 0 and y[3] == 0:
            raise PredictionsError(f"entry {name}: a sin/cos pair of y is (0, 0): no angle")
        return Prediction(id=pid, y=y, extra=extra, **env)
    missing = [k for k in ("pan_deg", "tilt_deg", "rgb") if k not in raw]
    if missing:
        raise PredictionsError(f"entry {name}: missing {', '.join(missing)} (or give 'y')")
    pan, tilt = _finite_list([raw["pan_deg"], raw["tilt_deg"]], 2, "pan_deg/tilt_deg", name)
    rgb = _finite_list(raw["rgb"], 3, "rgb", name)
    if min(rgb) < 0 or max(rgb) <= 0:
        raise PredictionsError(f"entry {name}: rgb must be non-negative and non-zero, got {list(rgb)}")
    if not -90.0 <= tilt <= 90.0:
        raise PredictionsError(f"entry {name}: tilt_deg must be in [-90, 90], got {tilt}")
    return Prediction(id=pid, pan_deg=pan, tilt_deg=tilt, rgb=rgb, extra=extra, **env)


@dataclass
class PredictionsFile:
    predictions: list[Prediction]
    dataset: str | None = None
    bad: list[tuple[str, str]] = field(default_factory=list)  # (entry, reason) when skip_bad
    meta: dict = field(default_factory=dict)
    colour_only: bool = False


def read_predictions(path: str | os.PathLike, skip_bad: bool = False) -> PredictionsFile:
    """Read and validate a predictions file. Duplicated ids are errors.

    Args:
        path: a ``relight.predictions/v1`` JSON file (``docs/conventions.md``).
        skip_bad: collect malformed entries in ``bad`` instead of raising.

    Returns:
        A :class:`PredictionsFile`: the validated :class:`Prediction` entries (angles in
        degrees, pan relative to the camera; linear unit-norm ``rgb``, or the raw ``y``),
        the ``dataset`` folder if named, and the file's other fields in ``meta``.

    Raises:
        PredictionsError naming the file and the entry.

    >>> import os, tempfile
    >>> tmp = tempfile.TemporaryDirectory()
    >>> path = os.path.join(tmp.name, "pred.json")
    >>> write_predictions(path, [{"id": "000003", "pan_deg": 90.0, "tilt_deg": 40.0, "rgb": [1.0, 0.9, 0.8]}])
    >>> p = read_predictions(path).predictions[0]
    >>> p.id, p.pan_deg, p.tilt_deg
    ('000003', 90.0, 40.0)
    >>> tmp.cleanup()
    """
    path = os.fspath(path)
    try:
        with open(path) as f:
            data = json.load(f)
    except OSError as exc:
        raise PredictionsError(f"cannot read predictions file {path}: {exc.strerror}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise PredictionsError(f"{path}: malformed JSON ({exc})") from None
    if not isinstance(data, dict) or data.get("format") not in PREDICTIONS_FORMATS:
        got = data.get("format") if isinstance(data, dict) else type(data).__name__
        raise PredictionsError(f"{path}: expected format {PREDICTIONS_FORMAT!r} or "
                               f"{PREDICTIONS_FORMAT_V2!r}, got {got!r}")
    version = 2 if data["format"] == PREDICTIONS_FORMAT_V2 else 1
    entries = data.get("predictions")
    if not isinstance(entries, list):
        raise PredictionsError(f"{path}: 'predictions' must be a list")
    colour_only = data.get("colour_only", False)
    if not isinstance(colour_only, bool):
        raise PredictionsError(f"{path}: 'colour_only' must be true or false")
    dataset = data.get("dataset")
    if dataset is not None and not isinstance(dataset, str):
        raise PredictionsError(f"{path}: 'dataset' must be a path string")
    out = PredictionsFile(predictions=[], dataset=dataset,
                          meta={k: v for k, v in data.items() if k not in ("format", "predictions", "dataset")},
                          colour_only=colour_only)
    seen = set()
    for i, raw in enumerate(entries):
        try:
            p = parse_entry(raw, i, colour_only, version)
            if p.id in seen:
                raise PredictionsError(f"entry #{i} (id {p.id!r}): duplicate id")
            seen.add(p.id)
            if p.envmap is not None:   # relative to the predictions file's folder
                p = replace(p, envmap=os.path.join(os.path.dirname(os.path.abspath(path)), p.envmap))
            out.predictions.append(p)
        except PredictionsError as exc:
            if not skip_bad:
                raise PredictionsError(f"{path}: {exc}") from None
            out.bad.append((f"#{i}", str(exc)))
    return out


def write_predictions(path: str | os.PathLike, entries: list[dict], dataset: str | None = None,
                      colour_only: bool = False, inputs=(), transaction=None, **meta) -> None:
    """Write a predictions file atomically. Each entry: ``{"id", "pan_deg", "tilt_deg",
    "rgb"}`` or ``{"id", "y"}`` (extra keys are kept), or ``{"id", "rgb"}`` with
    ``colour_only``; any of them may carry ``envmap`` (+ ``envmap_frame``, ``envmap_scale``;
    the path relative to the file), and then the file is ``relight.predictions/v2``
    (else v1). Entries are validated first (ids unique). The file is refused if it
    is one of ``inputs`` or inside ``dataset``'s own files; with a
    :class:`relight.fileio.Transaction` it is staged there instead of written.

    Args:
        path: the file to write (``relight.predictions/v1``).
        entries: dicts as above: angles in degrees (pan relative to the camera, 0 front,
            90 the camera's right), ``rgb`` linear (any positive scale).
        dataset: the dataset folder the ids belong to (recorded in the file).
        colour_only: the entries carry a colour and no direction.
        inputs: files the output must not overwrite; ``transaction``: stage the write.
        **meta: other top-level fields (e.g. ``model``).

    Returns:
        None; the file is complete or untouched (atomic rename).

    >>> import json, os, tempfile
    >>> tmp = tempfile.TemporaryDirectory()
    >>> path = os.path.join(tmp.name, "pred.json")
    >>> write_predictions(path, [{"id": "a", "pan_deg": 10.0, "tilt_deg": 50.0, "rgb": [1, 1, 1]}], model="demo")
    >>> doc = json.load(open(path))
    >>> doc["format"], doc["model"], len(doc["predictions"])
    ('relight.predictions/v1', 'demo', 1)
    >>> tmp.cleanup()
    """
    seen = set()
    version = 2 if any(isinstance(e, dict) and "envmap" in e for e in entries) else 1
    for i, e in enumerate(entries):
        p = parse_entry(e, i, colour_only, version)
        if p.id in seen:
            raise PredictionsError(f"entry #{i} (id {p.id!r}): duplicate id")
        seen.add(p.id)
    doc = {"format": PREDICTIONS_FORMAT_V2 if version == 2 else PREDICTIONS_FORMAT}
    if colour_only:
        doc["colour_only"] = True
    if dataset is not None:
        doc["dataset"] = os.fspath(dataset)
    doc.update(meta)
    doc["predictions"] = entries
    from relight.fileio import atomic_write

    def write(tmp):
        with open(tmp, "w") as f:
            json.dump(doc, f, indent=1)
    inputs = list(inputs) + ([dataset] if dataset is not None else [])
    if transaction is not None:
        from relight.fileio import check_outputs
        check_outputs([path], inputs)
        transaction.stage(path, write)
    else:
        atomic_write(path, write, inputs)


def entry_for_image(predictions, image_path: str, wanted_id: str | None):
    """The entry to draw: ``wanted_id``, the only entry, or the one named like the image."""
    if wanted_id is not None:
        found = [p for p in predictions if p.id == wanted_id]
        if not found:
            raise PredictionsError(f"no entry with id {wanted_id!r}")
        return found[0]
    if len(predictions) == 1:
        return predictions[0]
    stem = os.path.splitext(os.path.basename(image_path))[0]
    found = [p for p in predictions if p.id == stem]
    if not found:
        raise PredictionsError(f"{len(predictions)} entries and none has id {stem!r}; choose one with --id")
    return found[0]


def resolve_dataset_dir(predictions_path: str, data_dir: str | None, file_dataset: str | None) -> str:
    """The dataset folder: ``data_dir`` if given, else the file's ``dataset`` field
    (a relative path is tried against the predictions file's folder, then the cwd)."""
    if data_dir:
        return os.path.abspath(data_dir)
    if not file_dataset:
        raise PredictionsError(f"{predictions_path}: no dataset given (use --data DIR or a "
                           "'dataset' field in the file)")
    if os.path.isabs(file_dataset):
        return file_dataset
    beside = os.path.join(os.path.dirname(os.path.abspath(predictions_path)), file_dataset)
    return os.path.abspath(beside if os.path.isdir(beside) else file_dataset)

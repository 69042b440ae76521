"""``relight probe --folder DIR --circles CSV``: the sphere procedure on a folder of
photographs (a multi-illumination capture: the same probes under many lights), with
each image's circles from a CSV file.

The CSV has a header row. Columns (``image`` required, the rest optional, in any order):

* ``image``: the file name, relative to the folder;
* ``chrome_cx, chrome_cy, chrome_r``: the chrome sphere's circle in pixels (all three or
  none; none: found automatically);
* ``diffuse_cx, diffuse_cy, diffuse_r``: a diffuse sphere in the same image (all three or
  none; none: no diffuse sphere is used);
* ``id``: the prediction id (default: the file name without its extension).

Every row is checked before any image is measured; a bad row, or an image the procedure
cannot measure, stops the run with one line naming the CSV row and the file, and nothing
is written.

A fixed probe (``fixed_probe``, ``--fixed-probe``): where one camera photographs one chrome
sphere under many lights, the sphere stands in the same place in every image. The chrome
sphere is then found automatically in every row without a chrome circle, and the circle
most of those detections agree on (:func:`consensus_circle`) is given to each of them: a
detection the image cannot support (an outline dark against a dark background, a lens
flare taken for the sphere) no longer decides its image's light.
"""
from __future__ import annotations

import csv
import dataclasses
import math
import os

import numpy as np

from relight.errors import ProbeError

__all__ = [
    "AGREE_FRACTION",
    "COLUMNS",
    "BatchRow",
    "consensus_circle",
    "read_circles",
    "run_batch",
]

AGREE_FRACTION = 0.05   # a fixed probe: detected circles agree when centres and radii lie within 5% of the radius
COLUMNS = ("image", "id", "chrome_cx", "chrome_cy", "chrome_r", "diffuse_cx", "diffuse_cy", "diffuse_r")


@dataclasses.dataclass(frozen=True)
class BatchRow:
    """One image of a batch: its CSV row number (the header is row 1), path, id, circles."""
    row: int
    path: str
    ident: str
    chrome_circle: tuple[float, float, float] | None
    diffuse_circle: tuple[float, float, float] | None


def _circle(record: dict, kind: str, where: str):
    names = [f"{kind}_cx", f"{kind}_cy", f"{kind}_r"]
    texts = [(record.get(n) or "").strip() for n in names]
    if not any(texts):
        return None
    if not all(texts):
        missing = ", ".join(n for n, t in zip(names, texts) if not t)
        raise ProbeError(f"{where}: {missing} empty (give all of {', '.join(names)} or none)")
    values = []
    for n, t in zip(names, texts):
        try:
            v = float(t)
        except ValueError:
            raise ProbeError(f"{where}: {n} must be a number, got {t!r}") from None
        if not math.isfinite(v):
            raise ProbeError(f"{where}: {n} must be finite, got {t!r}")
        values.append(v)
    if values[2] <= 0:
        raise ProbeError(f"{where}: {kind}_r must be positive, got {texts[2]}")
    return tuple(values)


def read_circles(csv_path: str, folder: str) -> list[BatchRow]:
    """The rows of a circles CSV (see the module's documentation), every one checked:
    known columns, numbers, the image present in ``folder``, ids unique."""
    if not os.path.isfile(csv_path):
        raise ProbeError(f"circles file not found: {csv_path}")
    if not os.path.isdir(folder):
        raise ProbeError(f"folder not found: {folder}")
    try:
        with open(csv_path, newline="", encoding="utf-8") as f:
            reader = csv.DictReader(f)
            header = reader.fieldnames
            records = list(reader)
    except (UnicodeDecodeError, csv.Error) as exc:
        raise ProbeError(f"{csv_path}: not a readable CSV file ({exc})") from None
    if not header or "image" not in [h.strip() for h in header]:
        raise ProbeError(f"{csv_path}: the header row must name an 'image' column (and circle columns: "
                         f"{', '.join(COLUMNS[2:])})")
    unknown = [h for h in header if h is None or h.strip() not in COLUMNS]
    if unknown:
        raise ProbeError(f"{csv_path}: unknown column {unknown[0]!r}; known: {', '.join(COLUMNS)}")
    rows, seen = [], {}
    for i, raw in enumerate(records, start=2):
        record = {(k or "").strip(): v for k, v in raw.items()}
        name = (record.get("image") or "").strip()
        where = f"{csv_path} row {i}" + (f" ({name})" if name else "")
        if None in raw:
            raise ProbeError(f"{where}: more fields than the header names")
        if not name:
            raise ProbeError(f"{where}: empty image name")
        path = os.path.join(folder, name)
        if not os.path.isfile(path):
            raise ProbeError(f"{where}: image not found: {path}")
        ident = (record.get("id") or "").strip() or os.path.splitext(os.path.basename(name))[0]
        if ident in seen:
            raise ProbeError(f"{where}: id {ident!r} already used by row {seen[ident]}")
        seen[ident] = i
        rows.append(BatchRow(i, path, ident, _circle(record, "chrome", where), _circle(record, "diffuse", where)))
    if not rows:
        raise ProbeError(f"{csv_path}: no image rows")
    return rows


def consensus_circle(circles: list, images: int) -> tuple[tuple[float, float, float], int]:
    """The circle most of ``circles`` (``(cx, cy, r)``, or None where none was found) agree
    on, and how many agree: the circle with the most others whose centre and radius lie
    within :data:`AGREE_FRACTION` of its radius, the coordinate-wise median of that group.
    :class:`ProbeError` (one line) when the group holds no more than half of ``images``."""
    found = [tuple(float(v) for v in c) for c in circles if c is not None]

    def agreeing(a):
        return [c for c in found if math.hypot(c[0] - a[0], c[1] - a[1]) <= AGREE_FRACTION * a[2]
                and abs(c[2] - a[2]) <= AGREE_FRACTION * a[2]]
    group = max((agreeing(a) for a in found), key=len, default=[])
    if 2 * len(group) <= images:
        seen = ", ".join(f"({c[0]:.0f}, {c[1]:.0f}, r {c[2]:.0f})" for c in found[:4]) or "none"
        raise ProbeError(f"--fixed-probe: no chrome circle found in more than half of the {images} images "
                         f"({len(group)} agree; circles found: {seen}); give the circle in --circles")
    return tuple(float(v) for v in np.median(np.array(group), axis=0)), len(group)


def _fixed_probe_circle(rows: list[BatchRow], base, progress: bool):
    """The fixed probe's circle (:func:`consensus_circle`) over the automatic detections in
    the rows without a chrome circle (the chrome sphere alone, as ``relight probe`` finds
    it), and a record of it for their entries."""
    from tqdm import tqdm

    from relight.probe import detect
    from relight.probe.run import locate_sphere
    todo = [row for row in rows if row.chrome_circle is None]
    circles = []
    for row in tqdm(todo, desc="probe: finding the chrome sphere", unit="image", disable=None if progress else True):
        try:     # an image that cannot be read stops the run; one without a sphere found adds none
            image, clip, _ = detect.read_probe_image(row.path, base.linear)
        except ProbeError as exc:
            raise ProbeError(f"row {row.row} ({row.path}): {str(exc).splitlines()[0]}") from None
        camera = base.camera(image.shape[1], image.shape[0])
        try:
            sphere = locate_sphere(image, camera, "chrome", clip_level=clip, use_locator=base.locator)[0]
            circles.append(detect.outline_circle(camera, sphere))
        except ProbeError:
            circles.append(None)
    circle, agree = consensus_circle(circles, len(todo))
    return circle, {"circle": [round(v, 3) for v in circle], "agreeing": agree,
                    "found": sum(c is not None for c in circles), "images": len(todo)}


def run_batch(rows: list[BatchRow], base, qa_folder: str | None = None, progress: bool = True,
              fixed_probe: bool = False) -> list[dict]:
    """Predictions entries (with ``id``) for ``rows``, each measured with ``base`` (a
    :class:`relight.probe.run.ProbeConfig` giving the camera and options) and the row's
    circles. With ``fixed_probe`` the rows without a chrome circle are given the one their
    automatic detections agree on (the module's documentation; each entry records it as
    ``chrome_circle_shared``). With ``qa_folder`` a QA overlay per image is written there,
    all at the end (nothing is written when a row fails). A failure raises
    :class:`ProbeError` naming the row and the file."""
    from tqdm import tqdm

    from relight.probe.run import run_probe, write_qa
    shared, record = None, None
    if fixed_probe and any(row.chrome_circle is None for row in rows):
        shared, record = _fixed_probe_circle(rows, base, progress)
    entries, results = [], []
    for row in tqdm(rows, desc="probe", unit="image", disable=None if progress else True):   # off when not a terminal
        given = row.chrome_circle if row.chrome_circle is not None or shared is None else shared
        cfg = dataclasses.replace(base, chrome=row.path, chrome_circle=given, chrome_mask=None,
                                  diffuse=row.path if row.diffuse_circle else None,
                                  diffuse_circle=row.diffuse_circle, diffuse_mask=None)
        try:
            result = run_probe(cfg)
        except ProbeError as exc:
            raise ProbeError(f"row {row.row} ({row.path}): {str(exc).splitlines()[0]}") from None
        entries.append({"id": row.ident, "image": os.path.basename(row.path), **result.entry})
        if row.chrome_circle is None and record is not None:
            entries[-1]["chrome_circle_shared"] = record
        if qa_folder is not None:
            results.append((row, result, entries[-1]))
    if qa_folder is not None:
        from relight.fileio import atomic_folder

        def write_all(tmp):
            os.makedirs(tmp, exist_ok=True)
            for row, result, entry in results:
                write_qa(os.path.join(tmp, f"{row.ident}.png"), result, title=row.ident, entry=entry)
        atomic_folder(qa_folder, write_all)
    return entries

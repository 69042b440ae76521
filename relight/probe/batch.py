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
"""
from __future__ import annotations

import csv
import dataclasses
import math
import os

from relight.errors import ProbeError

__all__ = [
    "COLUMNS",
    "BatchRow",
    "read_circles",
    "run_batch",
]

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


def run_batch(rows: list[BatchRow], base, qa_folder: str | None = None, progress: bool = True) -> list[dict]:
    """Predictions entries (with ``id``) for ``rows``, each measured with ``base`` (a
    :class:`relight.probe.run.ProbeConfig` giving the camera and options) and the row's
    circles. With ``qa_folder`` a QA overlay per image is written there, all at the end
    (nothing is written when a row fails). A failure raises :class:`ProbeError` naming
    the row and the file."""
    from tqdm import tqdm

    from relight.probe.run import run_probe, write_qa
    entries, results = [], []
    for row in tqdm(rows, desc="probe", unit="image", disable=None if progress else True):   # off when not a terminal
        cfg = dataclasses.replace(base, chrome=row.path, chrome_circle=row.chrome_circle, chrome_mask=None,
                                  diffuse=row.path if row.diffuse_circle else None,
                                  diffuse_circle=row.diffuse_circle, diffuse_mask=None)
        try:
            result = run_probe(cfg)
        except ProbeError as exc:
            raise ProbeError(f"row {row.row} ({row.path}): {str(exc).splitlines()[0]}") from None
        entries.append({"id": row.ident, "image": os.path.basename(row.path), **result.entry})
        if qa_folder is not None:
            results.append((row, result))
    if qa_folder is not None:
        from relight.fileio import atomic_folder

        def write_all(tmp):
            os.makedirs(tmp, exist_ok=True)
            for row, result in results:
                write_qa(os.path.join(tmp, f"{row.ident}.png"), result, title=row.ident)
        atomic_folder(qa_folder, write_all)
    return entries

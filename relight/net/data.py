"""Network input encoding and the torch Dataset over a ``relight generate`` folder.

Input encoding (the same at training and prediction time):
    1. an 8-bit sRGB image (the dataset PNGs; EXR/linear input is first encoded with
       :func:`relight.imageio.to_srgb8`, exactly as the PNGs were written);
    2. centre-cropped to a square (the shorter side; dataset images are square so
       this is a no-op) and resized to ``res x res`` with PIL's bilinear filter
       (antialiased when shrinking; a no-op when the size already matches);
    3. scaled to float32 in [0, 1], channels first ``(3, res, res)``.

Augmentation keeps labels true: a horizontal flip mirrors the scene, so the light's
pan relative to the camera becomes ``360 - pan_rel``; in the 7-vector
``y0 = sin(pan_c - pan_l) = -sin(pan_rel)`` changes sign and everything else stays.
The same holds for a camera-frame target (``target_frame="camera"``,
:func:`relight.frames.y_to_target`): the mirror negates camera x, the pan of its level
camera.
"""
from __future__ import annotations

__all__ = [
    "SPLITS", "prepare_srgb8", "flip_y", "flip_image", "dataset_folders", "folders_record", "LightDataset",
    "linear_at_res", "mask_at_res", "square_at_res", "model_dataset", "NET_SURROUNDS",
]

import copy
import os

import numpy as np
import torch
from torch.utils.data import Dataset

from relight import frames
from relight.dataset import SPLIT_CHOICES, DatasetError, read_manifest, safe_join, split_records

SPLITS = SPLIT_CHOICES   # one split or "all"
SOURCES = ("image", "exr")   # what a LightDataset reads: the 8-bit PNG, or the linear EXR
# What a network is trained to see around the objects: "keep", the whole image; "black", the
# objects alone, everything outside an object mask black (``relight train --surround black``;
# its images need a mask: ``relight predict --mask``). Model files written before it: "keep".
NET_SURROUNDS = ("keep", "black")


def linear_at_res(path: str, res: int) -> np.ndarray:
    """A linear EXR centre-cropped to a square and area-averaged to ``(res, res, 3)`` float32."""
    from relight.imageio import ImageError, read_exr
    if not os.path.isfile(path):
        raise DatasetError(f"dataset EXR missing: {path}")
    try:
        img = np.asarray(read_exr(path), dtype=np.float32)[..., :3]
    except ImageError as exc:
        raise DatasetError(f"dataset EXR: {exc}") from None
    return square_at_res(img, res)


def mask_at_res(path: str, res: int) -> np.ndarray:
    """An object mask (``masks/ID.png``, coverage) cropped and area-averaged as
    :func:`linear_at_res` crops its image: ``(res, res)`` float32 in [0, 1]."""
    from relight.imageio import ImageError, read_mask
    if not os.path.isfile(path):
        raise DatasetError(f"dataset mask missing: {path}")
    try:
        return square_at_res(read_mask(path), res)
    except ImageError as exc:
        raise DatasetError(f"dataset mask: {exc}") from None


def square_at_res(img: np.ndarray, res: int) -> np.ndarray:
    """``img`` (H, W[, C]) centre-cropped to a square and area-averaged (or, when smaller,
    interpolated) to ``res`` x ``res``, float32."""
    import cv2

    img = np.asarray(img, dtype=np.float32)
    h, w = img.shape[:2]
    side = min(h, w)
    img = img[(h - side) // 2:(h - side) // 2 + side, (w - side) // 2:(w - side) // 2 + side]
    if side != res:
        img = cv2.resize(img, (res, res), interpolation=cv2.INTER_AREA if side > res else cv2.INTER_LINEAR)
    return np.ascontiguousarray(img, dtype=np.float32)


def prepare_srgb8(image_srgb8: np.ndarray, res: int) -> torch.Tensor:
    """8-bit sRGB ``(H, W, 3)`` uint8 -> network input ``(3, res, res)`` float32 in [0, 1]."""
    from PIL import Image
    img = np.asarray(image_srgb8)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) uint8 image, got {img.dtype} {img.shape}")
    h, w = img.shape[:2]
    if h != w:
        side = min(h, w)
        top, left = (h - side) // 2, (w - side) // 2
        img = img[top:top + side, left:left + side]
    if img.shape[0] != res:
        img = np.asarray(Image.fromarray(img).resize((res, res), Image.BILINEAR))
    return torch.from_numpy(np.ascontiguousarray(img).transpose(2, 0, 1).astype(np.float32) / 255.0)


def flip_y(y):
    """Target of the horizontally flipped image: pan_rel -> 360 - pan_rel (y0 -> -y0).

    Works on numpy arrays and torch tensors of shape ``(..., 7)``.
    """
    out = y.clone() if isinstance(y, torch.Tensor) else np.array(y, dtype=np.float64, copy=True)
    out[..., 0] = -out[..., 0]
    return out


def flip_image(x: torch.Tensor) -> torch.Tensor:
    """Mirror a ``(..., H, W)`` image left-right."""
    return torch.flip(x, dims=(-1,))


def _read_png_srgb8(path: str) -> np.ndarray:
    from relight.imageio import ImageError, read_srgb8
    if not os.path.isfile(path):
        raise DatasetError(f"dataset image missing: {path}")
    try:
        return read_srgb8(path)[0]
    except ImageError as exc:
        raise DatasetError(f"dataset image: {exc}") from None


def dataset_folders(data_dir) -> list[str]:
    """``data_dir`` (one folder, or a sequence of folders trained on together) as a list."""
    if isinstance(data_dir, (str, os.PathLike)):
        return [os.fspath(data_dir)]
    folders = [os.fspath(d) for d in data_dir]
    if not folders:
        raise DatasetError("no dataset folder given")
    if len({os.path.realpath(d) for d in folders}) != len(folders):
        raise DatasetError(f"a dataset folder is given twice: {', '.join(folders)}")
    return folders


def folders_record(data_dir):
    """What a run or calibration records of its data: the absolute path of one folder, or
    the list of them for several (one folder stays a plain string, as before)."""
    paths = [os.path.abspath(d) for d in dataset_folders(data_dir)]
    return paths[0] if len(paths) == 1 else paths


class LightDataset(Dataset):
    """Images and 7-vector targets of one split of one or several dataset folders.

    Items are ``(image (3, res, res) float32, y (7,) float32, index)``. With several
    folders (e.g. rooms with pattern and with mosaic backgrounds) the split's records of
    each folder follow one another, in the order given. With ``flip=True`` each item is
    mirrored with probability 1/2, decided by ``(seed, epoch, index)`` alone (set
    :attr:`epoch` each epoch), so a resumed run sees the same augmentation. Decoded
    images are cached in memory as uint8 (``res * res * 3`` bytes each) when ``cache``
    is true. :meth:`target` gives the label in ``target_frame`` (:data:`relight.frames.TARGET_FRAMES`:
    the stored paper's y, or the light in the camera frame), decoded with
    :meth:`target_tilts`.
    """

    def __init__(self, data_dir, split: str = "train", res: int = 128,
                 flip: bool = False, seed: int = 0, cache: bool = True, records: list[dict] | None = None,
                 image_key: str = "image", source: str = "image", augment=None, target_frame: str = "world",
                 surround: str = "keep"):
        self.data_dirs = dataset_folders(data_dir)
        self.data_dir = self.data_dirs[0]
        if records is not None and len(self.data_dirs) > 1:
            raise ValueError("records= needs a single dataset folder")
        self.image_key = image_key   # the record field naming the image ("image_masked": MID-like, spheres out)
        if source not in SOURCES:
            raise ValueError(f"source must be one of {', '.join(SOURCES)}, got {source!r}")
        self.source = source         # "image": the 8-bit PNG; "exr": the linear EXR through ``augment``
        self.augment = augment       # a relight.net.augment.PipelineAugment (source "exr"), or None
        if surround not in NET_SURROUNDS or (surround != "keep" and source != "exr"):
            raise ValueError(f"surround must be one of {', '.join(NET_SURROUNDS)} (not keep: with source exr), "
                             f"got {surround!r} with source {source!r}")
        self.surround = surround     # "black": the linear image times its object mask (the object alone)
        frames.check_target_frame(target_frame)
        self.target_frame = target_frame
        self.split = split
        self.res, self.flip, self.seed, self.cache = res, flip, seed, cache
        self.epoch = 0
        self._cache: dict[tuple[int, str], np.ndarray] = {}
        self._set_parts([split_records(read_manifest(d) if records is None else records, split)
                         for d in self.data_dirs])

    def _set_parts(self, parts: list[list[dict]]) -> None:
        self._parts = parts
        self.records = [rec for part in parts for rec in part]
        self._folder = [k for k, part in enumerate(parts) for _ in part]

    def __len__(self) -> int:
        return len(self.records)

    def part_sizes(self) -> list[int]:
        """Number of records taken from each folder, in folder order."""
        return [len(part) for part in self._parts]

    def keep_first(self, sizes) -> None:
        """Keep only the first ``sizes[k]`` records of folder ``k`` (processes that read
        a growing manifest at different moments agree on this prefix)."""
        self._set_parts([part[:int(n)] for part, n in zip(self._parts, sizes)])

    def refresh(self) -> int:
        """Re-read the manifests (a dataset still being generated grows); returns new size.
        Records keep their file order, so each folder's earlier records are unchanged."""
        self._set_parts([split_records(read_manifest(d), self.split) for d in self.data_dirs])
        return len(self.records)

    def unaugmented(self) -> LightDataset:
        """The same records without flip or pipeline augmentation (shares the image cache)."""
        twin = copy.copy(self)
        twin.flip = False
        twin.augment = None
        return twin

    def linear_image(self, i: int) -> np.ndarray:
        """The record's linear EXR at network size, ``(res, res, 3)`` float32 (centre-cropped,
        area-averaged; cached as float16)."""
        rec, folder = self.records[i], self._folder[i]
        key = (folder, rec["id"], "exr")
        img = self._cache.get(key)
        if img is None:
            img = linear_at_res(safe_join(self.data_dirs[folder], rec["exr"]), self.res)
            if self.surround == "black":   # before the camera pipeline: a black surround photographed
                if not isinstance(rec.get("mask"), str):
                    raise DatasetError(f"record {rec['id']!r} has no object mask (generate with "
                                       "\"object_masks\": true for --surround black)")
                img = img * mask_at_res(safe_join(self.data_dirs[folder], rec["mask"]), self.res)[..., None]
            img = img.astype(np.float16)
            if self.cache:
                self._cache[key] = img
        return img.astype(np.float32)

    def image_srgb8(self, i: int) -> np.ndarray:
        """The record's image at network size, ``(res, res, 3)`` uint8 (cached)."""
        rec, folder = self.records[i], self._folder[i]
        key = (folder, rec["id"])
        img = self._cache.get(key)
        if img is None:
            if not isinstance(rec.get(self.image_key), str):
                raise DatasetError(f"record {rec['id']!r} has no {self.image_key!r} image (only MID-like datasets "
                                   "have masked copies)")
            raw = _read_png_srgb8(safe_join(self.data_dirs[folder], rec[self.image_key]))
            img = (prepare_srgb8(raw, self.res).numpy().transpose(1, 2, 0) * 255.0 + 0.5).astype(np.uint8)
            if self.cache:
                self._cache[key] = img
        return img

    def target(self, i: int) -> np.ndarray:
        """The label of item ``i`` in :attr:`target_frame`, ``(7,)`` float64 (not mirrored)."""
        y = np.asarray(self.records[i]["y"], dtype=np.float64)
        if y.shape != (7,) or not np.all(np.isfinite(y)):
            raise DatasetError(f"record {self.records[i].get('id')!r}: 'y' must be 7 finite numbers")
        if self.target_frame == "world":
            return y
        return frames.y_to_target(y, self._camera_tilt(i), self.target_frame)

    def _camera_tilt(self, i: int) -> float:
        return float(self.records[i]["camera"]["tilt_deg"])

    def target_tilts(self, index) -> np.ndarray:
        """The camera tilts ``(len(index),)`` (degrees) the targets of items ``index`` decode
        with (:func:`relight.frames.target_tilt_deg`: the camera's own, or 0 in the camera frame)."""
        return frames.target_tilt_deg(np.array([self._camera_tilt(int(i)) for i in index], dtype=np.float64),
                                      self.target_frame)

    def flipped(self, i: int) -> bool:
        """Whether item ``i`` is mirrored in the current epoch."""
        if not self.flip:
            return False
        return bool(np.random.default_rng([self.seed, self.epoch, i]).random() < 0.5)

    def image_tensor(self, i: int) -> torch.Tensor:
        """The network input of item ``i``: ``(3, res, res)`` float32 in [0, 1], not mirrored.
        With source ``exr`` and an ``augment`` pipeline, the linear image goes through a
        camera pipeline drawn from ``(seed, epoch, i)`` (a resumed run sees the same)."""
        if self.source == "exr":
            from relight.net.augment import PipelineAugment
            pipeline = self.augment or PipelineAugment.none()
            srgb8 = pipeline.apply(self.linear_image(i), np.random.default_rng([self.seed, self.epoch, i, 1]))
        else:
            srgb8 = self.image_srgb8(i)
        return torch.from_numpy(srgb8.transpose(2, 0, 1).astype(np.float32) / 255.0)

    def batch(self, items) -> torch.Tensor:
        """:meth:`image_tensor` of ``items``, stacked ``(B, 3, res, res)``."""
        return torch.stack([self.image_tensor(i) for i in items])

    def __getitem__(self, i: int):
        x = self.image_tensor(i)
        y = self.target(i)
        if self.flipped(i):
            x, y = flip_image(x), flip_y(y)
        return x, torch.from_numpy(y.astype(np.float32)), i

    def truth(self) -> dict:
        """Ground truth of every item in degrees: ``pan_rel_deg``, ``tilt_deg``, ``rgb``,
        ``camera_tilt_deg`` (arrays of shape (N,) or (N, 3))."""
        r = self.records
        return {"id": [x["id"] for x in r],
                "pan_rel_deg": np.array([x["pan_rel_deg"] for x in r], dtype=np.float64),
                "tilt_deg": np.array([x["light"]["tilt_deg"] for x in r], dtype=np.float64),
                "rgb": np.array([x["light"]["rgb"] for x in r], dtype=np.float64).reshape(-1, 3),
                "camera_tilt_deg": np.array([x["camera"]["tilt_deg"] for x in r], dtype=np.float64)}


def model_dataset(model, data_dir, split: str, **kwargs) -> LightDataset:
    """The records of ``split`` of ``data_dir`` as ``model`` reads them: for a network of the
    objects alone (``config.surround`` "black") the linear EXRs times their object masks,
    unaugmented; else the 8-bit PNGs. ``kwargs`` go to :class:`LightDataset`."""
    config = model.config
    if getattr(config, "surround", "keep") != "keep":
        kwargs = {"source": "exr", "surround": config.surround} | kwargs
    return LightDataset(data_dir, split, int(config.res), **kwargs)

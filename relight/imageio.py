"""Image files: read and write EXR (linear HDR) and PNG/JPEG (8- or 16-bit sRGB).

Linear images are ``(H, W, 3)`` float32 arrays of scene-referred Rec.709 RGB. PNGs are
made for the network: ``srgb_encode(clip(linear * exposure, 0, 1))`` in 8 bits, with
``exposure`` 1 (the generator already normalises exposure through the light's strength).
All writes are atomic (temporary file, then rename), so a killed job never leaves a
half-written image under its final name.
"""
from __future__ import annotations

__all__ = [
    "write_exr", "read_exr", "to_srgb8", "write_png", "write_srgb8", "write_mask", "read_mask", "MAX_IMAGE_PIXELS", "load_image",
    "read_image", "read_srgb8",
]

import os

import numpy as np

from relight import colour
from relight.fileio import atomic_write, quiet_library_output
from relight.errors import ImageError, brief


def write_exr(path: str | os.PathLike, image: np.ndarray, inputs=()) -> None:
    """Write a linear ``(H, W, 3)`` image as a float32 RGB OpenEXR file, atomically
    (refusing to replace one of ``inputs``)."""
    import OpenEXR
    path = os.fspath(path)
    image = np.ascontiguousarray(image, dtype=np.float32)
    if image.ndim != 3 or image.shape[2] != 3:
        raise ImageError(f"expected an (H, W, 3) image, got shape {image.shape}")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}

    def write(tmp):
        with OpenEXR.File(header, {"RGB": image}) as f:
            f.write(tmp)
    atomic_write(path, write, inputs)


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read an OpenEXR file as linear ``(H, W, 3)`` float32 (see :func:`load_image`)."""
    return _read_exr(os.fspath(path))[0]


def _read_exr(path: str) -> tuple[np.ndarray, str]:
    import OpenEXR
    if not os.path.exists(path):
        raise ImageError(f"image not found: {path}")
    try:
        with quiet_library_output(), OpenEXR.File(path) as f:   # OpenEXR prints its own warnings
            channels = {k: np.asarray(v.pixels) for k, v in f.channels().items()}
    except Exception as exc:  # noqa: BLE001 - OpenEXR raises plain exceptions
        raise ImageError(f"cannot read EXR {path}: {brief(exc, 160)}") from None
    if "RGB" in channels or "RGBA" in channels:
        key = "RGB" if "RGB" in channels else "RGBA"
        img, how = channels[key][..., :3], key
    elif all(c in channels for c in "RGB"):
        img, how = np.stack([channels[c] for c in "RGB"], -1), "R, G, B"
    elif "Y" in channels:
        img, how = np.repeat(channels["Y"][..., None], 3, -1), "Y (grey, repeated)"
    else:
        raise ImageError(f"{path}: EXR without R, G, B or Y channels (found {sorted(channels)})")
    if img.ndim != 3 or img.shape[2] != 3 or img.shape[0] < 1 or img.shape[1] < 1:
        raise ImageError(f"{path}: unexpected EXR pixel layout {img.shape}")
    _check_size(path, img.shape[1], img.shape[0])
    img = np.ascontiguousarray(img, dtype=np.float32)
    if not np.isfinite(img).all():
        raise ImageError(f"{path}: EXR holds NaN or infinite pixels")
    kind = {np.dtype(np.float16): "half", np.dtype(np.float32): "float",
            np.dtype(np.uint32): "uint"}.get(channels[next(iter(channels))].dtype, "")
    return img, f"linear (EXR), {kind} channels {how}".replace(",  ", ", ")


def to_srgb8(linear: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """Linear float image to 8-bit sRGB (clipped)."""
    encoded = colour.srgb_encode(np.clip(np.asarray(linear, np.float64) * exposure, 0.0, 1.0))
    return np.round(encoded * 255.0).astype(np.uint8)


def write_png(path: str | os.PathLike, linear: np.ndarray, exposure: float = 1.0, inputs=()) -> None:
    """Write a linear image as an 8-bit sRGB PNG, atomically (refusing to replace one of
    ``inputs``)."""
    write_srgb8(path, to_srgb8(linear, exposure), inputs)


def write_srgb8(path: str | os.PathLike, srgb8: np.ndarray, inputs=()) -> None:
    """Write 8-bit sRGB pixels ``(H, W, 3)`` uint8 as a PNG, atomically."""
    from PIL import Image
    pixels = Image.fromarray(np.ascontiguousarray(srgb8, dtype=np.uint8))
    atomic_write(path, lambda tmp: pixels.save(tmp, format="PNG", compress_level=1), inputs)


def write_mask(path: str | os.PathLike, coverage: np.ndarray, inputs=()) -> None:
    """Write a mask ``(H, W)`` of coverage in [0, 1] as an 8-bit grey PNG (255: wholly
    covered), atomically; :func:`read_mask` reads it back."""
    from PIL import Image
    codes = np.round(np.clip(np.asarray(coverage, np.float64), 0.0, 1.0) * 255.0).astype(np.uint8)
    if codes.ndim != 2:
        raise ValueError(f"a mask is (H, W), got shape {codes.shape}")
    pixels = Image.fromarray(np.ascontiguousarray(codes), mode="L")
    atomic_write(path, lambda tmp: pixels.save(tmp, format="PNG", compress_level=1), inputs)


def read_mask(path: str | os.PathLike) -> np.ndarray:
    """A mask written by :func:`write_mask` (or any grey or RGB image: its first channel)
    as coverage ``(H, W)`` float32 in [0, 1]."""
    pixels, _, _ = load_image(path)
    return np.asarray(pixels[..., 0] if pixels.ndim == 3 else pixels, np.float32)


MAX_IMAGE_PIXELS = 8192 * 8192   # larger images are refused (decompression bombs)


def _check_size(path: str, width: int, height: int) -> None:
    if width * height > MAX_IMAGE_PIXELS:
        raise ImageError(f"{path}: image of {width}x{height} pixels is larger than the "
                         f"{MAX_IMAGE_PIXELS} pixels relight reads (decompression bomb?)")


def _png_depth(path: str) -> int | None:
    """Bit depth of a PNG file from its IHDR chunk (None for other formats)."""
    try:
        with open(path, "rb") as f:
            head = f.read(26)
    except OSError:
        return None
    return head[24] if head[:8] == b"\x89PNG\r\n\x1a\n" and len(head) >= 25 else None


def load_image(path: str | os.PathLike) -> tuple[np.ndarray, str, str]:
    """Read an image file of any supported kind, as it is encoded.

    PNG of every mode and bit depth (1/2/4/8/16-bit grey, grey+alpha, palette, RGB,
    RGBA), JPEG and OpenEXR (``RGB``/``RGBA``, separate ``R``/``G``/``B`` or ``Y``
    channels, half or float). Alpha is dropped; grey is repeated to three channels.

    Returns:
        ``(pixels, encoding, note)``: ``(H, W, 3)`` float32 values, ``encoding`` is
        ``"srgb"`` (values in [0, 1], sRGB-encoded) or ``"linear"`` (EXR), and
        ``note`` says in a few words how the file was read (for the output).

    Raises :class:`ImageError` (one line naming the file) for a missing, truncated,
    unknown or over-large (more than :data:`MAX_IMAGE_PIXELS`) image.
    """
    import warnings

    path = os.fspath(path)
    if path.lower().endswith(".exr"):
        img, note = _read_exr(path)
        return img, "linear", note
    from PIL import Image, UnidentifiedImageError
    if os.path.isdir(path):
        raise ImageError(f"{path} is a folder, not an image")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(path) as im:
                _check_size(path, *im.size)
                fmt, mode = im.format or "image", im.mode
                if fmt == "PNG":
                    im.verify()   # every chunk and CRC: a truncated file is refused
            with Image.open(path) as im:
                im.load()
                pixels, depth = _pil_pixels(im, path)
    except FileNotFoundError:
        raise ImageError(f"image not found: {path}") from None
    except ImageError:
        raise
    except (Image.DecompressionBombError, Image.DecompressionBombWarning):
        raise ImageError(f"{path}: image too large (decompression bomb?)") from None
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError, TypeError,
            MemoryError, EOFError) as exc:
        raise ImageError(f"cannot read image {path}: {brief(exc)}") from None
    if fmt == "PNG":
        depth = _png_depth(path) or depth
        if depth == 16 and mode in ("RGB", "RGBA"):   # Pillow keeps 8 of the 16 bits
            pixels = _png16_colour(path, pixels)
    kind = {"1": "1-bit grey", "L": "grey", "LA": "grey+alpha", "P": "palette", "PA": "palette+alpha",
            "RGB": "RGB", "RGBA": "RGBA", "I;16": "grey", "I;16B": "grey", "I;16L": "grey",
            "I": "grey", "CMYK": "CMYK", "YCbCr": "YCbCr"}.get(mode, mode)
    extra = [f"{fmt} {kind}"]
    if mode in ("LA", "PA") and depth == 16:
        extra.append("read at 8-bit precision")
    if "A" in mode:
        extra.append("alpha ignored")
    note = f"{depth}-bit sRGB ({', '.join(extra)})"
    return pixels, "srgb", note


def _png16_colour(path: str, fallback: np.ndarray) -> np.ndarray:
    """Full 16-bit values of a 16-bit RGB/RGBA PNG (OpenCV), else Pillow's 8-bit ones."""
    try:
        import cv2
    except ImportError:
        return fallback
    raw = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if raw is None or raw.dtype != np.uint16 or raw.ndim != 3 or raw.shape[:2] != fallback.shape[:2]:
        return fallback
    return (raw[..., :3][..., ::-1].astype(np.float32) / 65535.0).copy()


def _pil_pixels(im, path: str) -> tuple[np.ndarray, int]:
    """``(H, W, 3)`` float32 in [0, 1] and the bit depth of an opened PIL image."""
    mode = im.mode
    if mode in ("I;16", "I;16B", "I;16L", "I;16N"):
        grey = np.asarray(im).astype(np.float32) / 65535.0
        return np.repeat(grey[..., None], 3, -1), 16
    if mode == "I":   # 16-bit grey PNG in some Pillow versions (values 0..65535)
        grey = np.asarray(im).astype(np.float64)
        if grey.min() < 0 or grey.max() > 65535:
            raise ImageError(f"{path}: 32-bit integer pixels are not supported")
        return np.repeat((grey / 65535.0).astype(np.float32)[..., None], 3, -1), 16
    if mode in ("F", "I;32", "RGBa", "La"):
        raise ImageError(f"{path}: pixel mode {mode!r} is not supported (use PNG, JPEG or EXR)")
    depth = 1 if mode == "1" else 8
    rgb = np.asarray(im.convert("RGB"), dtype=np.float32) / 255.0
    return rgb, depth


def read_image(path: str | os.PathLike) -> tuple[np.ndarray, str]:
    """Read any supported image (see :func:`load_image`) as linear ``(H, W, 3)`` float32.

    Returns:
        ``(image, note)`` where ``note`` says how the file was read, e.g.
        ``"16-bit sRGB (PNG grey), decoded to linear"`` or ``"linear (EXR), half channels RGB"``.
    """
    pixels, encoding, note = load_image(path)
    if encoding == "linear":
        return pixels, note
    return colour.srgb_decode(pixels.astype(np.float64)).astype(np.float32), note + ", decoded to linear"


def read_srgb8(path: str | os.PathLike, linear: bool = False) -> tuple[np.ndarray, str]:
    """Read any supported image as 8-bit sRGB ``(H, W, 3)`` uint8 (the network's input
    encoding): sRGB files are rounded to 8 bits, linear files (EXR) encoded with
    :func:`to_srgb8`; with ``linear``, a PNG/JPEG's codes are taken as linear values (a
    camera whose output is proportional to the light) and encoded too. Returns
    ``(pixels, note)``."""
    pixels, encoding, note = load_image(path)
    if encoding == "linear":
        return to_srgb8(pixels), note + " -> 8-bit sRGB"
    if linear:
        return to_srgb8(pixels), note + ", codes read as linear -> 8-bit sRGB"
    return np.round(np.clip(pixels, 0.0, 1.0) * 255.0).astype(np.uint8), note

"""Render scene specs and read/write images (EXR linear HDR, PNG/JPEG 8-bit sRGB).

Linear images are ``(H, W, 3)`` float32 arrays of scene-referred Rec.709 RGB. PNGs are
made for the network: ``srgb_encode(clip(linear * exposure, 0, 1))`` in 8 bits, with
``exposure`` 1 (the generator already normalises exposure through the light's strength).
All writes are atomic (temporary file, then rename), so a killed job never leaves a
half-written image under its final name.
"""
from __future__ import annotations

import os

import numpy as np

from relight import colour


class ImageError(ValueError):
    """An image file cannot be read or written (one-line reason)."""


def _tmp(path: str) -> str:
    base, ext = os.path.splitext(path)
    return f"{base}.tmp{os.getpid()}{ext}"


def write_exr(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write a linear ``(H, W, 3)`` image as a half-float-free, float32 RGB OpenEXR file."""
    import OpenEXR
    path = os.fspath(path)
    image = np.ascontiguousarray(image, dtype=np.float32)
    if image.ndim != 3 or image.shape[2] != 3:
        raise ImageError(f"expected an (H, W, 3) image, got shape {image.shape}")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    tmp = _tmp(path)
    with OpenEXR.File(header, {"RGB": image}) as f:
        f.write(tmp)
    os.replace(tmp, path)


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read an OpenEXR file as linear ``(H, W, 3)`` float32 (grey images are repeated)."""
    import OpenEXR
    path = os.fspath(path)
    try:
        with OpenEXR.File(path) as f:
            channels = f.channels()
            if "RGB" in channels:
                img = np.asarray(channels["RGB"].pixels, dtype=np.float32)
            elif all(c in channels for c in "RGB"):
                img = np.stack([np.asarray(channels[c].pixels, np.float32) for c in "RGB"], -1)
            elif "Y" in channels:
                img = np.repeat(np.asarray(channels["Y"].pixels, np.float32)[..., None], 3, -1)
            else:
                raise ImageError(f"{path}: no R, G, B or Y channels (found {sorted(channels)})")
    except ImageError:
        raise
    except Exception as exc:  # noqa: BLE001 - OpenEXR raises plain exceptions
        raise ImageError(f"cannot read EXR {path}: {str(exc).splitlines()[0][:160]}") from None
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[..., :3]
    return np.ascontiguousarray(img[..., :3])


def to_srgb8(linear: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """Linear float image to 8-bit sRGB (clipped)."""
    encoded = colour.srgb_encode(np.clip(np.asarray(linear, np.float64) * exposure, 0.0, 1.0))
    return np.round(encoded * 255.0).astype(np.uint8)


def write_png(path: str | os.PathLike, linear: np.ndarray, exposure: float = 1.0) -> None:
    """Write a linear image as an 8-bit sRGB PNG."""
    from PIL import Image
    path = os.fspath(path)
    tmp = _tmp(path)
    Image.fromarray(to_srgb8(linear, exposure)).save(tmp, format="PNG", compress_level=1)
    os.replace(tmp, path)


def read_image(path: str | os.PathLike) -> tuple[np.ndarray, str]:
    """Read any supported image as linear ``(H, W, 3)`` float32.

    Returns:
        ``(image, assumed)`` where ``assumed`` says how pixels were interpreted:
        ``"linear (EXR)"`` or ``"sRGB 8-bit (decoded to linear)"``.
    """
    path = os.fspath(path)
    if path.lower().endswith(".exr"):
        return read_exr(path), "linear (EXR)"
    from PIL import Image, UnidentifiedImageError
    try:
        with Image.open(path) as im:
            im.load()
            rgb = np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
    except FileNotFoundError:
        raise ImageError(f"image not found: {path}") from None
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise ImageError(f"cannot read image {path}: {str(exc).splitlines()[0][:120]}") from None
    return colour.srgb_decode(rgb).astype(np.float32), "sRGB 8-bit (decoded to linear)"


_builder = None


def render_spec(spec) -> np.ndarray:
    """Render a :class:`~relight.scene.spec.SceneSpec` with a process-wide builder that
    reuses loaded scenes; returns linear ``(res, res, 3)`` float32."""
    global _builder
    if _builder is None:
        from relight.scene.build import SceneBuilder
        _builder = SceneBuilder()
    return _builder.render(spec)

"""Prediction on any image with a trained model (the default shipped one unless named).

Images of any size are brought to the network's input encoding exactly as at
training time (:func:`relight.net.data.prepare_srgb8`): linear images (EXR, or
arrays from a renderer) are first encoded to 8-bit sRGB with
:func:`relight.imageio.to_srgb8` -- the way the dataset PNGs were written -- while
PNG/JPEG files are taken as 8-bit sRGB already. The output 7-vector is decoded with
the stated camera tilt (photographs: the paper assumes 45 degrees) and camera pan 0; a
model trained in the camera frame (``--target-frame camera``) gives the light in the
camera frame, which that tilt turns into the world (:func:`relight.net.evaluate.decode_outputs`).

A grayscale input (grey PNG/EXR, or RGB whose channels agree within
:data:`ACHROMATIC_TOLERANCE` code values in every pixel, see :func:`is_achromatic`)
carries no light colour: its prediction still has an ``rgb`` but is marked
``"colour_reliable": false`` (docs/conventions.md, project additions).
"""
from __future__ import annotations

import os

import numpy as np
import torch

from relight import frames
from relight.errors import ImageError
from relight.net.data import prepare_srgb8
from relight.net.evaluate import decode_outputs, extra_fields, paper_y, target_frame_of
from relight.net.io import ModelFileError, load_model_file, resolve_model

DEFAULT_CAMERA_TILT_DEG = frames.PHOTO_CAMERA_TILT_DEG  # the paper's assumption for photographs
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".exr")
ACHROMATIC_TOLERANCE = 2   # 8-bit sRGB code values between the channels of a grayscale pixel (JPEG rounding)

__all__ = ["load_model", "predict_arrays", "predict_files", "list_images", "ModelFileError",
           "DEFAULT_CAMERA_TILT_DEG", "is_achromatic",
           "IMAGE_EXTENSIONS", "ACHROMATIC_TOLERANCE", "read_input", "image_ids", "model_surround",
           "objects_alone"]


def is_achromatic(srgb8: np.ndarray, tolerance: int = ACHROMATIC_TOLERANCE) -> bool:
    """True when the three channels of every pixel of ``srgb8`` (``(H, W, 3)`` 8-bit
    sRGB) agree within ``tolerance`` code values: a grayscale image (or grey stored as
    RGB), whose colour says nothing about the light's colour. An empty image is not."""
    a = np.asarray(srgb8)
    if a.ndim != 3 or a.shape[2] < 3 or a.size == 0:
        return False
    a = a[..., :3].astype(np.int16)
    return bool(int((a.max(axis=2) - a.min(axis=2)).max()) <= tolerance)


def load_model(path: str | os.PathLike | None = None, mirror_average: bool = False):
    """Load a model (``None``: the default shipped model) for inference: eval mode, batch
    norms folded into the convolutions (:meth:`~relight.net.model.LightNet.fold_batchnorm`).
    With ``mirror_average`` each image's prediction is averaged with its mirror image's
    (:class:`~relight.net.model.MirrorAveraged`). To train, calibrate or save a model,
    use :func:`relight.net.io.load_model_file`.

    Raises :class:`relight.net.io.ModelFileError` (one line) on a missing, corrupt or
    foreign file.

    Args:
        path: a shipped model's name (``"photo"``: real photographs; ``"sid2"``:
            relight's SID2-style renders, ``relight/models/sid2.safetensors``), a
            ``.safetensors`` model file or a training run folder; ``None``: the default
            shipped model, ``photo`` when it is shipped, else ``sid2``
            (:func:`relight.net.io.resolve_model`).
        mirror_average: average each prediction with its mirror image's (about 1.8x the time).

    Returns:
        A :class:`~relight.net.model.LightNet` (or its mirror-averaging wrapper) in eval
        mode; ``model.config.res`` is the input size in pixels.

    >>> model = load_model("sid2")
    >>> model.config.res, model.training
    (128, False)
    """
    model = load_model_file(resolve_model(path)).fold_batchnorm()
    if mirror_average:
        from relight.net.model import MirrorAveraged
        model = MirrorAveraged(model)
    return model


def _predict_inputs(model, inputs: list[torch.Tensor], camera_tilt_deg, batch_size: int = 32,
                    achromatic: list[bool] | None = None) -> list[dict]:
    """Predictions of network inputs. ``camera_tilt_deg``: one tilt per input (degrees), or
    None: the tilt the model's camera head predicts per image (a model without one: the
    paper's assumption, :data:`DEFAULT_CAMERA_TILT_DEG`)."""
    from relight.net.model import camera_tilt_deg as head_tilt_deg
    from relight.net.ood import ood_fields
    has_camera = bool(getattr(model, "has_camera", False))
    if camera_tilt_deg is not None:
        tilts = np.asarray(camera_tilt_deg, dtype=np.float64).reshape(-1)
        if tilts.size != len(inputs):
            raise ValueError(f"expected one camera tilt per image ({len(inputs)}), got {tilts.size}")
        if not np.all(np.isfinite(tilts)):
            raise ValueError("camera tilts must be finite degrees")
    model.eval()
    with_ood = bool(getattr(getattr(model, "config", None), "ood_dims", 0))
    one_pass = with_ood and hasattr(model, "heads")   # a plain network: the embedding serves both
    ys, kappas, cameras, embeds = [], [], [], []
    with torch.no_grad():
        for s in range(0, len(inputs), batch_size):
            batch = torch.stack(inputs[s:s + batch_size])
            if one_pass:
                e = model.encode(batch)
                embeds.append(e)
                y, kappa, camera = model.heads(e)
            elif has_camera:
                y, kappa, camera = model.forward_full(batch)
            else:
                (y, kappa), camera = model.forward_with_kappa(batch), None
            if camera is not None:
                cameras.append(head_tilt_deg(camera).double().numpy())
            ys.append(y.double().numpy())
            if kappa is not None:
                kappas.append(kappa.double().numpy())
    if not ys:
        return []
    y = np.concatenate(ys)
    how = "given"
    if camera_tilt_deg is None:
        if has_camera:
            tilts, how = np.clip(np.concatenate(cameras), -89.0, 89.0), "predicted"
        else:
            tilts, how = np.full(len(inputs), DEFAULT_CAMERA_TILT_DEG), "assumed"
    frame = target_frame_of(model)
    y = paper_y(y, tilts, frame)
    pan, tilt, rgb = decode_outputs(y, tilts)
    extras = extra_fields(rgb, np.concatenate(kappas) if kappas else None)
    for i, grey in enumerate(achromatic or []):
        if grey:
            extras[i]["colour_reliable"] = False
    oods = None
    if with_ood:
        with torch.no_grad():
            oods = ood_fields(model, None, torch.cat(embeds)) if one_pass else ood_fields(model, torch.stack(inputs))
    out = []
    for i in range(len(inputs)):
        tilt_c = float(np.clip(tilts[i], -89.0, 89.0))
        to_cam = frames.world_to_camera(frames.direction(float(pan[i]), float(tilt[i])), tilt_c)
        entry = {"pan_deg": float(pan[i]), "tilt_deg": float(tilt[i]), "rgb": [float(v) for v in rgb[i]],
                 "y": [float(v) for v in y[i]], **extras[i],
                 "camera_tilt_deg": float(tilts[i]), "camera_tilt_source": how,
                 "to_light_camera": [float(v) for v in to_cam]}
        if oods is not None:
            entry.update(oods[i])
        out.append(entry)
    return out


def model_surround(model) -> str:
    """What ``model`` was trained to see around the objects (:data:`relight.net.data.NET_SURROUNDS`):
    ``"black"`` for a network of the objects alone, whose images need an object mask."""
    return getattr(getattr(model, "config", None), "surround", "keep")


def objects_alone(srgb8: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """8-bit sRGB codes ``(H, W, 3)`` with everything outside ``mask`` (H, W: coverage in
    [0, 1], or bool) black: the light of each pixel times its coverage, encoded again
    (linear images: :func:`relight.net.photos.replace_surround` ``"black"``)."""
    from relight.colour import srgb_decode, srgb_encode
    m = np.clip(np.asarray(mask, np.float64), 0.0, 1.0)
    x = np.asarray(srgb8)
    if m.shape != x.shape[:2]:
        raise ImageError(f"mask of {m.shape[1]}x{m.shape[0]} pixels for an image of {x.shape[1]}x{x.shape[0]}")
    out = np.where(m[..., None] >= 1.0, x[..., :3], 0).astype(np.uint8)   # wholly object / wholly not
    edge = (m > 0.0) & (m < 1.0)                                           # only these need the curve
    lin = srgb_decode(x[..., :3][edge].astype(np.float64) / 255.0) * m[edge][:, None]
    out[edge] = np.round(srgb_encode(lin) * 255.0).astype(np.uint8)
    return out


def predict_arrays(model, images_linear: list[np.ndarray], camera_tilt_deg: list[float] | None) -> list[dict]:
    """Predict light of linear images.

    Args:
        model: from :func:`load_model`.
        images_linear: ``(H, W, 3)`` float arrays, linear RGB (any size; encoded with
            ``to_srgb8`` then centre-cropped and resized like the training images).
        camera_tilt_deg: one camera tilt (degrees) per image, used for decoding; None: the
            model's own prediction (camera head), else the paper's 45 degrees.

    Returns:
        One dict per image: ``pan_deg`` (light pan relative to the camera, [0, 360),
        0 = front, 90 = camera's right), ``tilt_deg`` (light elevation), ``rgb``
        (unit norm, linear), ``y`` (the raw 7-vector; a camera-frame model's turned into
        the paper's with the camera tilt used), ``cct_k`` and ``duv`` (None
        where the colour is far from the Planckian locus) and, for a model with a
        kappa head, ``kappa`` and ``cone90_deg`` (radius of the 90% cone, degrees);
        ``colour_reliable`` = False for a grayscale image (:func:`is_achromatic`);
        ``camera_tilt_deg`` and ``camera_tilt_source`` (given / predicted / assumed),
        ``to_light_camera`` (unit vector, camera frame: x right, y up, z toward the camera)
        and, for a model with an out-of-distribution detector, ``ood`` and ``ood_score``.

    >>> p = predict_arrays(load_model(), [np.full((64, 64, 3), 0.2, np.float32)], [45.0])[0]
    >>> 0.0 <= p["pan_deg"] < 360.0, -90.0 <= p["tilt_deg"] <= 90.0, len(p["y"])
    (True, True, 7)
    >>> round(float(np.linalg.norm(p["rgb"])), 6), p["colour_reliable"]   # a grey image says nothing of colour
    (1.0, False)
    """
    from relight.imageio import to_srgb8
    res = model.config.res
    inputs, achromatic = [], []
    for k, img in enumerate(images_linear):
        a = np.asarray(img)
        if a.ndim != 3 or a.shape[2] < 3:
            raise ValueError(f"image #{k}: expected (H, W, 3) linear RGB, got shape {a.shape}")
        srgb8 = to_srgb8(a[..., :3])
        inputs.append(prepare_srgb8(srgb8, res))
        achromatic.append(is_achromatic(srgb8))
    return _predict_inputs(model, inputs, camera_tilt_deg, achromatic=achromatic)


def read_input(path: str, res: int) -> tuple[torch.Tensor, str]:
    """Network input of an image file and how it was read (see
    :func:`relight.imageio.load_image`: every PNG mode and bit depth, JPEG, EXR).
    Raises :class:`relight.imageio.ImageError` for unreadable files."""
    x, note, _ = _read_input(path, res)
    return x, note


def _read_input(path: str, res: int, mask: str | None = None, linear: bool = False) -> tuple[torch.Tensor, str, bool]:
    """:func:`read_input` and whether the image is grayscale (:func:`is_achromatic`); with
    ``mask`` (an image file: white where the objects are), the objects alone
    (:func:`objects_alone`); with ``linear``, a PNG/JPEG's codes read as linear values."""
    from relight.imageio import read_mask, read_srgb8
    srgb8, note = read_srgb8(path, linear=linear)
    if mask is not None:
        try:
            srgb8 = objects_alone(srgb8, read_mask(mask))
        except ImageError as exc:
            raise ImageError(f"{mask}: {exc}") from None
        note += ", outside its mask black"
    return prepare_srgb8(srgb8, res), note, is_achromatic(srgb8)


def list_images(paths: list[str]) -> list[str]:
    """Files named, plus the images (PNG/JPEG/EXR) directly inside named folders, sorted;
    :class:`ImageError` when one image is named twice (directly, through its folder or a
    link), which would give two predictions of one picture."""
    from relight.fileio import is_temp_name
    from relight.imageio import ImageError
    out = []
    for p in paths:
        if os.path.isdir(p):
            found = sorted(os.path.join(p, n) for n in os.listdir(p)
                           if n.lower().endswith(IMAGE_EXTENSIONS) and not is_temp_name(n) and not n.startswith("."))
            if not found:
                raise ImageError(f"no PNG/JPEG/EXR images in folder {p}")
            out += found
        elif os.path.exists(p):
            out.append(p)
        else:
            raise ImageError(f"image not found: {p}")
    seen = {}
    for f in out:   # one image given twice (a file and its folder, a link...) is refused
        st = os.stat(f)
        key = (st.st_dev, st.st_ino)
        if key in seen:
            also = "" if f == seen[key] else f" (also as {seen[key]})"
            raise ImageError(f"image {f} is given twice{also}; give each image once (a file and "
                             "its folder, or a link to it, name it twice)")
        seen[key] = f
    return out


def image_ids(files: list[str]) -> list[str]:
    """Ids from file names (the stem; the full name where two stems collide)."""
    stems = [os.path.splitext(os.path.basename(f))[0] or os.path.basename(f) for f in files]
    ids = [s if stems.count(s) == 1 else os.path.basename(f) for s, f in zip(stems, files)]
    seen, out = {}, []
    for i in ids:  # same file name in two folders: number them
        seen[i] = seen.get(i, 0) + 1
        out.append(i if seen[i] == 1 else f"{i}~{seen[i]}")
    return out


def predict_files(model, files: list[str], camera_tilt_deg: float | None = None,
                  masks: list[str] | None = None, linear: bool = False) -> list[dict]:
    """Predictions for image files; each dict also has ``id``, ``file`` and ``assumed``
    (how its pixels were interpreted), and ``colour_reliable`` = False for a grayscale
    image (:func:`is_achromatic`).

    Args:
        model: from :func:`load_model`.
        files: image paths (PNG of any mode and depth, JPEG: sRGB; EXR: linear).
        camera_tilt_deg: the camera tilt assumed for every image, degrees; None: the
            model's own estimate (camera head), else the paper's 45 degrees.
        masks: one object mask file per image (white where the objects are; the image's
            size), or None: everything outside it is set black first. A model of the
            objects alone (:func:`model_surround` "black") needs them.
        linear: the PNG/JPEG files hold linear values (a camera whose output is
            proportional to the light, as measurement and machine-vision cameras store
            it), not sRGB; EXR files are linear either way.

    Returns:
        One dict per file, in order, with the fields of :func:`predict_arrays`.

    >>> import os, tempfile
    >>> from relight.imageio import write_png
    >>> tmp = tempfile.TemporaryDirectory()
    >>> path = os.path.join(tmp.name, "room.png")
    >>> write_png(path, np.full((32, 48, 3), 0.3, np.float32))
    >>> [(p["id"], p["file"] == path, p["colour_reliable"]) for p in predict_files(load_model(), [path])]
    [('room', True, False)]
    >>> tmp.cleanup()
    """
    if masks is not None and len(masks) != len(files):
        raise ImageError(f"{len(masks)} masks for {len(files)} images: give one mask per image, in order")
    if masks is None and model_surround(model) == "black":
        raise ImageError("this model reads the objects alone (trained with --surround black): give each "
                         "image's object mask (--mask, white where the objects are)")
    inputs, assumed, achromatic = [], [], []
    for k, f in enumerate(files):
        x, how, grey = _read_input(f, model.config.res, None if masks is None else masks[k], linear)
        inputs.append(x)
        assumed.append(how)
        achromatic.append(grey)
    tilts = None if camera_tilt_deg is None else [camera_tilt_deg] * len(files)
    preds = _predict_inputs(model, inputs, tilts, achromatic=achromatic)
    return [{"id": i, **p, "file": f, "assumed": a} for i, p, f, a in zip(image_ids(files), preds, files, assumed)]

"""Model weights on disk: safetensors (no pickle) with JSON metadata in its header.

A model file ``*.safetensors`` holds the network's state dict (float32 weights and
batch-norm buffers, or float16 for a shipped file: half the size, loaded back as float32)
and string metadata: ``format`` (= :data:`MODEL_FORMAT`),
``arch`` (a name of :data:`relight.net.model.ARCHES`), ``config`` (the
:class:`~relight.net.model.NetConfig` as JSON) and ``info`` (free JSON: training
settings, data, epoch). Anything else -- a missing file, a different format, wrong
tensor names or shapes -- raises :class:`ModelFileError` with a one-line reason.

Shipped models live in :data:`MODELS_DIR` as ``NAME.safetensors`` (with ``NAME.json``,
``NAME_log.csv``, ``NAME_reliability.png`` and a card, written by ``scripts/ship_model.py``),
one per name of :data:`SHIPPED_NAMES`: ``photo`` (trained for real photographs), ``sid2``
(relight's SID2-style synthetic rooms) and ``object`` (photographs of objects read through an
object mask: the objects alone, ``relight predict --model object --mask MASK``). :func:`resolve_model` turns what a user gives
(``None``, a shipped name, a file or a run folder) into a model file; ``None`` means the
first shipped name of :data:`DEFAULT_MODELS` whose file is present. This module imports no
torch until a model is read or written (the command line's options use its names).
"""
from __future__ import annotations

__all__ = ["stored_float_dtype",
    "MODEL_FORMAT", "MODELS_DIR", "SHIPPED_NAMES", "DEFAULT_MODELS", "SHIPPED_NAME", "SHIPPED_MODEL",
    "shipped_model_path", "named_file", "resolve_model", "default_model_name", "model_label", "save_model",
    "read_model_file", "read_model_header", "load_model_file", "ModelFileError",
]

import json
import os
from typing import TYPE_CHECKING

from relight.errors import ModelFileError, brief

if TYPE_CHECKING:   # torch and the network load with the first model read or written
    import torch

    from relight.net.model import LightNet, NetConfig

MODEL_FORMAT = "relight.model/v1"
MODELS_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "models")
SHIPPED_NAMES = ("photo", "sid2", "object")   # NAME.safetensors, NAME.json, NAME_log.csv, NAME_reliability.png
DEFAULT_MODELS = ("photo", "sid2")   # what no --model means: the first of these that is shipped
SHIPPED_NAME = "sid2"   # the SID2-style model (the paper's Tables 1-3); always shipped
SHIPPED_MODEL = os.path.join(MODELS_DIR, f"{SHIPPED_NAME}.safetensors")


def shipped_model_path(name: str) -> str:
    """The file of shipped model ``name`` (one of :data:`SHIPPED_NAMES`) in
    :data:`MODELS_DIR`, present or not.

    >>> os.path.basename(shipped_model_path("photo"))
    'photo.safetensors'
    """
    if name not in SHIPPED_NAMES:
        raise ModelFileError(f"no shipped model is named {name!r} (shipped names: {', '.join(SHIPPED_NAMES)})")
    return os.path.join(MODELS_DIR, f"{name}.safetensors")


def named_file(value: str | os.PathLike | None) -> str | None:
    """What a ``--model`` value names on disk: a shipped name's file (ModelFileError, one
    line, when this build lacks it), else the value as given (a file or a run folder, not
    resolved; ``None`` stays ``None``). The commands check their outputs against it
    (:func:`relight.fileio.check_outputs`); :func:`resolve_model` gives the model file itself."""
    if value is None:
        return None
    value = os.fspath(value)
    return resolve_model(value) if value in SHIPPED_NAMES else value


def default_model_name() -> str | None:
    """The shipped name no ``--model`` means: the first of :data:`DEFAULT_MODELS` whose file
    is present (``photo``, else ``sid2``); ``None`` when none is."""
    return next((name for name in DEFAULT_MODELS if os.path.isfile(shipped_model_path(name))), None)


def resolve_model(value: str | os.PathLike | None = None) -> str:
    """The model file ``value`` means, or :class:`ModelFileError` with one line.

    * ``None``: the default shipped model (:func:`default_model_name`: ``photo``, else ``sid2``);
    * a shipped name (``photo``, ``sid2``): that shipped file, which must be present (a file or
      folder of that name in the working folder is given as ``./NAME``);
    * anything else: a ``.safetensors`` file, or a training run folder (its ``best.safetensors``).
    """
    if value is None:
        name = default_model_name()
        if name is None:
            raise ModelFileError(f"no shipped model in {MODELS_DIR} ({' or '.join(f'{n}.safetensors' for n in DEFAULT_MODELS)}); "
                                 "give --model FILE")
        return shipped_model_path(name)
    value = os.fspath(value)
    if value in SHIPPED_NAMES:
        path = shipped_model_path(value)
        if not os.path.isfile(path):
            present = [n for n in SHIPPED_NAMES if os.path.isfile(shipped_model_path(n))]
            raise ModelFileError(f"shipped model {value!r} is not in this build ({path} is missing; "
                                 f"shipped: {', '.join(present) or 'none'})")
        return path
    try:
        return _model_path(value)
    except ModelFileError:
        if not os.path.exists(value) and os.sep not in value and not value.endswith(".safetensors"):
            raise ModelFileError(f"model not found: {value!r} is neither a shipped model name "
                                 f"({', '.join(SHIPPED_NAMES)}) nor a file or run folder") from None
        raise


def model_label(value: str | os.PathLike | None) -> str:
    """How reports and predictions files name the model ``value`` means: the shipped name
    for ``None`` (the default it resolves to) or a shipped name, else the path as given."""
    if value is None:
        return default_model_name() or "shipped"
    return os.fspath(value)


def save_model(path: str | os.PathLike, model: LightNet, info: dict | None = None,
               dtype: torch.dtype | None = None) -> None:
    """Write ``model`` (weights + config + ``info``) to ``path`` atomically; ``dtype``
    (e.g. ``torch.float16``) stores the floating-point tensors in that type."""
    from safetensors.torch import save_file
    path = os.fspath(path)
    if model.folded:
        raise ValueError("cannot save a network with folded batch norms (inference only); "
                         "save the one load_model_file returns")
    # the out-of-distribution statistics stay float32 (a half-precision threshold moves the flag)
    state = {k: v.detach().cpu().to(dtype if dtype is not None and v.is_floating_point()
                                    and not k.startswith("ood_") else v.dtype)
             .contiguous() for k, v in model.state_dict().items()}
    meta = {"format": MODEL_FORMAT, "arch": model.config.arch_name,
            "config": json.dumps(model.config.to_dict()), "info": json.dumps(info or {})}
    from relight.fileio import atomic_write

    def write(tmp):
        save_file(state, tmp, metadata=meta)
        os.chmod(tmp, 0o644)  # a shipped, readable package file
    atomic_write(path, write)


def _model_path(path: str | os.PathLike) -> str:
    """The model file ``path`` names (a run folder means its ``best.safetensors``)."""
    path = os.fspath(path)
    if os.path.isdir(path):
        candidate = os.path.join(path, "best.safetensors")
        if not os.path.isfile(candidate):
            raise ModelFileError(f"{path} is a folder without best.safetensors (give a .safetensors model file)")
        path = candidate
    if not os.path.isfile(path):
        raise ModelFileError(f"model file not found: {path}")
    return path


def _read(path: str | os.PathLike, tensors: bool) -> tuple[NetConfig, dict, dict]:
    from safetensors import SafetensorError, safe_open

    from relight.net.model import ARCHES, NetConfig
    path = _model_path(path)
    try:
        with safe_open(path, framework="pt") as f:
            meta = f.metadata() or {}
            state = {k: f.get_tensor(k) for k in f.keys()} if tensors else {}
    except (SafetensorError, OSError, ValueError, RuntimeError) as exc:
        raise ModelFileError(f"{path}: not a readable safetensors model ({brief(exc)})") from None
    if meta.get("format") != MODEL_FORMAT:
        raise ModelFileError(f"{path}: expected a {MODEL_FORMAT!r} model, got format {meta.get('format')!r}")
    arch = {name: key for key, name in ARCHES.items()}.get(meta.get("arch"))
    if arch is None:
        raise ModelFileError(f"{path}: unsupported architecture {meta.get('arch')!r} "
                             f"(expected one of {', '.join(map(repr, ARCHES.values()))})")
    try:
        config = NetConfig.from_dict(json.loads(meta.get("config", "")) | {"arch": arch})
        info = json.loads(meta.get("info", "{}"))
    except (json.JSONDecodeError, TypeError, ValueError) as exc:
        raise ModelFileError(f"{path}: bad model metadata ({brief(exc)})") from None
    return config, state, info


def read_model_file(path: str | os.PathLike) -> tuple[NetConfig, dict, dict]:
    """``(config, state_dict, info)`` of a model file; raises :class:`ModelFileError`."""
    return _read(path, tensors=True)


def read_model_header(path: str | os.PathLike) -> tuple[NetConfig, dict]:
    """``(config, info)`` of a model file from its header alone (no tensor is read)."""
    config, _, info = _read(path, tensors=False)
    return config, info


def load_model_file(path: str | os.PathLike) -> LightNet:
    """Build the network of a model file, weights loaded, in eval mode."""
    import torch

    from relight.net.model import LightNet
    config, state, info = read_model_file(path)
    model = LightNet(config)
    expected = model.state_dict()
    missing = sorted(set(expected) - set(state))
    unexpected = sorted(set(state) - set(expected))
    if missing or unexpected:
        what = f"missing {missing[0]!r}" if missing else f"unexpected {unexpected[0]!r}"
        raise ModelFileError(f"{os.fspath(path)}: weights do not match the network ({what}, "
                             f"{len(missing)} missing, {len(unexpected)} unexpected)")
    for k, v in state.items():
        if v.shape != expected[k].shape:
            raise ModelFileError(f"{os.fspath(path)}: tensor {k!r} has shape {tuple(v.shape)}, "
                                 f"expected {tuple(expected[k].shape)}")
        if v.is_floating_point() and not torch.isfinite(v).all():
            raise ModelFileError(f"{os.fspath(path)}: tensor {k!r} holds NaN or inf")
    model.load_state_dict(state)
    model.info = info
    return model.eval()


def stored_float_dtype(path: str | os.PathLike) -> torch.dtype:
    """The floating-point type a model file stores its weights in (float16 for a shipped file)."""
    import torch
    from safetensors import safe_open
    with safe_open(_model_path(path), framework="pt") as f:
        for key in f.keys():
            if key.startswith("ood_"):
                continue
            t = f.get_slice(key)
            dtype = {"F16": torch.float16, "BF16": torch.bfloat16, "F32": torch.float32, "F64": torch.float64}.get(
                t.get_dtype())
            if dtype is not None:
                return dtype
    return torch.float32

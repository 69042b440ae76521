"""Training as in the paper: Adam (lr 2e-4), ReduceLROnPlateau (factor 0.1) on the
validation loss, batch size 16, He-normal initialisation (in the model).

A run folder holds:
    settings.json      the run's final settings (repeat it with the same command)
    checkpoint.pt      full state after the last finished epoch (model, optimiser,
                       scheduler, epoch, history); tensors only, loaded with
                       ``torch.load(weights_only=True)``
    last.safetensors   weights after the last epoch; best.safetensors: lowest val loss
    log.csv            one row per epoch (losses, val errors in degrees, lr, time)
    curves.png         the curves of log.csv

Re-running the identical command continues an interrupted run; ``resume=True`` also
continues one whose settings changed in ways that keep it meaningful (``epochs``,
``lr``, ``patience``...). Resuming continues from checkpoint.pt to ``epochs``; the shuffling
and flip augmentation depend only on (seed, epoch), so an interrupted and resumed run
follows the same path as an uninterrupted one. A dataset still being generated may be
used: the manifest is re-read at the start of each epoch (``grow``).

Several processes: ``torchrun --nproc-per-node N -m relight train ...`` trains with
DistributedDataParallel (gloo on CPU, nccl on CUDA): each process takes its share of
every epoch through a DistributedSampler (seeded by (seed, epoch)), gradients are
averaged, and rank 0 alone holds the folder lock and writes settings, checkpoints,
weights and the log; the logged training losses are summed over all processes. One
process (no ``torchrun``, or one rank) is exactly the single-process path.
"""
from __future__ import annotations

__all__ = [
    "CHECKPOINT", "SETTINGS", "LOG", "LOG_FIELDS", "TrainConfig", "net_config", "plot_curves",
    "distributed_rank_world", "train", "RESOURCE_KEYS",
    "camera_loss", "with_camera_head",
    "with_heads",
]

import csv
import json
import math
import os
import time
from dataclasses import asdict, dataclass, field

import numpy as np
import torch

from relight.dataset import DatasetError
from relight.errors import TrainingError, brief
from relight.fileio import FolderLock, atomic_write, write_json
from relight.net.data import LightDataset, dataset_folders, folders_record
from relight.net.evaluate import errors_from_y, run_model
from relight.net.io import save_model
from relight.net.loss import LossWeights, light_loss
from relight.net.model import ARCHES, LightNet, NetConfig, count_parameters
from relight.net.uncertainty import fit_temperature, uncertainty_summary

CHECKPOINT = "checkpoint.pt"
SETTINGS = "settings.json"
LOG = "log.csv"
LOG_FIELDS = ["epoch", "lr", "n_train", "n_val", "train_loss", "train_pan", "train_tilt", "train_colour_rad",
              "val_loss", "val_pan_deg", "val_tilt_deg", "val_direction_deg", "val_colour_deg",
              "epoch_time_s", "train_img_per_s", "train_kappa_nll", "val_kappa_nll", "val_cone90_cover",
              "kappa_temperature", "train_camera", "val_camera_tilt_deg"]


@dataclass(frozen=True)
class TrainConfig:
    """Settings of one training run (written to ``settings.json``).

    Attributes:
        data_dir: dataset folder (``relight generate`` output), or a tuple of folders
            trained on together (their splits joined; e.g. two background styles).
        epochs: total number of epochs (a resumed run continues up to it).
        batch_size, lr: the paper's 16 and 2e-4.
        res: network input size in pixels.
        seed: weights initialisation, shuffling and flip augmentation.
        flip: horizontal-flip augmentation (labels mirrored, pan_rel -> 360 - pan_rel).
        plateau_patience: epochs without val improvement before lr *= 0.1.
        threads: torch CPU threads (1 is fastest on a busy 2-core machine).
        workers: DataLoader worker processes (0: load in the main process, with cache).
        grow: re-read the manifest each epoch (dataset still being generated).
        train_split, val_split: manifest splits used; an empty val split falls back
            to the train split (tiny datasets).
        loss_weights: alpha_1..3 of the loss.
        width: network base width (see NetConfig).
        arch: encoder, ``"small"`` or ``"paper"`` (:data:`relight.net.model.ARCHES`).
        kappa_detach: the kappa head reads the embedding detached (default; see
            :attr:`relight.net.model.NetConfig.kappa_detach`).
        init: a model file to fine-tune (its network and weights replace ``arch``,
            ``width`` and the initialisation; ``res`` must match it). The val loss of
            the loaded model before any step is written to settings.json (``init_val_loss``).
        image_key: the record field of the input image (``image_masked``: the MID-like
            set's copies with the spheres painted out).
        camera_weight: > 0 adds a camera-tilt head (``NetConfig.camera_head``) trained by the
            MSE of (sin, cos) of the camera tilt, with this weight (also in the val loss).
        source: ``"image"`` (the dataset's 8-bit PNGs) or ``"exr"`` (its linear EXRs, through
            ``augment``).
        augment: camera-pipeline augmentation of an ``exr`` source, a key of
            :data:`relight.net.augment.AUGMENTS` (``"none"``: as the PNGs are written;
            ``"photo"``: exposure, noise, vignetting, blur, tone curve, JPEG).
        target_frame: what the network learns, a name of :data:`relight.frames.TARGET_FRAMES`:
            ``"world"`` (the paper's 7-vector, decoded with the camera tilt) or ``"camera"``
            (the light in the camera frame, :func:`relight.frames.y_to_target`); recorded
            in the model file (``NetConfig.target_frame``).
        max_minutes: stop after the first epoch that ends past this wall time
            (minutes from the start of this invocation; None: no limit). A later
            ``resume`` continues from there.
        epoch_images: images per epoch (None: the whole training split). On a large set
            a shorter epoch validates, checkpoints and steps the scheduler more often; the
            epochs walk one seeded permutation after another, so every image is seen
            once before any is seen twice (:func:`_epoch_order`).
    """
    data_dir: str | tuple[str, ...]
    epochs: int = 10
    batch_size: int = 16
    lr: float = 2e-4
    res: int = 128
    seed: int = 0
    flip: bool = True
    plateau_patience: int = 2
    threads: int = 1
    workers: int = 0
    grow: bool = True
    train_split: str = "train"
    val_split: str = "val"
    loss_weights: LossWeights = field(default_factory=LossWeights)
    width: int = 32
    max_minutes: float | None = None
    arch: str = "small"
    kappa_detach: bool = True
    init: str | None = None
    image_key: str = "image"
    camera_weight: float = 0.0
    source: str = "image"
    augment: str = "none"
    target_frame: str = "world"
    epoch_images: int | None = None
    surround: str = "keep"

    def __post_init__(self):
        folders = tuple(dataset_folders(self.data_dir))   # one folder stays a plain string (older runs)
        object.__setattr__(self, "data_dir", folders[0] if len(folders) == 1 else folders)
        for name in ("epochs", "batch_size", "res", "threads"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < 1:
                raise TrainingError(f"{name} must be a positive integer, got {v!r}")
        if self.epoch_images is not None and not (isinstance(self.epoch_images, int) and self.epoch_images >= 1):
            raise TrainingError(f"epoch_images must be a positive integer, got {self.epoch_images!r}")
        if self.workers < 0 or self.plateau_patience < 0:
            raise TrainingError("workers and plateau_patience must be >= 0")
        if not (isinstance(self.seed, int) and 0 <= self.seed < 2 ** 32):
            raise TrainingError(f"seed must be an integer in [0, 2**32), got {self.seed!r}")
        if self.max_minutes is not None and not (0 <= self.max_minutes < math.inf):
            raise TrainingError(f"max_minutes must be a finite number >= 0, got {self.max_minutes!r}")
        w = self.loss_weights
        if max(w.pan, w.tilt, w.colour) <= 0:
            raise TrainingError("loss weights must not all be zero")
        if self.arch not in ARCHES:
            raise TrainingError(f"arch must be one of {', '.join(ARCHES)}, got {self.arch!r}")
        if not (isinstance(self.lr, float) and 0 < self.lr < 1):
            raise TrainingError(f"lr must be in (0, 1), got {self.lr!r}")
        if not (isinstance(self.camera_weight, (int, float)) and 0 <= self.camera_weight < math.inf):
            raise TrainingError(f"camera_weight must be a finite number >= 0, got {self.camera_weight!r}")
        from relight.net.augment import AUGMENTS
        from relight.net.data import SOURCES
        if self.source not in SOURCES or self.augment not in AUGMENTS:
            raise TrainingError(f"source must be one of {', '.join(SOURCES)} and augment one of "
                                f"{', '.join(AUGMENTS)}, got {self.source!r} and {self.augment!r}")
        if self.augment != "none" and self.source != "exr":
            raise TrainingError("--augment works on the linear EXRs: give --source exr")
        from relight.net.data import NET_SURROUNDS
        if self.surround not in NET_SURROUNDS:
            raise TrainingError(f"surround must be one of {', '.join(NET_SURROUNDS)}, got {self.surround!r}")
        if self.surround != "keep" and self.source != "exr":
            raise TrainingError("--surround black works on the linear EXRs and their masks: give --source exr")
        if self.image_key not in ("image", "image_masked"):
            raise TrainingError(f"image_key must be 'image' or 'image_masked', got {self.image_key!r}")
        from relight.frames import check_target_frame
        try:
            check_target_frame(self.target_frame)
        except ValueError as exc:
            raise TrainingError(str(exc)) from None

    def to_dict(self) -> dict:
        return asdict(self)


def _check_resume_compatible(saved: dict, cfg: TrainConfig) -> None:
    for key in ("res", "batch_size", "seed", "width", "flip", "arch", "kappa_detach", "init", "image_key",
                "camera_weight", "target_frame", "epoch_images", "surround"):
        if key not in saved and key not in LATER_DEFAULTS:
            continue
        was = saved.get(key, LATER_DEFAULTS.get(key))
        if was != getattr(cfg, key):
            raise TrainingError(f"cannot resume: {key} was {was!r} in this run, now {getattr(cfg, key)!r}")


# Settings added after the first runs: a settings.json without the key means this value.
LATER_DEFAULTS = {"camera_weight": 0.0, "source": "image", "augment": "none", "target_frame": "world",
                  "epoch_images": None, "surround": "keep"}


def net_config(cfg: TrainConfig, saved: dict | None = None) -> NetConfig:
    """The network of a run: ``cfg``'s, or for a resumed run the one its checkpoint's
    settings describe (runs from before the kappa head and ``arch`` continue as they were)."""
    if saved is None:
        return NetConfig.for_arch(cfg.arch, res=cfg.res, width=cfg.width,
                                  kappa_head=cfg.loss_weights.kappa > 0, kappa_detach=cfg.kappa_detach,
                                  camera_head=cfg.camera_weight > 0, target_frame=cfg.target_frame,
                                  surround=cfg.surround)
    weights = saved.get("loss_weights") or {}
    return NetConfig.for_arch(saved.get("arch", "small"), res=cfg.res, width=cfg.width,
                              kappa_head=float(weights.get("kappa", 0.0)) > 0,
                              kappa_detach=bool(saved.get("kappa_detach", True)),
                              camera_head=float(saved.get("camera_weight", 0.0)) > 0,
                              target_frame=saved.get("target_frame", "world"),
                              surround=saved.get("surround", "keep"))


def _camera_tilts(dataset: LightDataset, index) -> torch.Tensor:
    return torch.tensor([float(dataset.records[int(i)]["camera"]["tilt_deg"]) for i in index])


def camera_loss(camera: torch.Tensor, camera_tilt_deg: torch.Tensor) -> torch.Tensor:
    """MSE of a camera head's ``(N, 2)`` output against (sin, cos) of the true tilts ``(N,)`` (degrees)."""
    t = torch.deg2rad(camera_tilt_deg.to(camera.dtype))
    return torch.mean((camera - torch.stack([torch.sin(t), torch.cos(t)], dim=1)) ** 2)


def with_heads(model: LightNet, **changes) -> LightNet:
    """A copy of ``model`` whose config differs by ``changes`` in its optional parts (a camera
    head, the out-of-distribution statistics): new parts start fresh (He-initialised), dropped
    ones are left behind, every other weight is kept."""
    import dataclasses
    changed = LightNet(dataclasses.replace(model.config, **changes))
    state = {k: v for k, v in model.state_dict().items() if k in changed.state_dict()}
    missing, _ = changed.load_state_dict(state, strict=False)
    if any(not k.startswith(("camera_head.", "ood_")) for k in missing):
        raise TrainingError("cannot change the optional parts of this model")
    return changed


def with_camera_head(model: LightNet) -> LightNet:
    """A copy of ``model`` with a new (He-initialised) camera-tilt head; every other weight kept."""
    return with_heads(model, camera_head=True)


def _permutation(n: int, seed: int, index: int) -> list[int]:
    g = torch.Generator().manual_seed(seed * 1_000_003 + index)
    return torch.randperm(n, generator=g).tolist()


def _epoch_order(n: int, seed: int, epoch: int, epoch_images: int | None = None) -> list[int]:
    """The training images of ``epoch``, in order: a permutation of all ``n`` seeded by
    (seed, epoch), or with ``epoch_images`` the epoch's slice of the endless sequence of
    permutations seeded by (seed, 0), (seed, 1)... (each image once per pass)."""
    if epoch_images is None:
        return _permutation(n, seed, epoch)
    start, out = epoch * epoch_images, []
    npass, offset = divmod(start, n)
    while len(out) < epoch_images:
        out += _permutation(n, seed, npass)[offset:offset + epoch_images - len(out)]
        npass, offset = npass + 1, 0
    return out


def _save_checkpoint(path: str, state: dict) -> None:
    atomic_write(path, lambda tmp: torch.save(state, tmp))


def _load_checkpoint(path: str) -> dict:
    """The checkpoint's state, checked; :class:`TrainingError` (one line) if it is empty,
    corrupt, truncated or not a relight checkpoint."""
    try:
        state = torch.load(path, weights_only=True)
    except Exception as exc:  # noqa: BLE001 - torch raises many types for bad files
        raise TrainingError(f"{path}: cannot read checkpoint ({brief(exc)}); delete it to start over") from None
    keys = ("model", "optimiser", "scheduler", "epoch", "history", "best_val_loss", "settings", "torch_rng")
    if not isinstance(state, dict) or any(k not in state for k in keys) \
            or not isinstance(state["settings"], dict) or not isinstance(state["history"], list):
        raise TrainingError(f"{path}: not a relight training checkpoint; delete it to start over")
    return state


def _write_log(path: str, rows: list[dict]) -> None:
    def write(tmp):
        with open(tmp, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=LOG_FIELDS)
            w.writeheader()
            for r in rows:
                w.writerow({k: r.get(k, "") for k in LOG_FIELDS})
    atomic_write(path, write)


def plot_curves(rows: list[dict], path: str) -> None:
    """PNG of training/validation loss and validation errors (degrees) per epoch."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    ep = [r["epoch"] for r in rows]
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    a.plot(ep, [r["train_loss"] for r in rows], "o-", label="train")
    a.plot(ep, [r["val_loss"] for r in rows], "o-", label="val")
    a.set_yscale("log"), a.set_xlabel("epoch"), a.set_ylabel("loss"), a.legend(), a.grid(alpha=0.3)
    for key, lab in (("val_direction_deg", "direction"), ("val_pan_deg", "pan"),
                     ("val_tilt_deg", "tilt"), ("val_colour_deg", "colour")):
        b.plot(ep, [r[key] for r in rows], "o-", label=lab)
    b.set_xlabel("epoch"), b.set_ylabel("mean val error (deg)"), b.legend(), b.grid(alpha=0.3)
    fig.tight_layout()
    try:
        atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=100, format="png"))
    finally:
        plt.close(fig)


def distributed_rank_world() -> tuple[int, int]:
    """``(rank, world size)`` when started by ``torchrun`` with more than one process
    (``RANK``/``WORLD_SIZE`` set), else ``(0, 1)``."""
    try:
        world = int(os.environ.get("WORLD_SIZE", "1") or 1)
        rank = int(os.environ.get("RANK", "0") or 0)
    except ValueError:
        raise TrainingError("RANK and WORLD_SIZE must be integers (set by torchrun)") from None
    return (rank, world) if world > 1 else (0, 1)


class _KappaForward(torch.nn.Module):
    """``forward`` = ``net.forward_full(x, calibrated=False)``, so that
    DistributedDataParallel (which hooks ``forward``) sees the training pass."""

    def __init__(self, net):
        super().__init__()
        self.net = net

    def forward(self, x):
        return self.net.forward_full(x, calibrated=False)


def _ddp_agree(dataset: LightDataset) -> None:
    """Under DDP, keep the records every process has read (a growing manifest may be
    read at slightly different moments; records keep file order, so a prefix agrees)."""
    import torch.distributed as dist
    sizes = torch.tensor(dataset.part_sizes())
    dist.all_reduce(sizes, op=dist.ReduceOp.MIN)
    dataset.keep_first(sizes.tolist())


def train(cfg: TrainConfig, out_dir: str | os.PathLike, resume: bool = False, progress: bool = True) -> dict:
    """Train (or resume) a run in ``out_dir``; returns the last log row (dict). The run
    folder is locked for the duration (one writer); the identical command resumes.
    Under ``torchrun`` with several processes, trains with DDP (rank 0 writes and
    returns the row; other ranks return ``{}``)."""
    out_dir = os.fspath(out_dir)
    rank, world = distributed_rank_world()
    if world > 1:
        import torch.distributed as dist
        if not dist.is_initialized():
            dist.init_process_group("nccl" if torch.cuda.is_available() else "gloo")
        try:
            if rank != 0:   # rank 0 locks the folder (below), then all meet at a barrier
                _train_locked(cfg, out_dir, resume, False, ddp=(rank, world))
                return {}   # rank 0 reports
            return _train_rank0(cfg, out_dir, resume, progress, (rank, world))
        finally:
            dist.destroy_process_group()
    return _train_rank0(cfg, out_dir, resume, progress, None)


def _train_rank0(cfg: TrainConfig, out_dir: str, resume: bool, progress: bool, ddp) -> dict:
    lock, existed = FolderLock.take(out_dir, "training run")
    try:
        return _train_locked(cfg, out_dir, resume, progress, ddp=ddp)
    except BaseException:
        if not existed and not os.path.exists(os.path.join(out_dir, CHECKPOINT)):
            lock.remove_made()   # nothing was trained: leave no folder (nor parents made for it)
        raise
    finally:
        lock.release()


def _dataset_loss(model, dataset: LightDataset, cfg: TrainConfig) -> float:
    """The paper's loss of ``model`` over ``dataset`` (eval mode, no augmentation): what
    the log's ``val_loss`` measures after each epoch."""
    y, _ = run_model(model, dataset, cfg.batch_size * 4, with_kappa=True)
    target = torch.from_numpy(np.stack([dataset.target(i) for i in range(len(dataset))])).float()
    with torch.no_grad():
        return float(light_loss(torch.from_numpy(y), target, cfg.loss_weights))


# How a run is executed, not what it learns: changing them never blocks a plain re-run.
RESOURCE_KEYS = ("threads", "workers")


def _same_run(saved: dict, cfg: TrainConfig) -> bool:
    """True when ``saved`` (settings.json) holds the settings of ``cfg`` (the identical command),
    apart from the machine resources it uses (``RESOURCE_KEYS``)."""
    now = json.loads(json.dumps(cfg.to_dict()))
    return all(saved.get(k, LATER_DEFAULTS.get(k)) == v for k, v in now.items() if k not in RESOURCE_KEYS)


@dataclass
class _Run:
    """A training run as restored or started: what the epochs update."""
    model: LightNet
    optimiser: torch.optim.Optimizer
    scheduler: torch.optim.lr_scheduler.ReduceLROnPlateau
    train_set: LightDataset
    val_set: LightDataset
    start_epoch: int
    rows: list
    best: float
    net: object = None          # the DistributedDataParallel wrapper under torchrun


def _restore(cfg: TrainConfig, out_dir: str, resume: bool, ddp, writer: bool) -> _Run:
    """Check the folder's run, seed, load ``--init`` and the data, and restore the
    checkpoint when resuming; writes ``settings.json`` (rank 0)."""
    ckpt_path = os.path.join(out_dir, CHECKPOINT)
    if os.path.exists(ckpt_path) and not resume:
        try:
            with open(os.path.join(out_dir, SETTINGS)) as f:
                saved = json.load(f)
        except (OSError, ValueError):
            saved = {}
        if not (isinstance(saved, dict) and _same_run(saved, cfg)):
            raise TrainingError(f"{out_dir} already holds a run with other settings; add --resume to "
                                "continue it with these settings or use a new --out")
        resume = True   # the identical command: continue where it stopped
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)

    init_model = None
    if cfg.init is not None:   # a bad model file fails here, before any work
        from relight.net.io import load_model_file
        init_model = load_model_file(cfg.init)
        if init_model.config.res != cfg.res:
            raise TrainingError(f"--init model takes {init_model.config.res} px inputs; give --res "
                                f"{init_model.config.res}")
        if init_model.config.ood_dims:   # training moves the embedding: the detector must be fitted again
            init_model = with_heads(init_model, ood_dims=0)
        if cfg.camera_weight > 0 and not init_model.has_camera:   # a new camera head on the loaded network
            init_model = with_camera_head(init_model)
        if init_model.config.target_frame != cfg.target_frame:   # its outputs learn the other frame's target
            init_model = with_heads(init_model, target_frame=cfg.target_frame)
        if init_model.config.surround != cfg.surround:   # it learns to read what this run shows it
            init_model = with_heads(init_model, surround=cfg.surround)
    from relight.net.augment import AUGMENTS
    train_set = LightDataset(cfg.data_dir, cfg.train_split, cfg.res, flip=cfg.flip, seed=cfg.seed,
                             image_key=cfg.image_key, source=cfg.source, target_frame=cfg.target_frame,
                             augment=AUGMENTS[cfg.augment]() if cfg.augment != "none" else None,
                             surround=cfg.surround)
    val_set = LightDataset(cfg.data_dir, cfg.val_split, cfg.res, image_key=cfg.image_key, source=cfg.source,
                           target_frame=cfg.target_frame, surround=cfg.surround)
    if ddp is not None:
        _ddp_agree(train_set), _ddp_agree(val_set)
    if len(train_set) == 0:
        raise DatasetError(f"{', '.join(dataset_folders(cfg.data_dir))}: no records in split {cfg.train_split!r}")

    state = _load_checkpoint(ckpt_path) if resume and os.path.exists(ckpt_path) else None
    if state is not None:
        _check_resume_compatible(state["settings"], cfg)
    model = init_model.train() if init_model is not None else \
        LightNet(net_config(cfg, state["settings"] if state is not None else None))
    optimiser = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    scheduler = torch.optim.lr_scheduler.ReduceLROnPlateau(optimiser, mode="min", factor=0.1,
                                                           patience=cfg.plateau_patience)
    start_epoch, rows, best = 0, [], math.inf
    if state is not None:
        try:
            model.load_state_dict(state["model"])
            optimiser.load_state_dict(state["optimiser"])
            scheduler.load_state_dict(state["scheduler"])
            start_epoch, rows, best = int(state["epoch"]), list(state["history"]), float(state["best_val_loss"])
            torch.set_rng_state(state["torch_rng"])
            if state["settings"].get("lr", cfg.lr) != cfg.lr:   # --resume --lr X: continue at X
                for group in optimiser.param_groups:
                    group["lr"] = cfg.lr
            scheduler.patience = cfg.plateau_patience   # the loaded state carries the old one
        except (RuntimeError, ValueError, TypeError, KeyError, AttributeError) as exc:
            raise TrainingError(f"{ckpt_path}: checkpoint does not match this network "
                                f"({brief(exc)}); delete it to start over") from None
    settings = cfg.to_dict() | {"out_dir": out_dir, "parameters": count_parameters(model)}
    if init_model is not None:   # the starting point: the loaded model's val loss before any step
        if state is None:
            start_set = val_set if len(val_set) else train_set.unaugmented()
            settings["init_val_loss"] = _dataset_loss(model, start_set, cfg)
        else:
            try:
                with open(os.path.join(out_dir, SETTINGS)) as f:
                    settings["init_val_loss"] = json.load(f).get("init_val_loss")
            except (OSError, ValueError):
                pass
    if writer:
        write_json(os.path.join(out_dir, SETTINGS), settings)
    net = None
    if ddp is not None:
        from torch.nn.parallel import DistributedDataParallel
        net = DistributedDataParallel(_KappaForward(model))
    return _Run(model, optimiser, scheduler, train_set, val_set, start_epoch, rows, best, net)


def _train_epoch(run: _Run, cfg: TrainConfig, epoch: int, progress: bool, ddp) -> tuple[dict, int, float]:
    """One pass over the training split: ``(summed loss parts, images seen, seconds)``;
    under torchrun the sums cover every process's share."""
    from torch.utils.data import DataLoader
    from tqdm import tqdm
    model, train_set = run.model, run.train_set
    train_set.epoch = epoch
    if ddp is None:
        sampler = _epoch_order(len(train_set), cfg.seed, epoch, cfg.epoch_images)
    elif cfg.epoch_images is not None:   # every rank draws the same epoch, each takes its share
        sampler = _epoch_order(len(train_set), cfg.seed, epoch, cfg.epoch_images)[ddp[0]::ddp[1]]
    else:
        from torch.utils.data.distributed import DistributedSampler
        sampler = DistributedSampler(train_set, num_replicas=ddp[1], rank=ddp[0], shuffle=True,
                                     seed=cfg.seed, drop_last=False)
        sampler.set_epoch(epoch)
    loader = DataLoader(train_set, batch_size=cfg.batch_size, num_workers=cfg.workers,
                        sampler=sampler, drop_last=False)
    model.train()
    sums, seen, t0 = {"total": 0.0, "pan": 0.0, "tilt": 0.0, "colour": 0.0, "kappa_nll": 0.0,
                      "camera": 0.0}, 0, time.perf_counter()
    bar = tqdm(loader, desc=f"epoch {epoch + 1}/{cfg.epochs}", disable=not progress, leave=False,
               dynamic_ncols=True)
    for x, y, index in bar:
        y_pred, kappa, camera = model.forward_full(x, calibrated=False) if run.net is None else run.net(x)
        tilts = _camera_tilts(train_set, index)
        parts = light_loss(y_pred, y, cfg.loss_weights, parts=True, kappa=kappa,
                           camera_tilt_deg=torch.from_numpy(train_set.target_tilts(index))
                           if kappa is not None else None)
        parts["camera"] = None
        if camera is not None:   # the camera-tilt head (--camera-weight)
            parts["camera"] = camera_loss(camera, tilts)
            parts["objective"] = parts["objective"] + cfg.camera_weight * parts["camera"]
        run.optimiser.zero_grad(set_to_none=True)
        parts["objective"].backward()
        run.optimiser.step()
        for k in sums:
            if parts[k] is not None:
                sums[k] += float(parts[k].detach()) * len(x)
        seen += len(x)
        bar.set_postfix(loss=f"{sums['total'] / seen:.4f}")
    if ddp is not None:   # the log's training figures cover every process's share
        import torch.distributed as dist
        totals = torch.tensor([*sums.values(), float(seen)], dtype=torch.float64)
        dist.all_reduce(totals)
        sums, seen = dict(zip(sums, totals[:-1].tolist())), int(totals[-1])
        for buffer in model.buffers():   # batch-norm statistics: rank 0's, as DDP's forward does
            dist.broadcast(buffer, 0)
    return sums, seen, t0


def _validate(run: _Run, cfg: TrainConfig, evaluation_set: LightDataset, train_kappa_nll: float) -> tuple:
    """The loss and the errors on ``evaluation_set``, and kappa's temperature fitted there
    (stored in the model): ``(val_loss, errors in degrees by metric, calibration figures)``."""
    model = run.model
    y_val, kappa_val, camera_val = run_model(model, evaluation_set, cfg.batch_size * 4, with_kappa=True,
                                             with_camera=True)
    with torch.no_grad():
        val_loss = float(light_loss(torch.from_numpy(y_val),
                                    torch.from_numpy(np.stack([evaluation_set.target(i) for i in
                                                               range(len(evaluation_set))])).float(),
                                    cfg.loss_weights))
    camera_log = {}
    if camera_val is not None:   # the camera head's error, and its term of the val loss
        true_tilts = evaluation_set.truth()["camera_tilt_deg"]
        camera_log = {"val_camera_tilt_deg": float(np.mean(np.abs(camera_val - true_tilts)))}
        t = np.radians(camera_val)
        val_loss += cfg.camera_weight * float(camera_loss(torch.from_numpy(np.stack([np.sin(t), np.cos(t)], 1)),
                                                          torch.from_numpy(true_tilts)))
    errs = errors_from_y(y_val, evaluation_set.truth(), cfg.target_frame)
    calibration = {}
    if kappa_val is not None:   # temperature scaling of kappa on val (the model stores T)
        raw = kappa_val * float(model.kappa_temperature)
        temperature = fit_temperature(raw, errs["direction"])
        model.kappa_temperature.fill_(temperature)
        summary = uncertainty_summary(raw / temperature, errs["direction"])
        calibration = {"train_kappa_nll": train_kappa_nll, "val_kappa_nll": summary["nll_mean"],
                       "val_cone90_cover": summary["cone90_coverage"], "kappa_temperature": temperature}
    return val_loss, errs, calibration | camera_log


def _save(run: _Run, cfg: TrainConfig, out_dir: str, epoch: int, val_loss: float, seen: int,
          calibration: dict) -> None:
    """After an epoch (rank 0): last and best weights, the checkpoint, the log and its curves."""
    model = run.model
    info = {"epoch": epoch + 1, "val_loss": val_loss, "data_dir": folders_record(cfg.data_dir),
            "n_train": seen, "settings": cfg.to_dict(),
            **({"kappa_temperature": calibration["kappa_temperature"]} if "kappa_temperature" in calibration else {})}
    save_model(os.path.join(out_dir, "last.safetensors"), model, info)
    if val_loss < run.best:
        run.best = val_loss
        save_model(os.path.join(out_dir, "best.safetensors"), model, info)
    _save_checkpoint(os.path.join(out_dir, CHECKPOINT),
                     {"model": model.state_dict(), "optimiser": run.optimiser.state_dict(),
                      "scheduler": run.scheduler.state_dict(), "epoch": epoch + 1,
                      "history": run.rows, "best_val_loss": run.best, "settings": cfg.to_dict(),
                      "torch_rng": torch.get_rng_state()})
    _write_log(os.path.join(out_dir, LOG), run.rows)
    plot_curves(run.rows, os.path.join(out_dir, "curves.png"))


def _train_locked(cfg: TrainConfig, out_dir: str, resume: bool, progress: bool, ddp=None) -> dict:
    """The training loop; ``ddp`` is ``(rank, world)`` under torchrun (rank 0 writes):
    :func:`_restore`, then per epoch :func:`_train_epoch`, :func:`_validate` and :func:`_save`."""
    from tqdm import tqdm
    writer = ddp is None or ddp[0] == 0
    if ddp is not None:
        import torch.distributed as dist
        dist.barrier()   # rank 0 holds the folder lock from here on
    run = _restore(cfg, out_dir, resume, ddp, writer)
    start_epoch, rows = run.start_epoch, run.rows
    if start_epoch >= cfg.epochs:
        if progress:
            print(f"{out_dir}: already trained for {start_epoch} epochs (asked {cfg.epochs})")
        return rows[-1] if rows else {}

    started = time.perf_counter()
    for epoch in range(start_epoch, cfg.epochs):
        out_of_time = (cfg.max_minutes is not None and epoch > start_epoch
                       and time.perf_counter() - started > 60.0 * cfg.max_minutes)
        if ddp is not None:   # rank 0's clock decides for all
            flag = torch.tensor([int(out_of_time)])
            dist.broadcast(flag, 0)
            out_of_time = bool(flag)
        if out_of_time:
            if progress:
                tqdm.write(f"time budget of {cfg.max_minutes:g} min used after epoch {epoch}; "
                           "resume with --resume to continue")
            break
        if cfg.grow and epoch > start_epoch:
            run.train_set.refresh(), run.val_set.refresh()
            if ddp is not None:
                _ddp_agree(run.train_set), _ddp_agree(run.val_set)
        evaluation_set = run.val_set if len(run.val_set) else run.train_set.unaugmented()
        sums, seen, t0 = _train_epoch(run, cfg, epoch, progress, ddp)
        train_time = time.perf_counter() - t0
        val_loss, errs, calibration = _validate(run, cfg, evaluation_set, sums["kappa_nll"] / seen)
        run.scheduler.step(val_loss)
        row = {"epoch": epoch + 1, "lr": run.optimiser.param_groups[0]["lr"], "n_train": seen,
               "n_val": len(evaluation_set), "train_loss": sums["total"] / seen, "train_pan": sums["pan"] / seen,
               "train_tilt": sums["tilt"] / seen, "train_colour_rad": sums["colour"] / seen, "val_loss": val_loss,
               **{f"val_{m}_deg": float(np.mean(e)) for m, e in errs.items()},
               "epoch_time_s": time.perf_counter() - t0, "train_img_per_s": seen / train_time, **calibration,
               **({"train_camera": sums["camera"] / seen} if "val_camera_tilt_deg" in calibration else {})}
        rows.append(row)
        if not writer:
            continue
        _save(run, cfg, out_dir, epoch, val_loss, seen, calibration)
        if progress:
            tqdm.write(f"epoch {epoch + 1}/{cfg.epochs}: loss {row['train_loss']:.4f} val {val_loss:.4f} | "
                       f"val mean deg: direction {row['val_direction_deg']:.2f} pan {row['val_pan_deg']:.2f} "
                       f"tilt {row['val_tilt_deg']:.2f} colour {row['val_colour_deg']:.2f} | "
                       + (f"90% cone covers {100 * row['val_cone90_cover']:.0f}% (T {row['kappa_temperature']:.2f}) | "
                          if "val_cone90_cover" in calibration else "")
                       + f"lr {row['lr']:.1e} | {seen} img, {row['train_img_per_s']:.1f} img/s")
    return rows[-1]

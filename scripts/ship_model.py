"""Ship a training run as one of the package's named models, evaluate it and write its card.

    .venv/bin/python scripts/ship_model.py [--name sid2|photo] --run RUN --train-data TRAIN \
        --test-data TEST [--model CALIBRATED.safetensors] [--prior-test hsv=DIR --prior-test munsell=DIR]
        [--other-test mosaic=DIR ...]

``--name`` (default ``sid2``) is the shipped name (:data:`relight.net.io.SHIPPED_NAMES`):
``sid2``, the model for SID2-style synthetic rooms (``--model sid2``), or ``photo``, the
model for real photographs and the default of ``relight predict`` / ``relight evaluate``.

1. copies RUN/best.safetensors (or --model, e.g. the output of ``relight calibrate`` on
   RUN; weights unchanged) to relight/models/NAME.safetensors with its metadata,
   plus NAME.json and the training log NAME_log.csv;
2. runs ``relight evaluate`` with the shipped model on every image of TEST (a set never
   used for training) into TEST-eval/ (or --eval-out), and on each --prior-test set (a
   test set of one surface-colour prior) into EVAL-OUT-prior-NAME/, and on each --other-test set
   (other generator settings, e.g. mosaic backgrounds) into EVAL-OUT-other-NAME/;
3. writes the card (relight/models/MODEL_CARD.md for sid2, MODEL_CARD_photo.md for photo;
   :func:`card_file`): data, training, and the paper's Tables 1-3 next
   to ours, the colour error per prior. ``relight evaluate`` reproduces the card's
   numbers exactly. Everything the card says of the model and the data (architecture,
   input size, sampler, noise target, samples per pixel, colour prior) is read from the
   model file and the datasets' cards.

``--models-dir`` writes the model, its card and files elsewhere (a dry run).
"""
from __future__ import annotations

import argparse
import collections
import csv
import json
import os
import shutil
import sys
import torch

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

from relight.dataset import read_card, read_manifest  # noqa: E402
from relight.fileio import atomic_write, write_json, write_text  # noqa: E402
from relight.metrics import METRICS, format_pan_where_defined  # noqa: E402
from relight.net.io import (MODELS_DIR, SHIPPED_NAME, SHIPPED_NAMES, ModelFileError,  # noqa: E402
                            read_model_file, read_model_header, save_model)
from relight.net.model import LightNet, PaperEncoder, count_parameters, flops_per_image  # noqa: E402

SHIPPED_DTYPE = torch.float16   # the package's file at half size; it is evaluated as stored
PAPER = {"pan": 10.46, "tilt": 9.21, "direction": 14.22, "colour": 1.02}   # Table 1, SID2
PAPER_TILT = {"L1": (4.92, 5.14, 7.57, 1.04), "L2": (8.51, 5.14, 11.97, 0.90), "L3": (22.36, 18.33, 28.33, 1.00)}
PAPER_PAN = {"front": (6.87, 5.10, 9.10, 0.98), "right": (6.24, 5.12, 8.80, 0.96),
             "back": (6.35, 5.09, 9.46, 1.03), "left": (6.01, 5.16, 9.03, 0.97)}
STAGE_WORDS = {2: "Two", 3: "Three", 4: "Four", 5: "Five"}
GENERATE_FLAGS = ("res", "spp", "target_rmse", "sampler", "colour_prior", "object_parts", "backgrounds",
                  "max_depth", "mesh_dir")
PRESET_FLAGS = ("colour_prior", "object_parts", "light_colour")   # set by --preset sid2-paper


def card_file(name: str) -> str:
    """The card's file name of shipped model ``name``: ``MODEL_CARD.md`` for sid2 (the
    name every link uses), ``MODEL_CARD_NAME.md`` for another."""
    return "MODEL_CARD.md" if name == SHIPPED_NAME else f"MODEL_CARD_{name}.md"


def default_sentence(name: str) -> str:
    """The card's sentence on what the model is for (``relight.net.io.DEFAULT_MODELS``)."""
    if name == "photo":
        return "It is the default model of `relight predict` and `relight evaluate`."
    if name == "object":
        return ("It reads photographs of objects through an object mask, the objects alone "
                "(`relight predict --model object --mask MASK`); `photo` stays the default.")
    return f"It is the model for SID2-style synthetic rooms: `--model {name}`."


def _copy(src: str, dst: str) -> None:
    atomic_write(dst, lambda tmp: shutil.copyfile(src, tmp))


def dataset_settings(card: dict) -> dict:
    """Generator settings of a dataset card, with the values of cards written before a
    field existed (sampler ``independent``, prior ``hsv``, one-colour objects, pattern backgrounds) and the
    samples per pixel
    the run took (``spp_used``: the card's ``spp``, resolved from the noise target)."""
    from relight.generator.sampling import LEGACY_CONFIG
    cfg = LEGACY_CONFIG | dict(card["config"])
    cfg["spp_used"] = card.get("spp") or cfg.get("spp")
    return cfg


def noise_text(card: dict) -> str:
    """How the dataset set its noise, e.g. ``sampler multijitter, 16 spp (noise target:
    relative RMSE 0.02)`` or ``sampler independent, 32 spp (fixed)``."""
    cfg = dataset_settings(card)
    how = "(fixed)" if cfg.get("spp") is not None else f"(noise target: relative RMSE {cfg['target_rmse']:g})"
    return f"sampler {cfg['sampler']}, {cfg['spp_used']} spp {how}"


def settings_text(card: dict) -> str:
    """The generator settings a card's images differ by, e.g. ``128 px, sampler ..., colour
    prior hsv, objects of 1-32 coloured parts``."""
    cfg = dataset_settings(card)
    lo, hi = cfg["object_parts"]
    parts = "one colour per object" if hi == 1 else f"objects of {lo if lo == hi else f'{lo}-{hi}'} coloured parts"
    light = "" if cfg.get("light_colour", "planckian") == "planckian" else f", {cfg['light_colour']} light colours"
    return (f"{cfg['res']} px, {noise_text(card)}, colour prior {cfg['colour_prior']}, {parts}, "
            f"{cfg['backgrounds']} backgrounds{light}")


def generate_command(card: dict, path: str, count: int) -> tuple[str, str]:
    """``(command, note)``: the ``relight generate`` command that makes a dataset with the
    card's settings (explicit options for the noise, sampler, colour prior, object parts and
    backgrounds; settings
    without an option go into ``--config CONFIG.json``, which the note spells out)."""
    import dataclasses

    from relight.generator.sampling import GeneratorConfig, is_sid2_paper
    default = json.loads(json.dumps(dataclasses.asdict(GeneratorConfig())))
    cfg = dataset_settings(card)
    preset = is_sid2_paper(cfg)
    opts = [f"--count {count}", f"--out {path}", f"--seed {card['seed']}"]
    if preset:   # the preset's own settings go without saying
        opts.insert(0, "--preset sid2-paper")
    if cfg.get("res") != default["res"]:
        opts.append(f"--res {cfg['res']}")
    if cfg.get("spp") is not None:
        opts.append(f"--spp {cfg['spp']}")
    else:
        opts.append(f"--target-rmse {cfg['target_rmse']:g}")
    opts.append(f"--sampler {cfg['sampler']}")
    if not preset:
        opts.append(f"--colour-prior {cfg['colour_prior']}")
        lo, hi = cfg["object_parts"]
        opts.append(f"--object-parts {lo}" if lo == hi else f"--object-parts {lo}-{hi}")
    opts.append(f"--backgrounds {cfg['backgrounds']}")
    if cfg.get("max_depth", default["max_depth"]) != default["max_depth"]:
        opts.append(f"--max-depth {cfg['max_depth']}")
    if cfg.get("mesh_dir"):
        opts.append(f"--mesh-dir {cfg['mesh_dir']}")
    other = {k: v for k, v in cfg.items() if k in default and k not in GENERATE_FLAGS and v != default[k]
             and not (preset and k in PRESET_FLAGS)}
    note = ""
    if other:
        opts.append("--config CONFIG.json")
        note = f"CONFIG.json: `{json.dumps(other)}`"
    return "relight generate " + " ".join(opts), note


def _module_lines(doc: str) -> list[str]:
    """The numbered module lines of an encoder's docstring, without the grid sizes."""
    import re
    out = []
    for line in (doc or "").splitlines():
        m = re.match(r"\s*(\d)\. (.*?)\s*(->.*)?$", line)
        if m:
            out.append(f"{m.group(1)}. {m.group(2)}")
    return out


def architecture_text(config) -> str:
    """Markdown naming the encoder's modules (one indented line each), read from the class
    that builds it (:class:`LightNet` for ``small``, :class:`PaperEncoder` for ``paper``)."""
    if config.arch == "paper":
        head = ("the paper's five modules at Inception-v3 proportions (`--arch paper`, `PaperEncoder`: "
                "split, factorised 1 x 7 / 7 x 1 and expanded inception modules with grid reductions)")
        doc = PaperEncoder.__doc__
    else:
        head = ("five modules scaled down for a CPU (`--arch small`; split inception: n x n factorised "
                "into 1 x n then n x 1)")
        doc = LightNet.__doc__
    lines = [ln.replace("``grid``", str(config.grid)) for ln in _module_lines(doc)]
    if lines and "linear" not in lines[-1]:
        lines[-1] += f"; then the {config.grid} x {config.grid} grid, flattened, linear"
    if lines:
        lines[-1] += f" -> embedding of {config.embed} units"
    return head + ":\n" + "\n".join(f"  {ln}" for ln in lines)


def surround_text(config) -> str:
    """The card's words on what the network sees around the objects (``NetConfig.surround``)."""
    if getattr(config, "surround", "keep") == "keep":
        return ""
    return ("; the objects alone: everything outside the image's object mask black first (trained "
            "with `--surround black` on the render masks; `relight predict --mask MASK` per image, "
            "which this model requires)")


# The one command that makes a shipped model's data, trains, calibrates it (resumable)
SCRIPTS = {"photo": "scripts/train_photo.sh", "object": "scripts/train_object.sh"}


def script_line(name: str) -> str:
    """The card's line naming the model's reproduction script, if it has one."""
    script = SCRIPTS.get(name)
    return (f"- The whole chain (data, training, calibration), resumable: `bash {script}`; "
            "its steps:\n") if script else ""


def camera_loss_text(s: dict) -> str:
    """The camera-tilt head's term of the loss, when the run trained one (``--camera-weight``)."""
    weight = s.get("camera_weight", 0.0)
    return f" + {weight:g} x the camera-tilt head's loss (`--camera-weight {weight:g}`)" if weight else ""


def output_text(config) -> str:
    """How the card says the 7 outputs are read: in the camera frame with the camera head's
    tilt (the photo model), or in the world frame with a given or assumed tilt."""
    frame = ("in the camera frame (`--target-frame camera`)" if config.target_frame == "camera"
             else "in the world frame")
    if config.camera_head:
        return (f"{frame}, decoded with the camera tilt its camera head predicts per image (`--camera-tilt` "
                "overrides it); every prediction carries `to_light_camera` and `camera_tilt_deg`")
    return f"{frame}, decoded with the camera tilt (photographs: 45 deg assumed, as in the paper)"


def train_images_text(meta: dict, tds: list) -> str:
    """The size of the train split(s), and the images an epoch draws from it when that differs."""
    per_epoch = meta["train_images_per_epoch"][-1]
    split = meta["settings"].get("train_split", "train")
    total = sum(d.get("records", 0) if split == "all" else (d.get("split_records") or {}).get(split, 0)
                for d in tds)
    if not total or total == per_epoch:
        return f"{per_epoch} images"
    return f"{total:,} images; {per_epoch:,} drawn per epoch"


def data_options(data_path) -> str:
    """``--data A`` for one training folder, ``--data A --data B`` for several."""
    return " ".join(f"--data {p}" for p in ([data_path] if isinstance(data_path, str) else data_path))


def data_label(data_path) -> str:
    """One folder, or several joined with ``+``, for the card's prose."""
    return data_path if isinstance(data_path, str) else " + ".join(data_path)


def train_command(s: dict, data_path, epochs: int | None = None, out: str = "RUN",
                  init: str | None = None) -> str:
    """The ``relight train`` command of a run's settings (``settings.json`` / model info):
    options that differ from the defaults, the architecture and the kappa options always.
    ``epochs``: the epochs the run has done, when it stopped before its planned total (the
    schedule never looks at the total, so ``--epochs N`` repeats those N epochs). ``init``:
    how to name the ``--init`` model of a fine-tuning run (default its recorded path)."""
    w = s["loss_weights"]
    opts = [data_options(data_path), f"--out {out}", f"--epochs {epochs or s['epochs']}",
            f"--patience {s['plateau_patience']}"]
    if s.get("init"):
        opts.append(f"--init {init or s['init']}")
    for key, flag, default in (("batch_size", "--batch-size", 16), ("lr", "--lr", 2e-4), ("res", "--res", 128),
                               ("seed", "--seed", 0), ("width", "--width", 32), ("workers", "--workers", 0)):
        if s.get(key, default) != default:
            opts.append(f"{flag} {s[key]:g}" if isinstance(s[key], float) else f"{flag} {s[key]}")
    for key, flag, default in (("target_frame", "--target-frame", "world"), ("camera_weight", "--camera-weight", 0.0),
                               ("source", "--source", "image"), ("augment", "--augment", "none"),
                               ("epoch_images", "--epoch-images", None), ("surround", "--surround", "keep")):
        if s.get(key, default) != default:   # the photo model's options (docs/photo.md)
            opts.append(f"{flag} {s[key]:g}" if isinstance(s[key], float) else f"{flag} {s[key]}")
    opts.append(f"--torch-threads {s.get('threads', 1)}")
    opts.append(f"--loss-weights {w['pan']:g},{w['tilt']:g},{w['colour']:g}")
    if not s.get("flip", True):
        opts.append("--no-flip")
    # --max-minutes only cuts a run into sittings (an unfinished run is said by ``epochs``);
    # with --init the loaded model is the network, so --arch would only mislead
    opts.append(("" if s.get("init") else f"--arch {s.get('arch', 'small')} ")
                + f"--kappa-weight {w.get('kappa', 0.0):g}")
    if not s.get("kappa_detach", True):
        opts.append("--kappa-into-features")
    return "relight train " + " ".join(opts)


def _stage(model: str, info: dict) -> dict:
    """A stage's record from its model file: a run's checkpoint (``epoch``, ``val_loss``)
    or a model shipped by this script (``best_epoch``, ``best_val_loss``)."""
    return {"model": model, "settings": info["settings"], "best_epoch": int(info.get("epoch", info.get("best_epoch"))),
            "best_val_loss": info.get("val_loss", info.get("best_val_loss")),
            "train_dataset": info.get("train_dataset")}


def training_chain(settings: dict, name: str = SHIPPED_NAME) -> tuple[list[dict], dict | None]:
    """``(stages, start)``: the stages before a fine-tuning run (``settings["init"]``, a
    model file that ``relight train`` wrote), oldest first (each one's settings, best epoch,
    val loss and training data where known), and where the oldest stage started: ``None``
    from scratch, else ``{"model": FILE, "name": shipped name or None, "why": ...}`` for a
    start that is not a stage of this chain. The chain follows each model's own ``--init``:
    a model shipped by this script keeps it in its header (``stages``, ``init_from``); one
    shipped before that kept its first stage in the meta file beside it (``base``). It stops,
    with the start, at a model shipped under another name (e.g. a ``photo`` run fine-tuned
    from the shipped ``sid2``: that model's own card gives its history), a file without a
    training record, or one that is gone with no record kept. ``([], None)`` for a run
    from scratch."""
    path = settings.get("init")
    if not path:
        return [], None
    try:
        _, info = read_model_header(path)
    except ModelFileError as exc:
        return [], {"model": path, "name": None, "why": f"not readable here: {str(exc).splitlines()[0]}"}
    shipped_as = info.get("name")
    if shipped_as and shipped_as != name:
        card = card_file(shipped_as) if shipped_as in SHIPPED_NAMES else "its card"
        return [], {"model": path, "name": shipped_as,
                    "why": f"the shipped `{shipped_as}` model; its training: {card}"}
    if "settings" not in info or ("epoch" not in info and "best_epoch" not in info):
        return [], {"model": path, "name": None, "why": "a model file without a training record"}
    stage = _stage(path, info)
    if info.get("stages") or info.get("init_from"):
        return list(info.get("stages") or []) + [stage], info.get("init_from")
    previous = info["settings"].get("init")
    if not previous:
        return [stage], None
    if os.path.isfile(previous):
        stages, start = training_chain(info["settings"], name)
        return stages + [stage], start
    meta_file = os.path.splitext(path)[0] + ".json"
    meta = json.load(open(meta_file)) if os.path.isfile(meta_file) else {}
    if meta.get("stages") or meta.get("init_from"):
        return list(meta.get("stages") or []) + [stage], meta.get("init_from")
    if meta.get("base"):
        return [meta["base"], stage], None
    return [stage], {"model": previous, "name": None, "why": "gone, and no record of its training is kept"}


def earlier_stages(settings: dict, name: str = SHIPPED_NAME) -> list[dict]:
    """The stages of :func:`training_chain` alone."""
    return training_chain(settings, name)[0]


def start_option(start: dict | None) -> str | None:
    """How the card's commands give ``--init`` for the chain's start: a shipped name
    (``relight train --init sid2``), else the file."""
    if not start:
        return None
    return start["name"] if start.get("name") in SHIPPED_NAMES else start["model"]


def _dataset_record(path: str) -> dict:
    card = read_card(path)
    records = read_manifest(path)
    return {"path": path, "seed": card["seed"], "config": card["config"], "spp": card.get("spp"),
            "records": len(records),
            "split_records": dict(collections.Counter(str(r.get("split")) for r in records))}


def ship(run: str, train_data, model_path: str | None = None, models_dir: str = MODELS_DIR,
         name: str = SHIPPED_NAME) -> dict:
    """Ship RUN's best model (or ``model_path``) as ``name`` (``sid2``, ``photo``) with its
    record; ``train_data``: the folder the run trained on, or a list of the folders it
    trained on together."""
    if name not in SHIPPED_NAMES:
        raise SystemExit(f"--name must be one of {', '.join(SHIPPED_NAMES)}, got {name!r}")
    folders = [train_data] if isinstance(train_data, str) else list(train_data)
    config, state, info = read_model_file(model_path or os.path.join(run, "best.safetensors"))
    rows = list(csv.DictReader(open(os.path.join(run, "log.csv"))))
    best = int(info["epoch"])
    model = LightNet(config)
    model.load_state_dict(state)
    datasets = [_dataset_record(path) for path in folders]
    stages, start = training_chain(info["settings"], name)
    meta = {"name": name, "arch": config.arch_name, "config": config.to_dict(),
            "parameters": count_parameters(model), "gflop_per_image": flops_per_image(model) / 1e9,
            "trained_epochs_total": len(rows), "best_epoch": best, "best_val_loss": info["val_loss"],
            "train_images_per_epoch": [int(rows[0]["n_train"]), int(rows[-1]["n_train"])],
            "train_time_s_all_epochs": sum(float(r["epoch_time_s"]) for r in rows),
            "train_time_s_to_best": sum(float(r["epoch_time_s"]) for r in rows[:best]),
            "train_dataset": datasets[0], "train_datasets": datasets if len(datasets) > 1 else None,
            "settings": info["settings"], "run": run, "kappa_temperature": info.get("kappa_temperature"),
            "kappa_calibration": info.get("kappa_calibration"), "models_dir": models_dir,
            "stages": stages, "init_from": start, "ood": info.get("ood")}
    save_model(os.path.join(models_dir, f"{name}.safetensors"), model,
               {k: meta[k] for k in ("name", "best_epoch", "best_val_loss", "settings", "train_dataset",
                                     "train_datasets", "kappa_temperature", "kappa_calibration", "stages",
                                     "init_from", "ood")
                if meta[k] not in (None, [])},
               dtype=SHIPPED_DTYPE)
    _copy(os.path.join(run, "log.csv"), os.path.join(models_dir, f"{name}_log.csv"))
    write_json(os.path.join(models_dir, f"{name}.json"), meta)
    return meta


def prior_rows(prior_evals: dict) -> str:
    """Markdown table of the colour (and direction) error on the test set of each prior:
    ``{name: (test_dir, eval_dir)}``."""
    lines = ["| Test set (colour prior) | Images | Colour mean | Colour median | Direction mean |",
             "|---|---:|---:|---:|---:|"]
    for name, (test_dir, eval_dir) in prior_evals.items():
        ev = json.load(open(os.path.join(eval_dir, "metrics.json")))
        o = ev["tables"]["overall"]
        recorded = dataset_settings(read_card(test_dir))["colour_prior"]
        label = name if recorded == name else f"{name} (card: {recorded})"
        lines.append(f"| {label} (`{test_dir}`) | {ev['n']} | {o['colour']['mean']:.2f} | "
                     f"{o['colour']['median']:.2f} | {o['direction']['mean']:.2f} |")
    return "\n".join(lines)


def other_test_rows(other_evals: dict, test_card: dict) -> str:
    """Markdown table of the four mean errors (and the 90% cones' coverage) on other test
    sets: ``{name: (test_dir, eval_dir)}``; each row names the generator settings in which
    its set differs from the main test set (``test_card``)."""
    main = settings_text(test_card).split(", ")
    lines = ["| Test set | Differs from the main test set in | Images | Pan (tilt < 90) | Zenith left out | Tilt | "
             "Direction | Colour | Colour median | 90% cones cover | Pan, all lights |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, (test_dir, eval_dir) in other_evals.items():
        ev = json.load(open(os.path.join(eval_dir, "metrics.json")))
        o = ev["tables"]["overall"]
        differs = [part for part in settings_text(read_card(test_dir)).split(", ") if part not in main]
        cover = ev.get("uncertainty", {}).get("cone90_coverage")
        lines.append(f"| {name} (`{test_dir}`) | {', '.join(differs) or 'the seed only'} | {ev['n']} | "
                     + f"{_mean(o['pan'])} | {zenith_count(o)} | "
                     + " | ".join(f"{o[m]['mean']:.2f}" for m in METRICS[1:]) + f" | {o['colour']['median']:.2f} | "
                     + ("-" if cover is None else f"{100 * cover:.1f}%") + f" | {_mean(pan_all(o))} |")
    lines.append("")
    for name, (test_dir, _) in other_evals.items():   # how to make each set
        cmd, note = generate_command(read_card(test_dir), test_dir, len(read_manifest(test_dir)))
        lines.append(f"- {name}: `{cmd}`" + (f" ({note})" if note else ""))
    return "\n".join(lines)


def _mean(stats: dict) -> str:
    """A stats dict's mean with 2 decimals ("n/a" for an empty group)."""
    return "n/a" if not stats.get("n") else f"{stats['mean']:.2f}"


def zenith_count(group: dict) -> str:
    """The zenith lights a table group's pan leaves out ("-" for an evaluation made before
    pan was scored below the zenith only)."""
    return str(group["pan"].get("zenith_left_out", "-"))


def pan_all(group: dict) -> dict:
    """The all-lights pan stats of a table group (``pan_all``; an evaluation made before
    that column existed held them under ``pan``)."""
    return group.get("pan_all", group["pan"])


def level_rows(tables: dict, group: str, paper: dict) -> str:
    """Rows of the card's Table 2-3 comparison: the paper's means, ours (pan below the
    zenith), the zenith lights left out, and the group's images."""
    out = []
    for name, ref in paper.items():
        g = tables[group][name]
        ours = " | ".join(_mean(g[m]) for m in METRICS)
        out.append(f"| {name} | {' | '.join(f'{v:.2f}' for v in ref)} | {ours} | {zenith_count(g)} | "
                   f"{g['tilt']['n']} |")
    return "\n".join(out)


def table1_rows(overall: dict) -> list[str]:
    """The card's Table 1 rows (paper, ours mean and median): pan scored over the lights
    below the zenith with the count left out in its label, then tilt, direction, colour,
    and the all-lights pan as its own row (the paper gives no such figure)."""
    z = zenith_count(overall)
    label = {"pan": f"Pan (tilt < 90; {z} zenith lights left out)" if z != "-" else "Pan (all lights)",
             "tilt": "Tilt", "direction": "Direction",
             "colour": "Colour"}
    rows = [f"| {label[m]} | {PAPER[m]:.2f} | {_mean(overall[m])} | "
            f"{'n/a' if not overall[m].get('n') else format(overall[m]['median'], '.2f')} |" for m in METRICS]
    a = pan_all(overall)
    return rows + [f"| Pan, all lights | - | {_mean(a)} | {a['median']:.2f} |"]


def _fine_tune_why(before: dict, after: dict, default_data: str) -> str:
    """How a stage follows the one before it (training settings of both)."""
    head = f"fine-tunes the previous stage's best model (`--init`) at lr {after['lr']:g}"
    if after.get("data_dir", default_data) != before.get("data_dir", default_data):
        return f"{head} on other data (`{data_label(after.get('data_dir', default_data))}`)"
    return (f"{head}, a learning-rate drop made by hand where the plateau schedule would wait for "
            f"{before['plateau_patience'] + 1} epochs without a better val loss")


def mirror_line(mirror_eval_dir: str | None, test_data: str, name: str = SHIPPED_NAME) -> str:
    """The card's line for the test set evaluated with ``--mirror-average`` ("" without)."""
    if not mirror_eval_dir:
        return ""
    ev = json.load(open(os.path.join(mirror_eval_dir, "metrics.json")))
    o = ev["tables"]["overall"]
    cones = ev.get("uncertainty", {}).get("cone90_coverage")
    return (f"With `--mirror-average` (each image and its mirror image, the two predictions averaged; about "
            f"1.8x the time), mean errors: pan (tilt < 90) {_mean(o['pan'])}, tilt {o['tilt']['mean']:.2f}, direction "
            f"{o['direction']['mean']:.2f}, colour {o['colour']['mean']:.2f}"
            + (f"; the 90% cones cover {100 * cones:.1f}%" if cones is not None else "")
            + f" (`relight evaluate --model {name} --data {test_data} --split all --mirror-average --out REPORT`).\n\n")


def ood_section(meta: dict) -> str:
    """The card's section on the out-of-distribution flag (empty for a model without one)."""
    ood = meta.get("ood")
    if not ood:
        return ""
    flagged = ", ".join(f"{k} {100 * v:.1f}%" for k, v in (ood.get("flagged") or {}).items())
    return (f"\n## Out-of-distribution flag\nA feature-space Mahalanobis detector ({ood['ood_dims']} principal "
            f"components, threshold at the {100 * ood['quantile']:g}% quantile of {ood['n']} held-out renders; "
            f"`relight/net/ood.py`): a flagged image is `ood: true` and its 90% cone is 180 degrees."
            + (f" Flagged: {flagged}." if flagged else "") + (f"\n`{ood['command']}`" if ood.get("command") else "")
            + "\n")


def write_card(meta: dict, eval_dir: str, test_data: str, notes: str, prior_evals: dict | None = None,
               mirror_eval_dir: str | None = None, other_evals: dict | None = None) -> str:
    """Write the model's card (:func:`card_file` of ``meta["name"]``) into the models folder
    and return its text; ``prior_evals``:
    ``{prior name: (test set, evaluation folder)}``; ``mirror_eval_dir``: the test set's
    evaluation with ``--mirror-average``."""
    from relight.net.model import NetConfig
    models_dir = meta.get("models_dir", MODELS_DIR)
    name = meta.get("name", SHIPPED_NAME)
    start = meta.get("init_from")
    ev = json.load(open(os.path.join(eval_dir, "metrics.json")))
    report = open(os.path.join(eval_dir, "report.md")).read().split("\n", 4)[-1].strip()
    if os.path.isfile(os.path.join(eval_dir, "reliability.png")):   # the cones' reliability diagram
        _copy(os.path.join(eval_dir, "reliability.png"), os.path.join(models_dir, f"{name}_reliability.png"))
        report = report.replace("](reliability.png)", f"]({name}_reliability.png)")
    config = NetConfig.from_dict(meta["config"])
    res = config.res
    overall = ev["tables"]["overall"]
    rows = list(csv.DictReader(open(os.path.join(models_dir, f"{name}_log.csv"))))
    s = dict(meta["settings"])
    if rows:   # the rate the run started at: a resumed run's settings hold its last command's --lr
        s["lr"] = float(rows[0]["lr"])
    w = s["loss_weights"]
    unfinished = len(rows) < int(s["epochs"])
    stages = meta.get("stages") or ([meta["base"]] if meta.get("base") else [])   # "base": cards before chains
    td = meta["train_dataset"]
    tds = meta.get("train_datasets") or [td]   # the final stage's folders (one, or several trained together)
    td_paths = td["path"] if len(tds) == 1 else [d["path"] for d in tds]
    final_data = s.get("data_dir", td_paths)
    train_cmd_line = train_command(s, td_paths, len(rows) if unfinished else None,
                                   init=f"STAGE{len(stages)}/best.safetensors" if stages else start_option(start))
    stage_text, stage_lines = "", ""
    if start:   # where the oldest stage began: not a stage of this chain
        stage_text = (f"- Initialised from `{start['model']}` ({start['why']}), given as "
                      f"`--init {start_option(start)}` below.\n")
    chain = [st["settings"] for st in stages] + [s]
    for k, st in enumerate(stages, 1):
        b = st["settings"]
        cmd = train_command(b, b.get("data_dir", final_data), st["best_epoch"], out=f"STAGE{k}",
                            init=f"STAGE{k - 1}/best.safetensors" if k > 1 else start_option(start))
        loss = "" if st.get("best_val_loss") is None else f"val loss {st['best_val_loss']:.4f}, "
        head = (f"{STAGE_WORDS.get(len(chain), len(chain))} stages. Stage 1:" if k == 1 else
                f"Stage {k} {_fine_tune_why(chain[k - 2], b, final_data)}:")
        stage_text += f"- {head} `{cmd}` (lr {b['lr']:g}; its best {loss}epoch {st['best_epoch']}, passed on).\n"
        stage_lines += cmd + "\n"
    if stages:
        stage_text += f"- Stage {len(chain)} {_fine_tune_why(chain[-2], s, final_data)}:\n"
    stopped = ""
    if unfinished:
        stopped = (f"\n- The run is not finished: this is its state after epoch {len(rows)} of the planned "
                   f"{s['epochs']}. The command above (`--epochs {len(rows)}`) repeats those epochs; with "
                   f"`--epochs {s['epochs']}` the same command continues the run.")
    drops = [f"{float(r['lr']):.0e} after epoch {r['epoch']}" for i, r in enumerate(rows)
             if i and float(r["lr"]) != float(rows[i - 1]["lr"])]
    datasets = {}   # every stage's training data, in order of first use: path -> card (as in the model)
    for st in stages:
        d = st.get("train_dataset")
        path = st["settings"].get("data_dir") or (d or td)["path"]
        if datasets.get(path) is None:
            datasets[path] = d
    for d in tds:
        datasets.pop(d["path"], None)   # the final stage's folders come last
        datasets[d["path"]] = d
    data_lines = []
    for path, d in datasets.items():
        if d is None:   # a stage shipped before models kept their data card
            data_lines.append((f"{path} (its generate settings are not recorded)", ""))
            continue
        data_lines.append(generate_command({"seed": d["seed"], "config": d["config"], "spp": d.get("spp")}, path,
                                           d["records"]))
    n_final = len(tds)
    earlier_data = "".join(f"- Earlier stages: `{cmd}`{(' (' + note + ')') if note else ''}\n"
                           for cmd, note in data_lines[:-n_final])
    final_lines = data_lines[-n_final:]
    test_card = read_card(test_data)
    test_cmd, test_note = generate_command(test_card, test_data, len(read_manifest(test_data)))
    table1 = "\n".join(table1_rows(overall))
    pan_line = format_pan_where_defined(ev["pan_where_defined"]) if "pan_where_defined" in ev else ""
    if pan_line:   # said once, beside Table 1, not again inside the embedded report
        report = report.replace("\n" + pan_line, "", 1)
        pan_line += "\n"
    kappa_text = ""
    if meta["config"].get("kappa_head"):
        kappa_text = (", and a fourth giving the von Mises-Fisher concentration kappa of the direction "
                      f"(trained by its NLL, temperature {meta.get('kappa_temperature') or 1.0:.3f} fitted on val)")
        cal = meta.get("kappa_calibration")
        if cal:
            b, a = cal["check_before"], cal["check_after"]
            rho = (lambda v: "-" if v is None else f"{v:.2f}")
            kappa_text += (f"; then `relight calibrate --mode {cal['settings']['mode']}` on the {cal['split']} split "
                           f"of `{data_label(cal['data_dir'])}` ({cal['n_images']} images, network frozen; kept: {cal['kept']}): "
                           f"on its check part the 90% cone covered {100 * b['cone90_coverage']:.1f}% -> "
                           f"{100 * a['cone90_coverage']:.1f}%, Spearman(cone, error) {rho(b['spearman_cone90_error'])} "
                           f"-> {rho(a['spearman_cone90_error'])}")
    calibrate_line, ship_extra = "", ""
    cal = meta.get("kappa_calibration")
    if cal:
        calibrate_line = (f"relight calibrate --model RUN {data_options(cal['data_dir'])} --split {cal['split']} "
                          f"--mode {cal['settings']['mode']}{' --ood' if meta.get('ood') else ''} "
                          "--out CAL.safetensors\n")
        ship_extra = " --model CAL.safetensors"
    ship_extra += "".join(f" --prior-test {name}={folder}" for name, (folder, _) in (prior_evals or {}).items())
    ship_extra += "".join(f" --other-test {name}={folder}" for name, (folder, _) in (other_evals or {}).items())
    priors = ""
    if prior_evals:
        priors = ("\n## Colour error per surface-colour prior\n"
                  "The shipped model on a test set of each prior (`relight generate --colour-prior NAME`, all "
                  "images; degrees):\n\n" + prior_rows(prior_evals) + "\n")
    if other_evals:
        priors += ("\n## Other test sets\n"
                   "The shipped model on test sets made with other generator settings (all images; mean "
                   "degrees unless stated):\n\n" + other_test_rows(other_evals, test_card) + "\n")
    final_data_text = "".join(
        f"- `{cmd}`{(' (' + note + ')') if note else ''}\n  ({settings_text(d)}, depth {dataset_settings(d)['max_depth']})\n"
        for (cmd, note), d in zip(final_lines, tds))
    splits = ("The dataset's `train` split" if n_final == 1 else
              f"The `train` splits of these {n_final} datasets, joined")
    trained_on = ("synthetic datasets made by `relight generate` for real photographs (docs/photo.md)"
                  if name in ("photo", "object") else "a synthetic SID2-style dataset made by `relight generate`")
    ranges = ("" if name in ("photo", "object") else
              "SID2 ranges: light r 20-50 m, tilt 30-90 step 5, pan step 1, CCT 2500-10000 K |Duv| <= 0.01;\n"
              "  camera r 20 m, tilt 10-70; 1-3 objects.\n  ")
    history = ("[docs/photo.md](../../docs/photo.md)" if name in ("photo", "object")
               else "[docs/training.md](../../docs/training.md)")
    card = f"""# Model card: `{name}.safetensors`

The paper's regression network (Sial et al., "Light Direction and Color Estimation from
Single Image with Deep Regression"), trained by `relight train` on {trained_on}.
{default_sentence(name)} This card is written by `scripts/ship_model.py`.

## Model
- Architecture `{meta['arch']}` (`relight/net/model.py`), an encoder of {architecture_text(config)}
- Heads on the embedding: pan (sin/cos), tilt (sin/cos), colour (RGB, softplus){kappa_text}.
  He-normal initialisation.
- {meta['parameters']:,} parameters; {meta['gflop_per_image']:.3f} GFLOP per {res} px image (forward).
- Input: {res} x {res} 8-bit sRGB scaled to [0, 1] (PNG/JPEG as is; EXR / linear arrays encoded
  with `relight.imageio.to_srgb8` first, like the dataset PNGs; other sizes centre-cropped to a
  square and bilinearly resized){surround_text(config)}. Output: the 7-vector of `shared/conventions.md`, {output_text(config)}.
- File: safetensors (no pickle), float16 weights (loaded as float32), {os.path.getsize(os.path.join(models_dir, f"{name}.safetensors")) / 1e6:.1f} MB; metadata in its
  header and in `{name}.json`; training log `{name}_log.csv`.

## Training data
{earlier_data}{final_data_text}- {ranges}{splits} ({train_images_text(meta, tds)}) train{'s' if n_final == 1 else ''}, {'its `val` split drives' if n_final == 1 else 'their `val` splits drive'}
  the scheduler and the choice of the best epoch. The paper used 45,000 images.

## Training
{script_line(name)}{stage_text}- `{train_cmd_line}`
- Adam lr {s['lr']:g}, ReduceLROnPlateau factor 0.1 (patience {s['plateau_patience']}) on the val loss,
  batch {s['batch_size']}, horizontal flips (pan_rel -> 360 - pan_rel), loss
  {w['pan']:g} x MSE(pan pair) + {w['tilt']:g} x MSE(tilt pair) + {w['colour']:g} x mean RGB angular error (radians){camera_loss_text(s)}.
- {f'Stage {len(stages) + 1}: ' if stages else ''}{meta['trained_epochs_total']} epochs in {meta['train_time_s_all_epochs'] / 60:.0f} min on the 2-core CPU; best val
  loss at epoch {meta['best_epoch']} ({meta['train_time_s_to_best'] / 60:.0f} min). Learning-rate drops: {', '.join(drops) or 'none'}.{stopped}
- The training history, stage by stage and epoch by epoch: {history}.

## Test results (fresh test set, never used for training)
`{test_cmd}`{(' (' + test_note + ')') if test_note else ''}
({settings_text(test_card)}; another seed),
all {ev['n']} images, errors in degrees:

| Error | Paper SID2 (Table 1, mean) | This model, mean | This model, median |
|---|---:|---:|---:|
{table1}

{pan_line}{mirror_line(mirror_eval_dir, test_data, name)}Paper Table 2 (tilt levels) and Table 3 (pan levels, tilt 30-70) next to ours (means;
paper columns first):

| Level | Paper pan | Paper tilt | Paper dir. | Paper colour | Pan (tilt < 90) | Tilt | Dir. | Colour | Zenith left out | n |
|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|
{level_rows(ev['tables'], 'tilt_levels', PAPER_TILT)}
{level_rows(ev['tables'], 'pan_levels', PAPER_PAN)}

Full report of `relight evaluate`:

{report}
{priors}
## Where it falls short, and why
{notes}
{ood_section(meta)}
## Reproduce
```
{"".join(cmd + chr(10) for cmd, _ in data_lines)}{test_cmd}
{stage_lines}{train_cmd_line}
{calibrate_line}.venv/bin/python scripts/ship_model.py{'' if name == SHIPPED_NAME else f' --name {name}'} --run RUN{''.join(f" --train-data {d['path']}" for d in tds)} --test-data {test_data}{ship_extra} --notes NOTES.md
```
(`bash scripts/make_sid2.sh` makes the SID2-scale sets of one-colour objects and `bash
scripts/train_sid2.sh ARCH` trains on them; `bash scripts/make_sid2_parts.sh` makes those of
multi-coloured objects and `bash scripts/train_sid2p.sh` fine-tunes on them; all resumably.)
`relight evaluate --model {name} --data {test_data} --split all --out REPORT`
reproduces the tables above exactly (inference is deterministic). Training on a CPU is
repeatable in its settings, not bit for bit (thread scheduling).
"""
    write_text(os.path.join(models_dir, card_file(name)), card)
    return card


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--name", choices=SHIPPED_NAMES, default=SHIPPED_NAME,
                    help="the shipped name: sid2 (SID2-style synthetic rooms; the default), photo (real "
                         "photographs, the default model of relight predict and evaluate) or object "
                         "(photographs of objects read through a mask)")
    ap.add_argument("--run", required=True, help="training run folder (relight train --out)")
    ap.add_argument("--train-data", required=True, action="append",
                    help="the run's training dataset folder (repeat it, in the run's order, for a run "
                         "trained on several)")
    ap.add_argument("--test-data", required=True, help="a fresh dataset never used for training")
    ap.add_argument("--eval-out", default=None, help="evaluation folder (default TEST-eval)")
    ap.add_argument("--notes", default=None, help="markdown file: where the model falls short, and why")
    ap.add_argument("--model", default=None,
                    help="model file to ship instead of RUN/best.safetensors (e.g. relight calibrate's output)")
    ap.add_argument("--prior-test", action="append", default=[], metavar="NAME=DIR",
                    help="a test set of one surface-colour prior (repeat for each); the card reports the "
                         "colour error on each")
    ap.add_argument("--other-test", action="append", default=[], metavar="NAME=DIR",
                    help="a test set made with other generator settings (e.g. mosaic backgrounds, one-colour "
                         "objects; repeat for each); the card reports the four errors on each")
    ap.add_argument("--models-dir", default=MODELS_DIR,
                    help="where the model and its card go (default the package's models folder)")
    args = ap.parse_args()
    def named_folders(items, flag):
        out = {}
        for item in items:
            name, sep, folder = item.partition("=")
            if not sep or not name or not folder:
                ap.error(f"{flag} takes NAME=DIR, got {item!r}")
            out[name] = folder
        return out
    prior_tests = named_folders(args.prior_test, "--prior-test")
    other_tests = named_folders(args.other_test, "--other-test")
    meta = ship(args.run, args.train_data, args.model, args.models_dir, args.name)
    eval_out = args.eval_out or args.test_data.rstrip("/") + "-eval"
    from relight.net.evaluate import evaluate
    from relight.net.predict import load_model
    shipped = load_model(os.path.join(args.models_dir, f"{args.name}.safetensors"))
    evaluate(shipped, args.test_data, eval_out, split="all", model_name="shipped model")
    from relight.net.model import MirrorAveraged
    mirror_out = f"{eval_out.rstrip('/')}-mirror"
    evaluate(MirrorAveraged(shipped), args.test_data, mirror_out, split="all",
             model_name="shipped model (mirror-averaged)")
    prior_evals = {}
    for name, folder in prior_tests.items():
        prior_evals[name] = (folder, f"{eval_out.rstrip('/')}-prior-{name}")
        evaluate(shipped, folder, prior_evals[name][1], split="all", model_name=f"shipped model, prior {name}")
    other_evals = {}
    for name, folder in other_tests.items():
        other_evals[name] = (folder, f"{eval_out.rstrip('/')}-other-{name}")
        evaluate(shipped, folder, other_evals[name][1], split="all", model_name=f"shipped model, {name}")
    notes = open(args.notes).read().strip() if args.notes else "(no notes given)"
    print(write_card(meta, eval_out, args.test_data, notes, prior_evals, mirror_out, other_evals))
    return 0


if __name__ == "__main__":
    sys.exit(main())

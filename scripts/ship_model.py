"""Ship a training run as the package's default model, evaluate it and write its card.

    .venv/bin/python scripts/ship_model.py --run RUN --train-data TRAIN --test-data TEST

1. copies RUN/best.safetensors (weights unchanged) to relight/models/sid2_small.safetensors
   with its metadata, plus sid2_small.json and the training log sid2_small_log.csv;
2. runs ``relight evaluate`` with the shipped model on every image of TEST (a set never
   used for training) into TEST-eval/ (or --eval-out);
3. writes relight/models/MODEL_CARD.md: data, training, and the paper's Tables 1-3 next
   to ours. ``relight evaluate`` reproduces the card's numbers exactly.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import sys

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

from relight.dataset import read_card, read_manifest  # noqa: E402
from relight.net.io import MODELS_DIR, SHIPPED_MODEL, read_model_file, save_model  # noqa: E402
from relight.net.model import LightNet, count_parameters, flops_per_image  # noqa: E402

PAPER = {"pan": 10.46, "tilt": 9.21, "direction": 14.22, "colour": 1.02}   # Table 1, SID2
PAPER_TILT = {"L1": (4.92, 5.14, 7.57, 1.04), "L2": (8.51, 5.14, 11.97, 0.90), "L3": (22.36, 18.33, 28.33, 1.00)}
PAPER_PAN = {"front": (6.87, 5.10, 9.10, 0.98), "right": (6.24, 5.12, 8.80, 0.96),
             "back": (6.35, 5.09, 9.46, 1.03), "left": (6.01, 5.16, 9.03, 0.97)}
METRICS = ("pan", "tilt", "direction", "colour")


def ship(run: str, train_data: str) -> dict:
    config, state, info = read_model_file(os.path.join(run, "best.safetensors"))
    rows = list(csv.DictReader(open(os.path.join(run, "log.csv"))))
    best = int(info["epoch"])
    model = LightNet(config)
    model.load_state_dict(state)
    card = read_card(train_data)
    meta = {"name": "sid2_small", "arch": config.arch_name, "config": config.to_dict(),
            "parameters": count_parameters(model), "gflop_per_image": flops_per_image(model) / 1e9,
            "trained_epochs_total": len(rows), "best_epoch": best, "best_val_loss": info["val_loss"],
            "train_images_per_epoch": [int(rows[0]["n_train"]), int(rows[-1]["n_train"])],
            "train_time_s_all_epochs": sum(float(r["epoch_time_s"]) for r in rows),
            "train_time_s_to_best": sum(float(r["epoch_time_s"]) for r in rows[:best]),
            "train_dataset": {"path": train_data, "seed": card["seed"], "config": card["config"],
                              "records": len(read_manifest(train_data))},
            "settings": info["settings"], "run": run, "kappa_temperature": info.get("kappa_temperature")}
    os.makedirs(MODELS_DIR, exist_ok=True)
    save_model(SHIPPED_MODEL, model, {k: meta[k] for k in ("name", "best_epoch", "best_val_loss",
                                                             "settings", "train_dataset")})
    shutil.copy(os.path.join(run, "log.csv"), os.path.join(MODELS_DIR, "sid2_small_log.csv"))
    with open(os.path.join(MODELS_DIR, "sid2_small.json"), "w") as f:
        json.dump(meta, f, indent=1)
    return meta


def level_rows(tables: dict, group: str, paper: dict) -> str:
    out = []
    for name, ref in paper.items():
        g = tables[group][name]
        ours = " | ".join(f"{g[m]['mean']:.2f}" for m in METRICS)
        out.append(f"| {name} | {' | '.join(f'{v:.2f}' for v in ref)} | {ours} | {g['pan']['n']} |")
    return "\n".join(out)


def write_card(meta: dict, eval_dir: str, test_data: str, notes: str) -> str:
    ev = json.load(open(os.path.join(eval_dir, "metrics.json")))
    report = open(os.path.join(eval_dir, "report.md")).read().split("\n", 4)[-1].strip()
    if os.path.isfile(os.path.join(eval_dir, "reliability.png")):   # the cones' reliability diagram
        shutil.copy(os.path.join(eval_dir, "reliability.png"), os.path.join(MODELS_DIR, "sid2_small_reliability.png"))
        report = report.replace("](reliability.png)", "](sid2_small_reliability.png)")
    overall = ev["tables"]["overall"]
    s = meta["settings"]
    w = s["loss_weights"]
    train_flags = (f"--arch {s.get('arch', 'small')} --kappa-weight {w.get('kappa', 0.0):g}"
                   + (" --kappa-into-features" if not s.get("kappa_detach", True) else ""))
    rows = list(csv.DictReader(open(os.path.join(MODELS_DIR, "sid2_small_log.csv"))))
    drops = [f"{float(r['lr']):.0e} after epoch {r['epoch']}" for i, r in enumerate(rows)
             if i and float(r["lr"]) != float(rows[i - 1]["lr"])]
    td = meta["train_dataset"]
    test_card = read_card(test_data)
    table1 = "\n".join(f"| {m.capitalize()} | {PAPER[m]:.2f} | {overall[m]['mean']:.2f} | "
                       f"{overall[m]['median']:.2f} |" for m in METRICS)
    kappa_text = ""
    if meta["config"].get("kappa_head"):
        kappa_text = (", and a fourth giving the von Mises-Fisher concentration kappa of the direction "
                      f"(trained by its NLL, temperature {meta.get('kappa_temperature', 1.0):.3f} fitted on val)")
    card = f"""# Model card: `sid2_small.safetensors`

The paper's regression network (Sial et al., "Light Direction and Color Estimation from
Single Image with Deep Regression"), trained by `relight train` on a synthetic SID2-style
dataset made by `relight generate`. It is the default model of `relight predict` and
`relight evaluate`. This card is written by `scripts/ship_model.py`.

## Model
- Architecture `{meta['arch']}` (`relight/net/model.py`): stem conv + split-inception modules
  (n x n factorised into 1 x n then n x 1) with pooling, a grid embedding, and three heads:
  pan (sin/cos), tilt (sin/cos), colour (RGB, softplus){kappa_text}. He-normal initialisation.
- {meta['parameters']:,} parameters; {meta['gflop_per_image']:.3f} GFLOP per 128 px image (forward).
- Input: 128 x 128 8-bit sRGB scaled to [0, 1] (PNG/JPEG as is; EXR / linear arrays encoded
  with `relight.imageio.to_srgb8` first, like the dataset PNGs; other sizes centre-cropped to a
  square and bilinearly resized). Output: the 7-vector of `shared/conventions.md`, decoded
  with the camera tilt (photographs: 45 deg assumed, as in the paper).
- File: safetensors (no pickle), {os.path.getsize(SHIPPED_MODEL) / 1e6:.1f} MB; metadata in its
  header and in `sid2_small.json`; training log `sid2_small_log.csv`.

## Training data
- `relight generate --count {td['records']} --out {td['path']} --seed {td['seed']} --spp {td['config']['spp']}`
  ({td['config']['res']} px, depth {td['config']['max_depth']}; SID2 ranges: light r 20-50 m, tilt 30-90 step 5,
  pan step 1, CCT 2500-10000 K |Duv| <= 0.01; camera r 20 m, tilt 10-70; 1-3 objects).
  The dataset's `train` split ({meta['train_images_per_epoch'][-1]} images) trains, its `val` split drives
  the scheduler and the choice of the best epoch. The paper used 45,000 images.

## Training
- `relight train --data {td['path']} --out RUN --epochs {s['epochs']} --patience {s['plateau_patience']} \\
  --torch-threads {s['threads']} --loss-weights {w['pan']:g},{w['tilt']:g},{w['colour']:g} --max-minutes {s['max_minutes']:g} \\
  {train_flags}`
- Adam lr {s['lr']:g}, ReduceLROnPlateau factor 0.1 (patience {s['plateau_patience']}) on the val loss,
  batch {s['batch_size']}, horizontal flips (pan_rel -> 360 - pan_rel), loss
  {w['pan']:g} x MSE(pan pair) + {w['tilt']:g} x MSE(tilt pair) + {w['colour']:g} x mean RGB angular error (radians).
- {meta['trained_epochs_total']} epochs in {meta['train_time_s_all_epochs'] / 60:.0f} min on the 2-core CPU; best val
  loss at epoch {meta['best_epoch']} ({meta['train_time_s_to_best'] / 60:.0f} min). Learning-rate drops: {', '.join(drops) or 'none'}.

## Test results (fresh test set, never used for training)
`relight generate --count {len(read_manifest(test_data))} --out {test_data} --seed {test_card['seed']} --spp {test_card['config']['spp']}`
(same generator settings, another seed), all {ev['n']} images, errors in degrees:

| Error | Paper SID2 (Table 1, mean) | This model, mean | This model, median |
|---|---:|---:|---:|
{table1}

Paper Table 2 (tilt levels) and Table 3 (pan levels, tilt 30-70) next to ours (means;
paper columns first):

| Level | Paper pan | Paper tilt | Paper dir. | Paper colour | Pan | Tilt | Dir. | Colour | n |
|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|
{level_rows(ev['tables'], 'tilt_levels', PAPER_TILT)}
{level_rows(ev['tables'], 'pan_levels', PAPER_PAN)}

Full report of `relight evaluate`:

{report}

## Where it falls short, and why
{notes}

## Reproduce
```
relight generate --count {td['records']} --out {td['path']} --seed {td['seed']} --spp {td['config']['spp']}
relight generate --count {len(read_manifest(test_data))} --out {test_data} --seed {test_card['seed']} --spp {test_card['config']['spp']}
relight train --data {td['path']} --out RUN --epochs {s['epochs']} --patience {s['plateau_patience']} --torch-threads {s['threads']} --loss-weights {w['pan']:g},{w['tilt']:g},{w['colour']:g} --max-minutes {s['max_minutes']:g} {train_flags}
.venv/bin/python scripts/ship_model.py --run RUN --train-data {td['path']} --test-data {test_data} --notes NOTES.md
```
`relight evaluate --data {test_data} --split all --out REPORT` with the shipped model
reproduces the tables above exactly (inference is deterministic). Training on a CPU is
repeatable in its settings, not bit for bit (thread scheduling).
"""
    with open(os.path.join(MODELS_DIR, "MODEL_CARD.md"), "w") as f:
        f.write(card)
    return card


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", required=True, help="training run folder (relight train --out)")
    ap.add_argument("--train-data", required=True)
    ap.add_argument("--test-data", required=True, help="a fresh dataset never used for training")
    ap.add_argument("--eval-out", default=None, help="evaluation folder (default TEST-eval)")
    ap.add_argument("--notes", default=None, help="markdown file: where the model falls short, and why")
    args = ap.parse_args()
    meta = ship(args.run, args.train_data)
    eval_out = args.eval_out or args.test_data.rstrip("/") + "-eval"
    from relight.net.evaluate import evaluate
    from relight.net.predict import load_model
    evaluate(load_model(None), args.test_data, eval_out, split="all", model_name="shipped model")
    notes = open(args.notes).read().strip() if args.notes else "(no notes given)"
    print(write_card(meta, eval_out, args.test_data, notes))
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env bash
# The shipped object model (relight/models/object.safetensors; MODEL_CARD_object.md, docs/photo.md,
# tenth round): photographs of objects read through an object mask, the objects alone. One dataset
# (one colour per object, with object masks), a fine-tune of the shipped photo weights on the
# objects alone, calibration. Resumable: re-run the same command after a kill or a new session
# (each step skips what is done). Default root /root/relight-data (outside the repo).
# About 35 minutes of generation and 16 of training on a quiet 2-core machine (train alone; the
# shipped run is training seed 0, the default; seed 1, `--seed 1`, was its check: docs/photo.md).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=${1:-/root/relight-data}
RELIGHT=${RELIGHT:-.venv/bin/relight}
# 1. the photo mix (dim voids) with one colour per object and object masks: 20,000 images of seed
#    205, split 90/10; and a test set of 1,000 (seed 206)
"$RELIGHT" generate --preset photo --count 20000 --seed 205 \
    --config scenes/configs/photo_uniform_masks.json --out "$ROOT/photo-train-uniform-masks-20k" --quiet
"$RELIGHT" generate --preset photo --count 1000 --seed 206 \
    --config scenes/configs/photo_test_uniform_masks.json --out "$ROOT/photo-test-uniform-masks" --quiet
# 2. the shipped photo model fine-tuned on the objects alone (everything outside the masks black):
#    10 epochs of 8,000 images from the shipped photo weights (photo-bd, unchanged since the
#    seventh round)
"$RELIGHT" train --data "$ROOT/photo-train-uniform-masks-20k" --out "$ROOT/runs/object" \
    --init photo --target-frame camera --camera-weight 1 --source exr \
    --augment photo --surround black --lr 1e-4 --patience 2 --epochs 10 --epoch-images 8000 \
    --torch-threads 2 --quiet
# 3. the cones and the out-of-distribution flag, fitted on the val split (read through its masks)
[ -f "$ROOT/runs/object/calibrated.safetensors" ] || "$RELIGHT" calibrate \
    --model "$ROOT/runs/object" --data "$ROOT/photo-train-uniform-masks-20k" --split val --ood \
    --out "$ROOT/runs/object/calibrated.safetensors"
# 4. ship
echo "ship: .venv/bin/python scripts/ship_model.py --name object --run $ROOT/runs/object" \
     "--train-data $ROOT/photo-train-uniform-masks-20k --test-data $ROOT/photo-test-uniform-masks" \
     "--model $ROOT/runs/object/calibrated.safetensors --notes NOTES.md"

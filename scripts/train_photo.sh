#!/usr/bin/env bash
# The shipped photo model (relight/models/photo.safetensors; MODEL_CARD_photo.md, docs/photo.md):
# two datasets, two training stages from the shipped sid2 weights, calibration, shipping.
# Resumable: re-run the same command after a kill or a new session (each step skips what is done;
# relight generate and relight train resume). Default root /root/relight-data (outside the repo).
# About 2.5 hours of generation and 1.2 hours of training on a quiet 2-core machine.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=${1:-/root/relight-data}
RELIGHT=${RELIGHT:-.venv/bin/relight}
# 1. the photo mix with the second round's factors: the first 28,691 images of seed 201
#    (the same images as the first 28,691 of make_photo.sh's FACTORS=1 set; split 90/10)
"$RELIGHT" generate --preset photo --count 28691 --seed 201 --config scenes/configs/photo_train_factors.json \
    --out "$ROOT/photo-train-factors" --quiet
# 2. stage 1 (docs/photo.md, fourth round): the camera frame, pipeline augmentation on the EXRs
"$RELIGHT" train --data "$ROOT/photo-train-factors" --out "$ROOT/runs/photo-cam" --init sid2 \
    --target-frame camera --camera-weight 1 --source exr --augment photo --lr 1e-4 --patience 2 \
    --epochs 30 --epoch-images 8000 --torch-threads 2 --quiet
# 3. dim voids (void_albedo 0-0.3; fifth round): 6,000 images of seed 204
"$RELIGHT" generate --preset photo --count 6000 --seed 204 --config scenes/configs/photo_train_backdrop_grey.json \
    --out "$ROOT/photo-backdrop-grey" --quiet
# 4. stage 2: the fine-tune on them
"$RELIGHT" train --data "$ROOT/photo-backdrop-grey" --out "$ROOT/runs/photo-backdrop-grey" \
    --init "$ROOT/runs/photo-cam/best.safetensors" --target-frame camera --camera-weight 1 --source exr \
    --augment photo --lr 3e-5 --patience 2 --epochs 8 --torch-threads 2 --quiet
# 5. the cones and the out-of-distribution flag, fitted on stage 2's val split
[ -f "$ROOT/runs/photo-backdrop-grey/calibrated.safetensors" ] || "$RELIGHT" calibrate \
    --model "$ROOT/runs/photo-backdrop-grey" --data "$ROOT/photo-backdrop-grey" --split val --ood \
    --out "$ROOT/runs/photo-backdrop-grey/calibrated.safetensors"
# 6. ship: scripts/ship_model.py --name photo (test set: make_photo.sh with BACKDROP=1, its test part)
echo "ship: .venv/bin/python scripts/ship_model.py --name photo --run $ROOT/runs/photo-backdrop-grey" \
     "--train-data $ROOT/photo-train-factors --train-data $ROOT/photo-backdrop-grey" \
     "--test-data $ROOT/photo-test-backdrop --model $ROOT/runs/photo-backdrop-grey/calibrated.safetensors" \
     "--other-test sid2=$ROOT/sid2p-test500 --other-test factors=$ROOT/photo-test-factors --notes NOTES.md"

#!/usr/bin/env bash
# The photo-training set (--preset photo; docs/photo.md): resumable, re-run the same command
# after a kill or a new session. Default root /root/relight-data (outside the repository).
#   test:  2,500 images, seed 202 (never used for training), evaluate with --split all
#   train: 50,000 images, seed 201, split 90/10 -> ~45,000 train + ~5,000 val
# 128 px, multijitter, 16 spp (2% noise); camera-pipeline effects are applied at training time
# to the stored linear EXRs (relight train --source exr --augment photo), not baked in here.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=${1:-/root/relight-data}
RELIGHT=${RELIGHT:-.venv/bin/relight}
"$RELIGHT" generate --preset photo --count 2500 --out "$ROOT/photo-test" --seed 202
"$RELIGHT" generate --preset photo --count 50000 --out "$ROOT/photo-train" --seed 201 \
    --config scenes/configs/sid2_train.json

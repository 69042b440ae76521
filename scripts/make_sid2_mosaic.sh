#!/usr/bin/env bash
# SID2-scale data with mosaic backgrounds (--backgrounds mosaic: walls and floor are grids of
# 16-256 independently coloured cells; docs/generator.md "Backgrounds"), to measure what many
# independent surfaces in view do to the colour error. Resumable: re-run the same command
# after a kill or a new session. Default root /root/relight-data (outside the repository).
#   test:  2,500 images, seed 9 (never used for training), evaluate with --split all
#   train: 50,000 images, seed 10, split 90/10 -> ~45,000 train + ~5,000 val
# Otherwise the generator's defaults (128 px, multijitter, 16 spp, colour prior hsv, 1-32
# object parts).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=${1:-/root/relight-data}
RELIGHT=${RELIGHT:-.venv/bin/relight}
"$RELIGHT" generate --count 2500 --out "$ROOT/sid2m-test" --seed 9 --backgrounds mosaic
"$RELIGHT" generate --count 50000 --out "$ROOT/sid2m-train" --seed 10 --backgrounds mosaic \
    --config scenes/configs/sid2_train.json

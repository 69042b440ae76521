#!/usr/bin/env bash
# SID2-scale data with multi-coloured objects (--object-parts 1-32, the paper's colour per
# mesh part; docs/generator.md "Multi-coloured objects"): resumable, re-run the same command after a
# kill or a new session. Default root /root/relight-data (outside the repository).
#   test:  2,500 images, seed 5 (never used for training), evaluate with --split all
#   train: 50,000 images, seed 6, split 90/10 -> ~45,000 train + ~5,000 val
#   per-prior tests: 1,000 images each with the munsell (seed 7) and mixture (seed 8) colour
#          priors, for the model card's colour error on each prior (hsv: the main test set)
# Otherwise the generator's defaults (128 px, multijitter, 16 spp, colour prior hsv).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=${1:-/root/relight-data}
PARTS=${PARTS:-1-32}
RELIGHT=${RELIGHT:-.venv/bin/relight}
"$RELIGHT" generate --count 2500 --out "$ROOT/sid2p-test" --seed 5 --object-parts "$PARTS"
"$RELIGHT" generate --count 50000 --out "$ROOT/sid2p-train" --seed 6 --object-parts "$PARTS" \
    --config scenes/configs/sid2_train.json
"$RELIGHT" generate --count 1000 --out "$ROOT/sid2p-test-munsell" --seed 7 --object-parts "$PARTS" --colour-prior munsell
"$RELIGHT" generate --count 1000 --out "$ROOT/sid2p-test-mixture" --seed 8 --object-parts "$PARTS" --colour-prior mixture


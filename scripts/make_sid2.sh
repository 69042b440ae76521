#!/usr/bin/env bash
# The paper-scale SID2-style data (issue 8): resumable, re-run the same command after a
# kill or a new session. Default root /root/relight-data (outside the repository).
#   train: 50,000 images, seed 1, split 90/10 -> ~45,000 train (the paper's count) + ~5,000 val
#   test:  2,500 images, seed 2 (never used for training), evaluate with --split all
#   per-prior tests: 1,000 images each with the munsell (seed 3) and mixture (seed 4) colour
#          priors, for the model card's colour error on each prior (hsv: the main test set)
# Generator defaults: 128 px, multijitter, 2% relative RMSE target (16 spp), colour prior hsv;
# one-colour objects (--object-parts 1, the default before 1-32; scripts/make_sid2_parts.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=${1:-/root/relight-data}
RELIGHT=${RELIGHT:-.venv/bin/relight}
"$RELIGHT" generate --count 2500 --out "$ROOT/sid2-test" --seed 2 --object-parts 1
"$RELIGHT" generate --count 50000 --out "$ROOT/sid2-train" --seed 1 --object-parts 1 --config scenes/configs/sid2_train.json
"$RELIGHT" generate --count 1000 --out "$ROOT/sid2-test-munsell" --seed 3 --object-parts 1 --colour-prior munsell
"$RELIGHT" generate --count 1000 --out "$ROOT/sid2-test-mixture" --seed 4 --object-parts 1 --colour-prior mixture

#!/usr/bin/env bash
# Train the paper-scale network on the SID2-scale data of scripts/make_sid2.sh (issue 8).
# Resumable: re-run the same command after a kill or a new session (it continues from the
# run's last checkpoint; the Adam state, the plateau schedule and the shuffling resume too).
#   bash scripts/train_sid2.sh small|paper [ROOT] [THREADS]   (THREADS may change between runs)
# The equal-time choice of the encoder: run `small` and `paper` side by side (one thread
# each, started together), then `.venv/bin/python benchmarks/bench_arch.py --runs
# ROOT/runs/sid2-small ROOT/runs/sid2-paper` compares them at equal training time.
set -euo pipefail
cd "$(dirname "$0")/.."
ARCH=${1:?usage: train_sid2.sh small|paper [ROOT] [THREADS]}
ROOT=${2:-/root/relight-data}
THREADS=${3:-1}
RELIGHT=${RELIGHT:-.venv/bin/relight}
mkdir -p "$ROOT/runs"
exec "$RELIGHT" train --data "$ROOT/sid2-train" --out "$ROOT/runs/sid2-$ARCH" --arch "$ARCH" \
    --epochs 40 --torch-threads "$THREADS"

#!/usr/bin/env bash
# The shipped chrome-sphere locator (relight/models/probe_locator.safetensors; relight.probe.locator,
# docs/probe-history.md twelfth round): 1,214 generated probe scenes rendered by Mitsuba (seeds 100000-101213,
# disjoint from every set it is judged on), then 16 epochs with a camera pipeline on half the images.
# Resumable: re-run the same command (finished scenes are skipped). Default root /root/relight-data.
# About 30 minutes of rendering and 12 minutes of training on a quiet 2-core machine.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=${1:-/root/relight-data}
PY=${PY:-.venv/bin/python}
DATA="$ROOT/issue-29/detector-train"
"$PY" benchmarks/bench_probe.py --set "$DATA" --make 1214 --first 100000 --no-cycles --no-auto --no-psm \
    --renderers none --worst 0
"$PY" benchmarks/train_locator.py --train "$DATA" --limit 1214 --epochs 16 --augment 0.5 \
    --save relight/models/probe_locator.safetensors --force

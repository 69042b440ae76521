#!/usr/bin/env bash
# The shipped outline check (relight/models/probe_outline_check.safetensors; relight.probe.outline_check,
# docs/probe-history.md fourteenth round): trained on the locator's 1,214 Mitsuba training scenes (seeds
# 100000-101213, disjoint from every set it is judged on; scripts/train_locator.sh renders the missing
# ones), 24 candidate circles drawn around each true one, half of them through a camera pipeline.
# Resumable: re-run the same command (the rendering skips finished scenes; the training starts over,
# about 20 minutes on a quiet 2-core machine). Default root /root/relight-data.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=${1:-/root/relight-data}
PY=${PY:-.venv/bin/python}
DATA="$ROOT/issue-29/detector-train"
"$PY" benchmarks/bench_probe.py --set "$DATA" --make 1214 --first 100000 --no-cycles --no-auto --no-psm \
    --renderers none --worst 0
"$PY" benchmarks/train_outline_check.py --train "$DATA" --limit 1214 --epochs 12 --per-scene 24 --augment 0.5 \
    --save relight/models/probe_outline_check.safetensors --force

#!/usr/bin/env bash
# The shipped rim reader (relight/models/probe_rim.safetensors; relight.probe.rim, docs/probe-history.md
# twenty-fifth round): generated probe scenes disjoint from every set it is judged on -- 300 drawn as the
# team's renders (seeds 30000-30299: 256 px, FOV 30, chrome radius 15-20 px; Mitsuba and Cycles with
# Blender's filter) and 150 of the default draw (seeds 31000-31149, Mitsuba) -- and 1,000 mirrors in a
# distant room drawn in the training itself (seeds 0-999, nothing stored). Two rim fits drawn off the
# truth per image, 8 epochs. Resumable: re-run the same command (finished renders are skipped; the
# training starts over). Default root /root/relight-data. About 60 minutes of rendering (Cycles: see
# scripts/setup_blender.sh) and 10 minutes of training on a quiet 2-core machine.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=${1:-/root/relight-data}
PY=${PY:-.venv/bin/python}
TEAM="$ROOT/issue-29/train-team"
HELD="$ROOT/issue-29/train-held"
"$PY" benchmarks/bench_probe.py --set "$TEAM" --make 300 --first 30000 --res 256 --fov 30 --chrome-radius 15-20 \
    --cycles-filter blackman-harris --no-auto --no-psm --renderers none --worst 0
"$PY" benchmarks/bench_probe.py --set "$HELD" --make 150 --first 31000 --no-cycles --no-auto --no-psm \
    --renderers none --worst 0
"$PY" benchmarks/train_rim.py --train "$TEAM" "$HELD" --rooms 1000 --copies 2 --epochs 8 \
    --save relight/models/probe_rim.safetensors --force

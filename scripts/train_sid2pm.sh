#!/usr/bin/env bash
# Stage 4 (candidate): fine-tune the model shipped at commit e0cdd45 (stage 3, pattern
# backgrounds) on pattern and mosaic rooms together: the train splits of
# scripts/make_sid2_parts.sh (sid2p-train) and scripts/make_sid2_mosaic.sh (sid2m-train) are
# joined, so the colour of many-surface rooms is learnt without forgetting the patterns.
# Same learning rate and loss weights as stage 3. Resumable: re-run the same command after a
# kill or a new session; while sid2m-train is still being generated, each epoch re-reads its
# manifest and trains on what exists.
#   bash scripts/train_sid2pm.sh [ROOT] [THREADS]
# Then evaluate on both backgrounds:
#   relight evaluate --model ROOT/runs/sid2pm-ft --data ROOT/sid2p-test --split all --out EVAL_P
#   relight evaluate --model ROOT/runs/sid2pm-ft --data ROOT/sid2m-test --split all --out EVAL_M
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=${1:-/root/relight-data}
THREADS=${2:-2}
RELIGHT=${RELIGHT:-.venv/bin/relight}
BASE_COMMIT=e0cdd45
BASE=$ROOT/runs/sid2-$BASE_COMMIT.safetensors
mkdir -p "$ROOT/runs"
if [ ! -f "$BASE" ]; then   # its header keeps the earlier stages' records
    git show "$BASE_COMMIT:relight/models/sid2.safetensors" > "$BASE.part"
    mv "$BASE.part" "$BASE"
fi
exec "$RELIGHT" train --init "$BASE" --data "$ROOT/sid2p-train" --data "$ROOT/sid2m-train" \
    --out "$ROOT/runs/sid2pm-ft" --lr 2e-5 --loss-weights 1,1,4 --epochs 20 --torch-threads "$THREADS" \
    --arch paper --kappa-weight 1 --resume

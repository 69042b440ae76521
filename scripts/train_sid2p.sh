#!/usr/bin/env bash
# Stage 3 of the shipped model: fine-tune the two-stage model shipped at commit e14f98a
# (trained on one-colour objects, scripts/make_sid2.sh) on the multi-coloured-object data
# of scripts/make_sid2_parts.sh, at stage 2's learning rate and loss weights. Resumable:
# re-run the same command after a kill or a new session (--resume also lets a run made with
# fewer --epochs continue up to this count; the plateau schedule does not depend on it).
#   bash scripts/train_sid2p.sh [ROOT] [THREADS]
# Then: relight calibrate --model ROOT/runs/sid2p-ft --data ROOT/sid2p-train --split val --out CAL
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=${1:-/root/relight-data}
THREADS=${2:-2}
RELIGHT=${RELIGHT:-.venv/bin/relight}
BASE_COMMIT=e14f98a
BASE=$ROOT/runs/sid2-$BASE_COMMIT.safetensors
mkdir -p "$ROOT/runs"
if [ ! -f "$BASE" ]; then   # the model and its meta file (which keeps stage 1's record)
    git show "$BASE_COMMIT:relight/models/sid2.json" > "${BASE%.safetensors}.json.part"
    git show "$BASE_COMMIT:relight/models/sid2.safetensors" > "$BASE.part"
    mv "${BASE%.safetensors}.json.part" "${BASE%.safetensors}.json"
    mv "$BASE.part" "$BASE"
fi
exec "$RELIGHT" train --init "$BASE" --data "$ROOT/sid2p-train" --out "$ROOT/runs/sid2p-ft" \
    --lr 2e-5 --loss-weights 1,1,4 --epochs 20 --torch-threads "$THREADS" --arch paper --kappa-weight 1 --resume

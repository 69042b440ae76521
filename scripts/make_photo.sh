#!/usr/bin/env bash
# The photo-training set (--preset photo; docs/photo.md): resumable, re-run the same command
# after a kill or a new session. Default root /root/relight-data (outside the repository).
#   test:  2,500 images, seed 202 (never used for training), evaluate with --split all
#   train: 50,000 images, seed 201, split 90/10 -> ~45,000 train + ~5,000 val
# 128 px, multijitter, 16 spp (2% noise); camera-pipeline effects are applied at training time
# to the stored linear EXRs (relight train --source exr --augment photo), not baked in here.
# With FACTORS=1 the sets also carry the second round's factors (glossy and metal objects,
# the shipped meshes, lights near the camera: scenes/configs/photo_train_factors.json) and
# go to photo-test-factors / photo-train-factors. With BACKDROP=1 they also have dim voids
# (void_albedo 0-0.3: the fifth round; scenes/configs/photo_train_backdrop_grey.json and
# photo_test_backdrop.json), seeds 205 (train) / 206 (test), in photo-{train,test}-backdrop.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=${1:-/root/relight-data}
RELIGHT=${RELIGHT:-.venv/bin/relight}
TRAIN_SEED=201; TEST_SEED=202
if [ "${BACKDROP:-0}" = 1 ]; then
    TRAIN_CONFIG=scenes/configs/photo_train_backdrop_grey.json; SUFFIX=-backdrop
    TEST_CONFIG=(--config scenes/configs/photo_test_backdrop.json); TRAIN_SEED=205; TEST_SEED=206
elif [ "${FACTORS:-0}" = 1 ]; then
    TRAIN_CONFIG=scenes/configs/photo_train_factors.json; SUFFIX=-factors
    TEST_CONFIG=(--config scenes/configs/photo_materials_meshes_flash.json)
else
    TRAIN_CONFIG=scenes/configs/sid2_train.json; SUFFIX=""
    TEST_CONFIG=()
fi
"$RELIGHT" generate --preset photo --count 2500 --out "$ROOT/photo-test$SUFFIX" --seed "$TEST_SEED" "${TEST_CONFIG[@]}"
"$RELIGHT" generate --preset photo --count 50000 --out "$ROOT/photo-train$SUFFIX" --seed "$TRAIN_SEED" \
    --config "$TRAIN_CONFIG"

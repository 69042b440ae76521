#!/usr/bin/env bash
# Idempotent set-up of the Blender Cycles side (relight export-blender,
# benchmarks/bench_cycles.py, tests/test_blender.py): a SEPARATE virtual environment
# with bpy (PyPI; CPython 3.11 wheels only, numpy < 2), numpy, and this checkout of
# relight installed without its dependencies (the bpy side uses only relight's
# numpy modules: scene files, meshes, textures, frames).
#
#   RELIGHT_BPY_VENV   where to make it (default ~/relight-bpy-venv, where relight looks)
#   PYTHON311          a Python 3.11 interpreter (default python3.11, else python3 if 3.11)
#
# Elsewhere, point RELIGHT_BLENDER_PYTHON at that environment's bin/python.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${RELIGHT_BPY_VENV:-$HOME/relight-bpy-venv}
BPY_PIN="bpy==5.0.1"
NUMPY_PIN="numpy<2"

if [ -z "${PYTHON311:-}" ]; then
  if command -v python3.11 >/dev/null 2>&1; then PYTHON311=python3.11; else PYTHON311=python3; fi
fi
if ! "$PYTHON311" -c 'import sys; sys.exit(0 if sys.version_info[:2] == (3, 11) else 1)'; then
  echo "[setup_blender] $BPY_PIN needs CPython 3.11; set PYTHON311 to one" >&2
  exit 2
fi

if [ ! -x "$VENV/bin/python" ]; then
  echo "[setup_blender] creating virtual environment $VENV"
  "$PYTHON311" -m venv "$VENV"
fi
VPY="$VENV/bin/python"

if ! "$VPY" -c "import bpy, numpy, sys; sys.exit(0 if bpy.app.version_string == '5.0.1' and numpy.__version__ < '2' else 1)" 2>/dev/null; then
  echo "[setup_blender] installing $BPY_PIN and $NUMPY_PIN (about 400 MB)"
  "$VPY" -m pip install --quiet "$BPY_PIN" "$NUMPY_PIN"
fi

if ! (cd / && "$VPY" -c "import relight.scene.blender") 2>/dev/null; then
  echo "[setup_blender] installing relight (editable, --no-deps)"
  "$VPY" -m pip install --quiet --no-deps -e .
fi
echo "[setup_blender] ok: $("$VPY" -c 'import bpy, numpy; print("bpy", bpy.app.version_string, "numpy", numpy.__version__)') in $VENV"

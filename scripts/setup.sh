#!/usr/bin/env bash
# Idempotent set-up for a fresh machine: a libLLVM >= 17 for Dr.Jit, a virtual
# environment in .venv, torch==2.13.0 (CPU build) first, then relight[dev].
# Safe to re-run; it only installs what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${RELIGHT_VENV:-.venv}
PY=${PYTHON:-python3}

have_good_llvm() {
  for f in /usr/lib/x86_64-linux-gnu/libLLVM-1[7-9]*.so* /usr/lib/x86_64-linux-gnu/libLLVM-2[0-9]*.so* \
           /usr/lib/llvm-1[7-9]/lib/libLLVM*.so* /usr/lib/llvm-2[0-9]/lib/libLLVM*.so*; do
    [ -e "$f" ] && return 0
  done
  return 1
}

if [ ! -x "$VENV/bin/python" ]; then
  echo "[setup] creating virtual environment $VENV"
  "$PY" -m venv "$VENV"
  "$VENV/bin/python" -m pip install --quiet --upgrade pip
fi
VPY="$VENV/bin/python"

if ! "$VPY" -c "import torch, sys; sys.exit(0 if torch.__version__.startswith('2.13.0') else 1)" 2>/dev/null; then
  echo "[setup] installing torch==2.13.0 (CPU build)"
  "$VPY" -m pip install --quiet torch==2.13.0
fi

if ! "$VPY" -c "import relight" 2>/dev/null || [ pyproject.toml -nt "$VENV/.relight-installed" ]; then
  echo "[setup] installing relight[dev]"
  "$VPY" -m pip install --quiet -e ".[dev]"
  touch "$VENV/.relight-installed"
fi

# Dr.Jit's LLVM backend needs libLLVM >= 17. Prefer Debian's libllvm19 when we
# are root; otherwise the karellen-llvm-core wheel (libLLVM 23, no root needed).
if [ -z "${DRJIT_LIBLLVM_PATH:-}" ] && ! have_good_llvm; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "[setup] installing Debian libllvm19"
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 >/dev/null) \
      || echo "[setup] apt-get failed; falling back to karellen-llvm-core"
  fi
  if ! have_good_llvm; then
    echo "[setup] installing karellen-llvm-core"
    "$VPY" -m pip install --quiet karellen-llvm-core
  fi
fi
# Headless Chromium for the test that opens the compare report (skipped where absent).
# Root only, tried once per environment (RELIGHT_NO_CHROMIUM=1 skips it); never fails the set-up.
if ! command -v chromium >/dev/null 2>&1 && [ -z "${RELIGHT_NO_CHROMIUM:-}" ] \
    && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 && [ ! -e "$VENV/.chromium-tried" ]; then
  echo "[setup] installing Debian chromium (for the report test)"
  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
      chromium >/dev/null) || echo "[setup] chromium not installed; the report browser test will skip"
  touch "$VENV/.chromium-tried" || true
fi
echo "[setup] ok: $("$VPY" -c 'import relight.backend as b; print(b.describe())')"

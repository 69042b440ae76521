#!/usr/bin/env bash
# Set up (if needed) and run the demo: a small SID2-style dataset rendered with
# Mitsuba 3, the shipped network's predictions on it, and the verifier's report.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/relight demo --out "${1:-demo_out}"

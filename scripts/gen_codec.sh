#!/usr/bin/env bash
# Regenerate the C codec ecu/src/gen/td_can.[ch] from protocol/topdress.dbc (never edit them by hand).
# Usage: scripts/gen_codec.sh [OUTPUT_DIR]   (default ecu/src/gen; tests pass a temporary directory)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-ecu/src/gen}"
python="${PYTHON:-.venv/bin/python}"
"$python" -m cantools generate_c_source --use-float --database-name td_can \
    protocol/topdress.dbc -o "$out"

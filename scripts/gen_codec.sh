#!/usr/bin/env bash
# Regenerate the C codecs from the DBCs (never edit them by hand):
#   protocol/topdress.dbc     -> ecu/src/gen/td_can.[ch]           (the bus protocol)
#   protocol/topdress_hil.dbc -> ecu/ports/common/gen/td_hilcan.[ch]  (the emulator link's HIL frames)
#   protocol/topdress.dbc     -> ecu/src/gen/td_dbc.h  (ids, value tables, the parameter table:
#                                scripts/gen_proto.py)
# Usage: scripts/gen_codec.sh [OUTPUT_DIR]   (tests pass a temporary directory: both go there)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-ecu/src/gen}"
hil_out="${1:-ecu/ports/common/gen}"
python="${PYTHON:-.venv/bin/python}"
"$python" -m cantools generate_c_source --use-float --database-name td_can \
    protocol/topdress.dbc -o "$out"
"$python" -m cantools generate_c_source --use-float --database-name td_hilcan \
    protocol/topdress_hil.dbc -o "$hil_out"
"$python" scripts/gen_proto.py "$out"

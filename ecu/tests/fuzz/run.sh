#!/bin/sh
# Coverage-guided fuzzing of the ECU application with libFuzzer (clang; Debian: clang and
# libclang-rt-14-dev). Usage: ecu/tests/fuzz/run.sh [seconds] (default 60).
# Builds into build/ecu-fuzz, keeps its corpus in build/ecu-fuzz/corpus; a crash leaves the
# input that caused it in build/ecu-fuzz/ (replay: build/ecu-fuzz/fuzz_app <file>).
set -eu
cd "$(dirname "$0")/../../.."
seconds="${1:-60}"
cmake -S ecu -B build/ecu-fuzz -DCMAKE_C_COMPILER=clang -DCMAKE_BUILD_TYPE=Debug -DTD_FUZZ=ON >/dev/null
cmake --build build/ecu-fuzz -j2 --target fuzz_app
mkdir -p build/ecu-fuzz/corpus
cd build/ecu-fuzz
./fuzz_app -max_total_time="$seconds" -max_len=4096 corpus

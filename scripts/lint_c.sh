#!/usr/bin/env bash
# Static analysis of the C code (make lint-c, part of make check and make test):
#   cppcheck   - the core, the portable port code, the STM32F4 firmware and the ISOBUS layer
#   clang-tidy - the core, the portable port code and the ISOBUS layer with .clang-tidy
# A finding fails the build; one that is wrong is suppressed inline with a reason
# (/* NOLINT(check): why */ or // cppcheck-suppress id), never in a global list.
set -euo pipefail
cd "$(dirname "$0")/.."
inc=(-Iecu/include -Iecu/src/gen -Iecu/ports/common -Iecu/ports/common/gen)
host=(ecu/src/*.c ecu/ports/common/*.c)
if [ -d ecu/isobus/src ]; then
    inc+=(-Iecu/isobus/include -Iecu/isobus/src -Iecu/isobus/src/gen)
    host+=(ecu/isobus/src/*.c)
fi
cppcheck --quiet --error-exitcode=1 --std=c99 --inline-suppr -j 2 \
    --enable=warning,style,performance,portability --suppress=missingIncludeSystem \
    "${inc[@]}" "${host[@]}"
fw=(ecu/ports/stm32f4/*.c)
for variant in "" "-DFW_QEMU=1" "-DFW_ISOBUS=1" "-DFW_QEMU=1 -DFW_ISOBUS=1"; do
    cppcheck --quiet --error-exitcode=1 --std=c99 --inline-suppr \
        --enable=warning,style,performance,portability --suppress=missingIncludeSystem \
        "${inc[@]}" -Iecu/ports/stm32f4 $variant "${fw[@]}"
done
echo "cppcheck: ${#host[@]} host files and ${#fw[@]} firmware files, no findings"
# one file a process, two at a time (the two cores); any finding fails the whole run
printf '%s\0' "${host[@]}" | xargs -0 -P 2 -I{} \
    sh -c 'f=$1; shift; clang-tidy --quiet "$f" -- -std=c99 "$@" 2>/dev/null' _ {} "${inc[@]}"
echo "clang-tidy: ${#host[@]} files, no findings"

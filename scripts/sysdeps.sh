#!/usr/bin/env bash
# System packages topdress needs, installed with apt-get when missing (as root).
#   sysdeps.sh python   - what building the venv needs: venv/ensurepip and Python headers (cffi)
#   sysdeps.sh ctest    - what the C tests and their gates need: cmocka, pkg-config, gcovr
#                         (line coverage), cppcheck and clang-tidy (make lint-c)
#   sysdeps.sh firmware - what the ECU firmware needs: Debian's arm-none-eabi-gcc with newlib-nano
#   sysdeps.sh qemu     - what the emulated firmware's tests need: qemu-system-arm (and the firmware's)
#   sysdeps.sh browser  - what the display's end-to-end test needs: Debian's Chromium and its
#                         chromedriver (nothing downloads a browser), a CJK font for Chinese
#   sysdeps.sh office   - what the farm office's tests need: PostgreSQL (initdb, pg_ctl) and
#                         PostGIS for it
set -euo pipefail
what=${1:-ctest}
python=${PYTHON:-python3}
missing=()
case "$what" in
python)
    command -v "$python" >/dev/null || { echo "topdress: $python not found (Python >= 3.11 is needed)" >&2; exit 1; }
    ver=$("$python" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
    "$python" -c 'import sys; sys.exit(sys.version_info < (3, 11))' \
        || { echo "topdress: Python >= 3.11 is needed, $python is $ver" >&2; exit 1; }
    "$python" -c 'import ensurepip, venv' 2>/dev/null || missing+=("python$ver-venv")
    inc=$("$python" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
    [ -f "$inc/Python.h" ] || missing+=("python$ver-dev")
    command -v cc >/dev/null || missing+=(gcc)
    ;;
ctest)
    [ -f /usr/include/cmocka.h ] || missing+=(libcmocka-dev)
    command -v pkg-config >/dev/null || missing+=(pkg-config)
    command -v cmake >/dev/null || missing+=(cmake)
    command -v gcovr >/dev/null || missing+=(gcovr)
    command -v cppcheck >/dev/null || missing+=(cppcheck)
    command -v clang-tidy >/dev/null || missing+=(clang-tidy)
    ;;
firmware | qemu)
    command -v arm-none-eabi-gcc >/dev/null || missing+=(gcc-arm-none-eabi)
    [ -f /usr/lib/arm-none-eabi/newlib/thumb/v7e-m+fp/hard/libc_nano.a ] || missing+=(libnewlib-arm-none-eabi)
    if [ "$what" = qemu ]; then
        command -v qemu-system-arm >/dev/null || missing+=(qemu-system-arm)
    fi
    ;;
browser)
    [ -x /usr/bin/chromium ] || missing+=(chromium)
    [ -x /usr/bin/chromedriver ] || missing+=(chromium-driver)
    if ! { command -v fc-list >/dev/null && [ -n "$(fc-list :lang=zh)" ]; }; then
        missing+=(fonts-wqy-zenhei)
    fi
    ;;
office)
    initdb=$(ls /usr/lib/postgresql/*/bin/initdb 2>/dev/null | sort -V | tail -n 1 || true)
    if [ -z "$initdb" ]; then
        missing+=(postgresql postgis)
    else
        major=$(basename "$(dirname "$(dirname "$initdb")")")
        ls /usr/share/postgresql/"$major"/extension/postgis.control >/dev/null 2>&1 \
            || missing+=("postgresql-$major-postgis-3")
    fi
    ;;
*)
    echo "usage: $0 python|ctest|firmware|qemu|browser|office" >&2
    exit 2
    ;;
esac
if [ ${#missing[@]} -eq 0 ]; then exit 0; fi
if [ "$(id -u)" -ne 0 ] || ! command -v apt-get >/dev/null; then
    echo "topdress: missing system packages: ${missing[*]} (install them, e.g. sudo apt-get install ${missing[*]})" >&2
    exit 1
fi
echo "topdress: installing ${missing[*]}" >&2
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq >/dev/null
apt-get install -y -qq "${missing[@]}" >/dev/null

#!/usr/bin/env bash
# System packages the C tests need (cmocka). Installs them with apt-get when missing and root.
set -euo pipefail
missing=()
[ -f /usr/include/cmocka.h ] || missing+=(libcmocka-dev)
command -v pkg-config >/dev/null || missing+=(pkg-config)
if [ ${#missing[@]} -eq 0 ]; then exit 0; fi
if [ "$(id -u)" -ne 0 ]; then
    echo "topdress: missing system packages: ${missing[*]} (run: sudo apt-get install ${missing[*]})" >&2
    exit 1
fi
echo "topdress: installing ${missing[*]}" >&2
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq >/dev/null
apt-get install -y -qq "${missing[@]}" >/dev/null

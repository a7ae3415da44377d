#!/usr/bin/env bash
# Installs the Debian packages given as arguments that are not installed yet.
# Idempotent: does nothing (and needs no root) when all are present.
set -euo pipefail
# One dpkg-query for all of them: each call reads dpkg's whole database,
# which in the test VM comes over 9p (seconds a call on a machine with many
# packages: `make run` in tests/hw/test_hw_e2e.c took over a minute to start).
native=$(dpkg --print-architecture)
declare -A have=()
listed=$(dpkg-query -W -f='${binary:Package}\t${Status}\n' "$@" 2>/dev/null || true)
while IFS=$'\t' read -r name status; do
    [ "$status" = "install ok installed" ] || continue
    have[$name]=1
    case "$name" in
        *:"$native") have[${name%:*}]=1 ;; # Multi-Arch: same packages name their arch
        *:*) ;;
        *) have[$name:$native]=1 ;;
    esac
done <<<"$listed" # (no process substitution: the test VM has no /dev/fd)
missing=()
for p in "$@"; do
    [ -n "${have[$p]:-}" ] || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
echo "deps: installing missing packages: ${missing[*]}"
if [ "$(id -u)" -ne 0 ]; then
    echo "deps: not root; run: sudo apt-get install -y --no-install-recommends ${missing[*]}" >&2
    exit 1
fi
export DEBIAN_FRONTEND=noninteractive
# arm64 packages (make ARCH=aarch64): Debian multiarch needs the architecture.
if printf '%s\n' "${missing[@]}" | grep -q ':arm64$' && ! dpkg --print-foreign-architectures | grep -qx arm64; then
    dpkg --add-architecture arm64
fi
apt-get update -qq
apt-get install -y -qq --no-install-recommends "${missing[@]}"

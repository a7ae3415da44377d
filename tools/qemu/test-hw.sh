#!/usr/bin/env bash
# The hardware-driver tests (build/tests/hw/test_hw_*) in a Debian kernel
# booted under qemu: prints each binary's cmocka output. When the VM cannot be
# set up here (no root, no package mirror) it says so and exits 77: skipped.
set -uo pipefail
W=${QEMU_WORK:-build/qemu}; D=$(dirname "$0")
bins=${HW_BINS:-}   # the test binaries, from the Makefile
[ -n "$bins" ] || { echo "[  SKIPPED ] test-hw: no test binaries given (HW_BINS)"; exit 77; }
mkdir -p "$W"
if ! bash "$D/ensure.sh" "$W" > "$W.setup.log" 2>&1; then
    echo "[  SKIPPED ] test-hw: the qemu VM could not be set up: $(tail -1 "$W.setup.log") (log: $W.setup.log)"
    exit 77
fi
# The console is a serial line: CR LF endings, and firmware escape codes.
QEMU_WORK=$W VM_TIMEOUT=${VM_TIMEOUT:-600} bash "$D/run-in-vm.sh" -s "$D/guest-modules.sh" \
    -- sh tools/qemu/in-vm.sh $bins 2>&1 | tr -d '\r' | sed 's/\x1b\[[0-9;?]*[a-zA-Z]//g; s/\x1bc//g'
exit "${PIPESTATUS[0]}"

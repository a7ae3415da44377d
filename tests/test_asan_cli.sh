#!/usr/bin/env bash
# The whole runtime under AddressSanitizer, UndefinedBehaviorSanitizer and
# LeakSanitizer (make test), built from the sanitized objects
# (build/san/pushstep), where the end-to-end tests' sanitized build
# (build/tests/san/, docs/testing.md) does not take it: one lockstep run
# among the crowd with every output at once (recorder, flight dumps, crowd
# log, candump log, summary), and doctor on a board this machine is not.
# Replay, monitor, log, render, the camera, profile and the error paths run
# sanitized in build/tests/san/test_e2e_cli, _recorder and _camera, which
# assert their output too. A check passes on the exit status it expects and
# no sanitizer report. About 5 s.
set -uo pipefail
cd "$(dirname "$0")/.."
bin=${ASAN_PUSHSTEP:-build/san/pushstep}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
export ASAN_OPTIONS="detect_leaks=1:abort_on_error=0:exitcode=66"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
pass=0; fail=0; failed=()
n=0
# check NAME WANT_STATUS -- ARGS...
check() {
    local name=$1 want=$2; shift 3
    n=$((n + 1))
    local log="$out/$n.out"
    "$bin" "$@" >"$log" 2>&1; local rc=$?
    if [ $rc -eq "$want" ] && ! grep -Eq "ERROR: (Address|Leak)Sanitizer|runtime error:" "$log"; then
        pass=$((pass + 1)); echo "[       OK ] $name"
    else
        fail=$((fail + 1)); failed+=("$name"); echo "[  FAILED  ] $name (exit $rc, want $want)"
        grep -v '^bus ' "$log" | head -60
    fi
}
mkdir -p "$out/flight"
check "lockstep crowd with recorder, flight dumps, crowd log, candump log" 0 -- \
    --lockstep --duration 2 --quiet --record "$out/r.mcap" --flight "$out/flight" \
    --crowd-log "$out/crowd.csv" --candump "$out/c.log" --summary "$out/s.json"
check "doctor on board rpi4 (exit 1: this machine is not that board)" 1 -- doctor --board rpi4
echo "[  PASSED  ] $pass test(s)."
[ $fail -gt 0 ] && { echo "[  FAILED  ] $fail test(s), listed below:"; printf '[  FAILED  ] %s\n' "${failed[@]}"; }
[ $fail -eq 0 ]

#!/usr/bin/env bash
# Every subcommand and mode of the runtime under AddressSanitizer,
# UndefinedBehaviorSanitizer and LeakSanitizer (make test): the unit tests
# run sanitized already; this covers the end-to-end paths (the binary built
# from the same sanitized objects, build/san/pushstep): lockstep among the
# crowd with the recorder, crowd log and candump log; a replay of that log;
# monitor, log (summary, events, CSV, plot), render, camera in real time,
# pushstep camera, profile, doctor; error paths (a bad option, a bad file).
# A check passes on the exit status it expects and no sanitizer report.
# About 45 s.
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
mkdir -p "$out/flight" "$out/render" "$out/prof" "$out/cam"
check "lockstep crowd with recorder, flight dumps, crowd log, candump log" 0 -- \
    --lockstep --duration 2 --quiet --record "$out/r.mcap" --flight "$out/flight" \
    --crowd-log "$out/crowd.csv" --candump "$out/c.log" --summary "$out/s.json"
check "replay of the candump log" 0 -- --replay "$out/c.log" --duration 2 --quiet
check "monitor of the candump log" 0 -- monitor --board sim --log "$out/c.log" --rates
check "log: summary" 0 -- log "$out/r.mcap"
check "log: every event" 0 -- log "$out/r.mcap" --events
check "log: CSV and balance plot" 0 -- log "$out/r.mcap" --csv "$out/b.csv" --plot "$out/b.png" \
    --signals balance
check "render: frames, density map, MP4" 0 -- \
    --lockstep --duration 0.3 --quiet --render "$out/render" --render-fps 10
check "simulated camera beside the loop in real time" 0 -- \
    --board tests/data/boards/sim-camera.yaml --duration 1 --quiet
check "pushstep camera on the simulated camera" 0 -- \
    camera --board tests/data/boards/sim-camera.yaml --duration 1 --out "$out/cam"
check "profile" 0 -- profile --scenario scenarios/stand.yaml --duration 1 --quiet \
    --out "$out/prof"
check "doctor on board rpi4 (exit 1: this machine is not that board)" 1 -- doctor --board rpi4
check "a bad option: exit 2" 2 -- --no-such-option
check "a bad scenario file: exit 2" 2 -- --scenario tests/fuzz/no-such-file.yaml
echo "[  PASSED  ] $pass test(s)."
[ $fail -gt 0 ] && { echo "[  FAILED  ] $fail test(s), listed below:"; printf '[  FAILED  ] %s\n' "${failed[@]}"; }
[ $fail -eq 0 ]

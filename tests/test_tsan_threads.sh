#!/usr/bin/env bash
# The threads around the loop under ThreadSanitizer (make test): the whole
# runtime built with -fsanitize=thread (build/tsan/pushstep) runs with the
# plant thread, the logger, the recorder's writer and a flight dump, the
# camera's perception thread and the render thread, each run halting on the
# first report. Each check also asserts that the threads it is about did
# work (records written, frames detected, frames rendered), so that a run
# which never reached them cannot pass. The TSan build is slow: its real-time
# runs overrun and damp, which is fine here (and a recorder trigger). ~30 s.
set -uo pipefail
cd "$(dirname "$0")/.."
bin=${TSAN_PUSHSTEP:-build/tsan/pushstep}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
export TSAN_OPTIONS="halt_on_error=1 exitcode=66 second_deadlock_stack=1"
pass=0; fail=0; failed=()
# check NAME LOGFILE EXPECT-REGEX -- ARGS...: runs the TSan build, passes on
# exit 0, no ThreadSanitizer report, and EXPECT-REGEX in its output.
check() {
    local name=$1 log=$2 expect=$3; shift 4
    "$bin" "$@" >"$log" 2>&1; local rc=$?
    if [ $rc -eq 0 ] && ! grep -q "ThreadSanitizer" "$log" && grep -Eq "$expect" "$log"; then
        pass=$((pass + 1)); echo "[       OK ] $name"
    else
        fail=$((fail + 1)); failed+=("$name"); echo "[  FAILED  ] $name (exit $rc)"
        grep -v '^bus ' "$log" | head -60
    fi
}
mkdir -p "$out/flight" "$out/render"
check "plant, logger, recorder writer and flight dump in real time" "$out/rt.out" \
    'continuous .*: [1-9][0-9]* records' -- \
    --scenario scenarios/stand.yaml --duration 3 --quiet --candump "$out/c.log" \
    --record "$out/r.mcap" --flight "$out/flight" --flight-pre 1 --flight-post 0.5
check "perception thread and mailbox (simulated camera) in real time" "$out/cam.out" \
    'camera: [1-9][0-9]* frames' -- \
    --board tests/data/boards/sim-camera.yaml --duration 2 --quiet
check "render thread, crowd and recorder in lockstep" "$out/render.out" \
    'render: [1-9][0-9]* frames' -- \
    --lockstep --duration 0.5 --quiet --render "$out/render" --render-fps 10 \
    --crowd-log "$out/crowd.csv" --record "$out/l.mcap"
echo "[  PASSED  ] $pass test(s)."
[ $fail -gt 0 ] && { echo "[  FAILED  ] $fail test(s), listed below:"; printf '[  FAILED  ] %s\n' "${failed[@]}"; }
[ $fail -eq 0 ]

#!/usr/bin/env bash
# The short run of every fuzz target (make test; make fuzz runs them long):
# each libFuzzer target of tests/fuzz/ replays its seeds (tests/fuzz/corpus)
# and fuzzes for FUZZ_TEST_SECONDS (default 1) in a scratch corpus; a crash,
# a broken contract or a sanitizer report fails it, the input kept in
# build/fuzz/test-crashes/. Prints cmocka's summary lines for tools/run-tests.sh
# (tools/fuzz.sh --test): two at a time, 33 s for the 13 targets measured
# with load average 4 on 2 cores (docs/fuzzing.md).
set -uo pipefail
cd "$(dirname "$0")/.."
build=${BUILD:-build}
bins=${FUZZ_BINS:-$(ls "$build"/fuzz/fuzz_* 2>/dev/null)}
if [ -z "$bins" ]; then
    echo "[  FAILED  ] no fuzz targets built (make $build/fuzz/fuzz_mit ...)"
    echo "[  PASSED  ] 0 test(s)."
    echo "[  FAILED  ] 1 test(s), listed below:"
    exit 1
fi
# shellcheck disable=SC2086 # a list of paths
BUILD=$build exec bash tools/fuzz.sh --test "${FUZZ_TEST_SECONDS:-1}" $bins

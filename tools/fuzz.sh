#!/usr/bin/env bash
# Runs the libFuzzer targets (tests/fuzz/, docs/fuzzing.md), each from its
# seeds (tests/fuzz/corpus/NAME, read only) and its working corpus.
#
#   tools/fuzz.sh BIN...          make fuzz: FUZZ_SECONDS (default 60) each, one
#                                 at a time; working corpus $BUILD/fuzz/corpus/
#                                 NAME (kept between runs), crashes in
#                                 $BUILD/fuzz/crashes/NAME/, libFuzzer's output
#                                 in $BUILD/fuzz/logs/NAME.log; then writes
#                                 bench/results/fuzz.json and fuzz.md from every
#                                 target's latest log (so a run of some targets
#                                 updates their rows and keeps the others')
#   tools/fuzz.sh --report       the two files again from the logs, no run
#   tools/fuzz.sh --test S BIN... make test: S seconds each, two at a time, in a
#                                 scratch corpus with a fixed seed (a crash's
#                                 input is kept in $BUILD/fuzz/test-crashes/
#                                 NAME/); prints cmocka's lines for
#                                 tools/run-tests.sh, one test per target
# FUZZ_JOBS: targets at a time. Exit 1 if any target crashed (a broken
# contract or a sanitizer report).
set -uo pipefail
cd "$(dirname "$0")/.."
build=${BUILD:-build}
is_test=0
seconds=${FUZZ_SECONDS:-60}
is_report=0
if [ "${1:-}" = "--test" ]; then
    is_test=1
    seconds=${2:-1}
    shift 2
elif [ "${1:-}" = "--report" ]; then
    is_report=1
    shift
fi
[ $# -gt 0 ] || [ $is_report -eq 1 ] ||
    { echo "usage: tools/fuzz.sh [--test SECONDS] BIN... | --report" >&2; exit 2; }
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
if [ $is_test -eq 1 ]; then logs=$scratch; else logs=$build/fuzz/logs; fi
mkdir -p "$logs"
corpus_of() { if [ $is_test -eq 1 ]; then echo "$scratch/$1"; else echo "$build/fuzz/corpus/$1"; fi; }
art_of() { if [ $is_test -eq 1 ]; then echo "$scratch/crashes-$1/"; else echo "$build/fuzz/crashes/$1/"; fi; }

# One target: libFuzzer's output, exit status and start date into
# $logs/NAME.{log,rc,date}.
run_one() {
    local bin=$1 name seeds corpus art
    name=$(basename "$bin")
    seeds=tests/fuzz/corpus/$name
    [ -d "$seeds" ] || seeds=
    corpus=$(corpus_of "$name")
    art=$(art_of "$name")
    mkdir -p "$corpus" "$art"
    local dict=() seed=()
    [ -f "tests/fuzz/$name.dict" ] && dict=(-dict="tests/fuzz/$name.dict")
    [ $is_test -eq 1 ] && seed=(-seed=1) # make test: the same mutations each run
    date -u +%Y-%m-%dT%H:%M:%SZ >"$logs/$name.date" # also the stamp: crashes newer than it
    local start
    start=$(date +%s%N)
    # -close_fd_mask=1: the targets' stdout (pushstep log's summary) is not
    # wanted; libFuzzer's own report goes to stderr. -timeout: an input that
    # takes 10 s is a hang, reported as a crash. The seeds come second: new
    # inputs go to the first directory only.
    "$bin" -max_total_time="$seconds" -print_final_stats=1 -close_fd_mask=1 -timeout=10 \
        -rss_limit_mb=2048 -artifact_prefix="$art" "${dict[@]}" "${seed[@]}" "$corpus" $seeds \
        >"$logs/$name.log" 2>&1
    echo $? >"$logs/$name.rc"
    echo $((($(date +%s%N) - start) / 1000000)) >"$logs/$name.ms"
}

jobs=${FUZZ_JOBS:-$([ $is_test -eq 1 ] && echo 2 || echo 1)}
for bin in "$@"; do
    [ $is_report -eq 1 ] && break
    while [ "$(jobs -rp | wc -l)" -ge "$jobs" ]; do wait -n; done
    run_one "$bin" &
done
wait

# One target's figures from its files: prints a JSON object; sets n_crash.
report_one() {
    local name=$1 log=$logs/$1.log rc execs rss secs n_corpus n_seeds crashes art
    rc=$(cat "$logs/$name.rc" 2>/dev/null || echo 1)
    art=$(art_of "$name")
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    rss=$(sed -n 's/^stat::peak_rss_mb: *//p' "$log" | tail -1)
    # libFuzzer's own count of seconds; a run that crashed has none: wall time
    secs=$(sed -n 's/^Done [0-9]* runs in \([0-9]*\) second.*/\1/p' "$log" | tail -1)
    [ -n "$secs" ] || secs=$((($(cat "$logs/$name.ms" 2>/dev/null || echo 0) + 500) / 1000))
    n_corpus=$(ls "$(corpus_of "$name")" 2>/dev/null | wc -l)
    n_seeds=$(ls "tests/fuzz/corpus/$name" 2>/dev/null | wc -l)
    # this run's inputs only (earlier ones stay in the folder, for replaying)
    crashes=$(find "$art" -maxdepth 1 -type f -newer "$logs/$name.date" \
        -regex '.*/\(crash\|leak\|timeout\|oom\)-.*' -printf '%f\n' 2>/dev/null || true)
    n_crash=$(printf '%s' "$crashes" | grep -c . || true)
    if [ "$rc" -ne 0 ] && [ "$n_crash" -eq 0 ]; then n_crash=1; crashes="(exit $rc, no input saved)"; fi
    execs=${execs:-0}
    printf '{"target": "%s", "date": "%s", "seconds": %s, "executions": %s, "exec_per_s": %s, "peak_rss_mb": %s, "seeds": %s, "corpus": %s, "crashes": %s, "crash_files": [%s]}' \
        "$name" "$(cat "$logs/$name.date" 2>/dev/null)" "$secs" "$execs" \
        "$((execs / (secs > 0 ? secs : 1)))" "${rss:-0}" "$n_seeds" "$n_corpus" "$n_crash" \
        "$(printf '%s\n' "$crashes" | grep . | sed 's/.*/"&"/' | paste -sd, -)"
}

if [ $is_test -eq 1 ]; then
    n_pass=0; n_fail=0; failed=()
    for bin in "$@"; do
        name=$(basename "$bin")
        report_one "$name" >"$scratch/row" # not in $(...): it sets n_crash
        line=$(cat "$scratch/row")
        execs=$(printf '%s' "$line" | sed 's/.*"executions": \([0-9]*\).*/\1/')
        if [ "$n_crash" -eq 0 ]; then
            n_pass=$((n_pass + 1))
            echo "[       OK ] $name: $execs executions in $seconds s, no crash"
        else
            n_fail=$((n_fail + 1)); failed+=("$name")
            echo "[  FAILED  ] $name: crashed after $execs executions"
            grep -E 'contract broken|ERROR: |SUMMARY|runtime error' "$logs/$name.log" | head -5
            mkdir -p "$build/fuzz/test-crashes/$name"
            cp "$(art_of "$name")"* "$build/fuzz/test-crashes/$name/" 2>/dev/null
            echo "    input kept in $build/fuzz/test-crashes/$name/ (reproduce: $bin FILE)"
        fi
    done
    echo "[  PASSED  ] $n_pass test(s)."
    if [ $n_fail -gt 0 ]; then
        echo "[  FAILED  ] $n_fail test(s), listed below:"
        printf '[  FAILED  ] %s\n' "${failed[@]}"
        exit 1
    fi
    exit 0
fi

# make fuzz: every target that has a log, this run's and earlier ones'.
rows=(); n_fail=0; this_run_failed=0
for log in "$logs"/*.log; do
    name=$(basename "$log" .log)
    report_one "$name" >"$scratch/row"
    rows+=("$(cat "$scratch/row")")
    [ "$n_crash" -gt 0 ] && n_fail=$((n_fail + 1))
    for bin in "$@"; do
        if [ "$(basename "$bin")" = "$name" ] && [ "$n_crash" -gt 0 ]; then
            this_run_failed=1
            echo "$name: crashed; input in $(art_of "$name") (reproduce: $bin FILE)"
            grep -E 'contract broken|ERROR: |SUMMARY|runtime error' "$log" | head -5
        fi
    done
done
mkdir -p bench/results
{
    printf '{\n  "what": "libFuzzer targets of tests/fuzz (docs/fuzzing.md), one at a time",\n'
    printf '  "host": "%s, %s CPUs",\n  "targets": [\n' "$(uname -r)" "$(nproc)"
    for i in "${!rows[@]}"; do
        printf '    %s%s\n' "${rows[$i]}" "$([ "$i" -lt $((${#rows[@]} - 1)) ] && echo ,)"
    done
    printf '  ],\n  "targets_crashed": %s\n}\n' "$n_fail"
} >bench/results/fuzz.json
/usr/bin/python3 - <<'PY'
import json
r = json.load(open("bench/results/fuzz.json"))
lines = ["# Fuzzing (make fuzz)", "",
         "Each target's latest run (%s). Seeds: tests/fuzz/corpus; working corpus:"
         " build/fuzz/corpus; crashes: build/fuzz/crashes." % r["host"], "",
         "| target | run | seconds | executions | exec/s | corpus (seeds) | peak RSS MB | crashes |",
         "|---|---|---:|---:|---:|---:|---:|---:|"]
for t in r["targets"]:
    lines.append("| %s | %s | %s | %s | %s | %s (%s) | %s | %s |" % (
        t["target"], t["date"], t["seconds"], format(t["executions"], ","),
        format(t["exec_per_s"], ","), t["corpus"], t["seeds"], t["peak_rss_mb"], t["crashes"]))
lines += ["", "Targets whose latest run crashed: %d" % r["targets_crashed"]]
open("bench/results/fuzz.md", "w").write("\n".join(lines) + "\n")
print("\n".join(lines))
PY
[ $this_run_failed -eq 0 ]

#!/usr/bin/env bash
# Runs the libFuzzer targets (tests/fuzz/, docs/fuzzing.md), one after the
# other, each from its seeds (tests/fuzz/corpus/NAME, read only) and its
# working corpus.
#
#   tools/fuzz.sh BIN...          make fuzz: FUZZ_SECONDS (default 60) each,
#                                 working corpus $BUILD/fuzz/corpus/NAME (kept
#                                 between runs), crashes in $BUILD/fuzz/crashes/
#                                 NAME/; writes bench/results/fuzz.json and
#                                 fuzz.md (executions, corpus, crashes)
#   tools/fuzz.sh --test S BIN... make test: S seconds each in a scratch
#                                 corpus (a crash's input is kept in
#                                 $BUILD/fuzz/test-crashes/NAME/); prints
#                                 cmocka's lines for tools/run-tests.sh, one
#                                 test per target
# Exit 1 if any target crashed (a broken contract or a sanitizer report).
set -uo pipefail
cd "$(dirname "$0")/.."
build=${BUILD:-build}
is_test=0
seconds=${FUZZ_SECONDS:-60}
if [ "${1:-}" = "--test" ]; then
    is_test=1
    seconds=${2:-1}
    shift 2
fi
[ $# -gt 0 ] || { echo "usage: tools/fuzz.sh [--test SECONDS] BIN..." >&2; exit 2; }
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
# Where each target's corpus and crash artifacts go.
corpus_of() { if [ $is_test -eq 1 ]; then echo "$scratch/$1"; else echo "$build/fuzz/corpus/$1"; fi; }
art_of() { if [ $is_test -eq 1 ]; then echo "$scratch/crashes-$1/"; else echo "$build/fuzz/crashes/$1/"; fi; }

# One target: its log, exit status and wall time into $scratch/NAME.{log,rc,ms}.
run_one() {
    local bin=$1 name seeds corpus art start
    name=$(basename "$bin")
    seeds=tests/fuzz/corpus/$name
    [ -d "$seeds" ] || seeds=
    corpus=$(corpus_of "$name")
    art=$(art_of "$name")
    mkdir -p "$corpus" "$art"
    local dict=() seed=()
    [ -f "tests/fuzz/$name.dict" ] && dict=(-dict="tests/fuzz/$name.dict")
    [ $is_test -eq 1 ] && seed=(-seed=1) # make test: the same mutations each run
    start=$(date +%s%N)
    # -close_fd_mask=1: the targets' stdout (pushstep log's summary) is not
    # wanted; libFuzzer's own report goes to stderr. -timeout: an input that
    # takes 10 s is a hang, reported as a crash. The seeds come second: new
    # inputs go to the first directory only.
    "$bin" -max_total_time="$seconds" -print_final_stats=1 -close_fd_mask=1 -timeout=10 \
        -rss_limit_mb=2048 -artifact_prefix="$art" "${dict[@]}" "${seed[@]}" "$corpus" $seeds \
        >"$scratch/$name.log" 2>&1
    echo $? >"$scratch/$name.rc"
    echo $((($(date +%s%N) - start) / 1000000)) >"$scratch/$name.ms"
}

# FUZZ_JOBS targets at a time (make test: 2, the short runs; make fuzz: 1,
# so that the executions of one target are comparable from run to run).
jobs=${FUZZ_JOBS:-$([ $is_test -eq 1 ] && echo 2 || echo 1)}
for bin in "$@"; do
    while [ "$(jobs -rp | wc -l)" -ge "$jobs" ]; do wait -n; done
    run_one "$bin" &
done
wait

results=()
n_pass=0; n_fail=0; failed=()
for bin in "$@"; do
    name=$(basename "$bin")
    seeds=tests/fuzz/corpus/$name
    [ -d "$seeds" ] || seeds=
    corpus=$(corpus_of "$name")
    art=$(art_of "$name")
    log=$scratch/$name.log
    rc=$(cat "$scratch/$name.rc")
    wall_ms=$(cat "$scratch/$name.ms")
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    rss=$(sed -n 's/^stat::peak_rss_mb: *//p' "$log" | tail -1)
    n_corpus=$(ls "$corpus" | wc -l)
    n_seeds=0; [ -n "$seeds" ] && n_seeds=$(ls "$seeds" | wc -l)
    crashes=$(ls "$art" | grep -E '^(crash|leak|timeout|oom)-' || true)
    n_crash=$(printf '%s' "$crashes" | grep -c . || true)
    if [ $rc -ne 0 ] && [ "$n_crash" -eq 0 ]; then n_crash=1; crashes="(exit $rc, no artifact)"; fi
    if [ "$n_crash" -eq 0 ]; then
        n_pass=$((n_pass + 1))
        echo "[       OK ] $name: ${execs:-0} executions in ${seconds} s, no crash"
    else
        n_fail=$((n_fail + 1)); failed+=("$name")
        echo "[  FAILED  ] $name: $n_crash crash(es) after ${execs:-?} executions"
        grep -E 'contract broken|ERROR: |SUMMARY|runtime error' "$log" | head -5
        if [ $is_test -eq 1 ]; then
            mkdir -p "$build/fuzz/test-crashes/$name"
            cp "$art"* "$build/fuzz/test-crashes/$name/" 2>/dev/null
            echo "    input kept in $build/fuzz/test-crashes/$name/ (reproduce: $bin FILE)"
        else
            echo "    input in $art (reproduce: $bin FILE)"
        fi
    fi
    results+=("$(printf '{"target": "%s", "seconds": %s, "wall_s": %d.%03d, "executions": %s, "exec_per_s": %s, "peak_rss_mb": %s, "seeds": %s, "corpus": %s, "crashes": %s, "crash_files": [%s]}' \
        "$name" "$seconds" $((wall_ms / 1000)) $((wall_ms % 1000)) "${execs:-0}" "$(( ${execs:-0} / (seconds > 0 ? seconds : 1) ))" \
        "${rss:-0}" "$n_seeds" "$n_corpus" "$n_crash" \
        "$(printf '%s\n' "$crashes" | grep . | sed 's/.*/"&"/' | paste -sd, -)")")
done

if [ $is_test -eq 1 ]; then
    echo "[  PASSED  ] $n_pass test(s)."
    [ $n_fail -gt 0 ] && echo "[  FAILED  ] $n_fail test(s), listed below:" && printf '[  FAILED  ] %s\n' "${failed[@]}"
    [ $n_fail -eq 0 ]
    exit
fi

mkdir -p bench/results
{
    printf '{\n  "what": "libFuzzer targets of tests/fuzz (docs/fuzzing.md), one after the other",\n'
    printf '  "date": "%s",\n  "host": "%s, %s CPUs",\n  "fuzz_seconds_per_target": %s,\n' \
        "$(date -u +%Y-%m-%dT%H:%M:%SZ)" "$(uname -r)" "$(nproc)" "$seconds"
    printf '  "targets": [\n'
    for i in "${!results[@]}"; do
        printf '    %s%s\n' "${results[$i]}" "$([ "$i" -lt $((${#results[@]} - 1)) ] && echo ,)"
    done
    printf '  ],\n  "targets_crashed": %s\n}\n' "$n_fail"
} >bench/results/fuzz.json
/usr/bin/python3 - <<'PY'
import json
r = json.load(open("bench/results/fuzz.json"))
lines = ["# Fuzzing (make fuzz)", "",
         "%s, %s s per target (%s). Seeds: tests/fuzz/corpus; working corpus: build/fuzz/corpus."
         % (r["date"], r["fuzz_seconds_per_target"], r["host"]), "",
         "| target | executions | exec/s | corpus (seeds) | peak RSS MB | crashes |",
         "|---|---:|---:|---:|---:|---:|"]
for t in r["targets"]:
    lines.append("| %s | %s | %s | %s (%s) | %s | %s |" % (
        t["target"], format(t["executions"], ","), format(t["exec_per_s"], ","), t["corpus"],
        t["seeds"], t["peak_rss_mb"], t["crashes"]))
lines += ["", "Targets with a crash: %d" % r["targets_crashed"]]
open("bench/results/fuzz.md", "w").write("\n".join(lines) + "\n")
print("\n".join(lines))
PY
[ $n_fail -eq 0 ]

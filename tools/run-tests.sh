#!/usr/bin/env bash
# Runs each cmocka test binary given, prints its output, and ends with one
# line "N passed, N failed" summed over all binaries (tests that crash before
# cmocka's summary count as one failure each). Exit 1 if anything failed.
# A binary that exits 77 after a line "[  SKIPPED ] why" is listed as skipped.
# Tests cmocka skipped inside a binary, and the checks a sanitized build
# reports rather than asserts (lines "[ NOT ASSERTED ] what: n (why)",
# tests/fakes/ps_san.h), are counted on a line of their own.
set -uo pipefail
passed=0; failed=0; crashed=(); skipped=(); n_skipped_tests=0; n_not_asserted=0
for bin in "$@"; do
    name=$(basename "$bin")
    case "$bin" in */tests/san/*) name="san/$name" ;; esac # the sanitized e2e build
    echo "=== $name"
    t0=$(date +%s.%N)
    out=$("$bin" 2>&1); rc=$?
    printf '%s\n' "$out"
    # each binary's wall time, so the suite's 15-minute budget can be read off a log
    awk -v n="$name" -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN { printf "--- %s: %.1f s\n", n, b - a }'
    # grep on a here-string: `printf | grep -q` dies of SIGPIPE under pipefail
    # when grep stops reading early in a long output.
    if [ "$rc" -eq 77 ] && grep -q '^\[  SKIPPED \]' <<<"$out"; then
        skipped+=("$(printf '%s\n' "$out" | sed -n 's/^\[  SKIPPED \] //p' | head -1)"); continue
    fi
    p=$(printf '%s\n' "$out" | sed -n 's/^\[  PASSED  \] \([0-9]\+\) test(s)\./\1/p' | awk '{s+=$1} END {print s+0}')
    f=$(printf '%s\n' "$out" | sed -n 's/^\[  FAILED  \] \([0-9]\+\) test(s), listed below:/\1/p' | awk '{s+=$1} END {print s+0}')
    if ! grep -q '^\[  PASSED  \]' <<<"$out"; then
        crashed+=("$name (rc $rc)"); f=$((f + 1))
    elif [ "$rc" -ne 0 ] && [ "$f" -eq 0 ]; then
        crashed+=("$name (rc $rc)"); f=1
    fi
    passed=$((passed + p)); failed=$((failed + f))
    ns=$(printf '%s\n' "$out" | sed -n 's/^\[  SKIPPED \] \([0-9]\+\) test(s), listed below:/\1/p' | awk '{s+=$1} END {print s+0}')
    n_skipped_tests=$((n_skipped_tests + ns))
    n_not_asserted=$((n_not_asserted + $(grep -c '^\[ NOT ASSERTED \]' <<<"$out")))
done
for s in "${skipped[@]}"; do printf 'skipped: %s\n' "$s"; done
[ ${#crashed[@]} -gt 0 ] && printf 'did not finish cleanly: %s\n' "${crashed[*]}"
[ "$n_skipped_tests" -gt 0 ] && echo "$n_skipped_tests tests skipped inside their binaries (lines above say why)"
[ "$n_not_asserted" -gt 0 ] &&
    echo "$n_not_asserted checks not asserted in a sanitized build (their [ NOT ASSERTED ] lines say why)"
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]

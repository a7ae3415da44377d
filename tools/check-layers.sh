#!/usr/bin/env bash
# check-layers.sh: the include layering of docs/architecture.md, checked on
# every source and header under rt/, drivers/, policy/ and sim/ (tests/ may
# include anything). Each file's project includes are followed transitively,
# so a header that drags a forbidden one in counts too.
#
#   base     rt/ps_err, rt/ps_clock, rt/ps_ring, rt/ps_limits, rt/ps_mailbox,
#            rt/ps_neighbours: nothing else
#   drivers  base and drivers/
#   policy   base, policy/, and of drivers/ only the neutral actuator types
#            (ps_actuator.h and the ps_can.h frame it uses): no protocol
#   sim      base, drivers/ and sim/ (no policy/, no application)
#   app      every other file in rt/: base, drivers/ (no actuator protocol
#            header), policy/ and rt/; sim/ only from the composition root
#
# Output is cmocka-shaped (one "test" per file, plus a self-test that a
# planted violation is caught) so tools/run-tests.sh counts it; exit 1 on a
# violation. Usage: check-layers.sh [ROOT]   (default: the repository root)
set -uo pipefail

ROOT=${1:-$(cd "$(dirname "$0")/.." && pwd)}
# The loader files that fill sim's own structs (the scenario, the robot file's
# `sim:` section) belong to the composition root too.
COMPOSITION_ROOT="rt/main.c rt/ps_app.c rt/ps_app.h rt/ps_emulate.c rt/ps_doctor.c rt/ps_camview.c rt/ps_config_sim.h rt/ps_config_robot.c rt/ps_config_scenario.c"
BASE="rt/ps_err.h rt/ps_err.c rt/ps_clock.h rt/ps_clock.c rt/ps_ring.h rt/ps_ring.c rt/ps_limits.h
      rt/ps_mailbox.h rt/ps_mailbox.c rt/ps_neighbours.h"
POLICY_DRIVERS="drivers/ps_actuator.h drivers/ps_can.h"
# Actuator protocols: only drivers/ (the registry) and sim/ (the drives' side)
# may name one; the loop, the servo and the loader go through ps_actuator.h.
PROTOCOL_HEADERS="drivers/ps_mit.h drivers/ps_robstride.h drivers/ps_moteus.h"

is_in() { local x=$1; shift; for y in "$@"; do [ "$x" = "$y" ] && return 0; done; return 1; }

# The layer of file $1, into LAYER (a global: no subshell per call; the
# checks below run for every include of every file).
layer_of() {
    local f=$1
    if is_in "$f" $BASE; then LAYER=base; return; fi
    case $f in
    drivers/*) LAYER=drivers ;;
    policy/*) LAYER=policy ;;
    sim/*) LAYER=sim ;;
    rt/*) LAYER=app ;;
    *) LAYER=other ;;
    esac
}

# Direct project includes of every file under the four folders, as paths
# relative to ROOT, read once: DIRECT[file] (newline-separated).
declare -A DIRECT=()
read_direct_includes() {
    local f dir incs
    while read -r f; do
        dir=$(dirname "$f")
        incs=$(sed -n 's/^[[:space:]]*#[[:space:]]*include[[:space:]]*"\([^"]*\)".*/\1/p' "$ROOT/$f")
        if [ -n "$incs" ]; then
            # shellcheck disable=SC2086 # one argument per include
            DIRECT[$f]=$(cd "$ROOT/$dir" && realpath -m --relative-to="$ROOT" $incs)
        else
            DIRECT[$f]=""
        fi
    done < <(cd "$ROOT" && find rt drivers policy sim -name '*.[ch]' -o -name '*.cpp' | sort)
}

# Transitive closure (files only under the four layer folders) into CLOSURE.
closure() {
    local -A seen=()
    local stack=("$1") f inc
    while [ ${#stack[@]} -gt 0 ]; do
        f=${stack[-1]}
        unset 'stack[-1]'
        for inc in ${DIRECT[$f]:-}; do
            [ -n "${seen[$inc]:-}" ] && continue
            seen[$inc]=1
            [ -f "$ROOT/$inc" ] && stack+=("$inc")
        done
    done
    CLOSURE=("${!seen[@]}")
}

# Why file f may not include inc, into WHY (empty when it may).
violation() {
    local f=$1 inc=$2 lf li
    WHY=""
    layer_of "$f"
    lf=$LAYER
    layer_of "$inc"
    li=$LAYER
    case $lf in
    base) [ "$li" = base ] || WHY="base includes $li" ;;
    drivers) is_in "$li" base drivers || WHY="drivers/ includes $li" ;;
    policy)
        if [ "$li" = drivers ]; then
            is_in "$inc" $POLICY_DRIVERS || WHY="policy/ includes a protocol or port header"
        else
            is_in "$li" base policy || WHY="policy/ includes $li"
        fi
        ;;
    sim) is_in "$li" base drivers sim || WHY="sim/ includes $li" ;;
    app)
        if [ "$li" = sim ]; then
            is_in "$f" $COMPOSITION_ROOT ||
                WHY="application code outside the composition root includes sim/"
        elif is_in "$inc" $PROTOCOL_HEADERS; then
            WHY="application code names an actuator protocol (use drivers/ps_actuator.h)"
        else
            is_in "$li" base drivers policy app || WHY="rt/ includes $li"
        fi
        ;;
    esac
}

check_tree() {
    local n_files=0 n_bad=0 f inc
    FAILED=()
    read_direct_includes
    while read -r f; do
        n_files=$((n_files + 1))
        local bad=""
        closure "$f"
        for inc in "${CLOSURE[@]}"; do
            violation "$f" "$inc"
            [ -n "$WHY" ] && bad+="    $f -> $inc: $WHY"$'\n'
        done
        if [ -n "$bad" ]; then
            n_bad=$((n_bad + 1))
            FAILED+=("$f")
            printf '[  ERROR   ] --- %s\n%s' "$f" "$bad"
        fi
    done < <(cd "$ROOT" && find rt drivers policy sim -name '*.[ch]' -o -name '*.cpp' | sort)
    N_FILES=$n_files
    N_BAD=$n_bad
}

# The check must be able to fail: plant policy/ -> a protocol header in a
# copy of the tree and expect exactly that file to be reported.
self_test() {
    local tmp
    tmp=$(mktemp -d)
    cp -r "$ROOT/rt" "$ROOT/drivers" "$ROOT/policy" "$ROOT/sim" "$tmp/"
    printf '#include "../drivers/ps_mit.h"\n' >"$tmp/policy/ps_planted_violation.h"
    local out
    out=$(bash "$0" "$tmp" --no-self-test 2>&1)
    local rc=$?
    rm -rf "$tmp"
    [ $rc -ne 0 ] && grep -q 'policy/ps_planted_violation.h -> drivers/ps_mit.h' <<<"$out"
}

echo "[==========] Running include layering checks ($ROOT)"
check_tree
n_tests=$N_FILES
n_failed=$N_BAD
if [ "${2:-}" != "--no-self-test" ]; then
    n_tests=$((n_tests + 1))
    if self_test; then
        echo "[       OK ] layering self-test: a planted policy/ -> ps_mit.h include is caught"
    else
        echo "[  FAILED  ] layering self-test: a planted violation was not caught"
        n_failed=$((n_failed + 1))
        FAILED+=("self-test")
    fi
fi
echo "[==========] $n_tests test(s) run."
echo "[  PASSED  ] $((n_tests - n_failed)) test(s)."
if [ "$n_failed" -gt 0 ]; then
    echo "[  FAILED  ] $n_failed test(s), listed below:"
    for f in "${FAILED[@]}"; do echo "[  FAILED  ] $f"; done
    exit 1
fi
exit 0

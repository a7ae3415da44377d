#!/usr/bin/env bash
# `make bench`: every benchmark of pushstep, written to bench/results/.
#
#   latency       pushstep's wake-up latency beside cyclictest: same interval,
#                 priority, CPU, memory locking, interleaved in blocks in the
#                 order P C C P P C C P ... (see docs/latency.md for why)
#   stress_cpu    the same under `stress-ng --cpu 0` (both tools, same command)
#   tick          read-to-write compute time, plain and policy ticks, per period
#   bus           CAN bus load per bus, planned and observed, beside capacity
#   alloc         mallocs / page faults on the loop thread after init
#   recorder      the flight recorder's cost: tick time with and without
#                 recording (alternated blocks), bytes/s, records lost
#                 (bench/recorder.sh)
#
# Outputs bench/results/{latency,latency_stress_cpu,tick,bus,alloc}.json,
# summary.md and *.png (ignored by git); raw block outputs stay in
# $BUILD/bench/. Nothing is committed by this script.
#
# Knobs (environment): BENCH_PAIRS (4), BENCH_BLOCK_S (15), BENCH_STRESS_PAIRS
# (2, 0 = skip), BENCH_STRESS_BLOCK_S (10), BENCH_HIST_US (10000),
# BENCH_BOARD (sim), BENCH_ROBOT (robots/ps1.yaml), BUILD (build).
set -euo pipefail
cd "$(dirname "$0")/.."

PAIRS=${BENCH_PAIRS:-4}
BLOCK_S=${BENCH_BLOCK_S:-15}
STRESS_PAIRS=${BENCH_STRESS_PAIRS:-2}
STRESS_BLOCK_S=${BENCH_STRESS_BLOCK_S:-10}
HIST_US=${BENCH_HIST_US:-10000}
BOARD=${BENCH_BOARD:-sim}
ROBOT=${BENCH_ROBOT:-robots/ps1.yaml}
BUILD=${BUILD:-build}
BIN=$BUILD/pushstep
RESULTS=bench/results
PY=/usr/bin/python3
[ -x "$PY" ] || PY=python3

die() {
    echo "bench: $*" >&2
    exit 1
}
log() { echo "bench: $*"; }

[ -x "$BIN" ] || die "$BIN missing: run make"
"$BIN" --help | grep -q "pushstep profile" || die "$BIN has no profile subcommand"
command -v cyclictest >/dev/null || die "cyclictest missing: apt-get install rt-tests"
"$PY" bench/analyze.py --self-test >/dev/null || die "bench/analyze.py --self-test failed"

t0=$(date +%s)
RUN=$BUILD/bench/$(date +%Y%m%d-%H%M%S)
mkdir -p "$RUN" "$RESULTS"
rm -f "$RESULTS"/*.png "$RESULTS"/*.dat
: >"$RUN/blocks.tsv"
COMMANDS=()

# ---- conditions -------------------------------------------------------------

# RT privileges: cyclictest (rt-tests 2.x) refuses to start without them, so
# without them the latency section holds pushstep alone (under SCHED_OTHER).
if chrt -f 1 true 2>/dev/null; then RT=yes; else RT=no; fi

# The loop's priority, CPU and period, from the board and robot files; the
# first profile.json confirms them (and what pushstep was granted).
[ -f "boards/$BOARD.yaml" ] && BOARD_FILE=boards/$BOARD.yaml || BOARD_FILE=$BOARD
read -r PRIO LOOP_CPU WORKER_CPU SERVO_HZ < <("$PY" - "$BOARD_FILE" "$ROBOT" <<'EOF'
import re, sys
b, r = open(sys.argv[1]).read(), open(sys.argv[2]).read()
def num(text, key, default):
    m = re.search(r"\b%s:\s*(-?\d+)" % key, text)
    return int(m.group(1)) if m else default
print(num(b, "priority", 80), num(b, "loop_cpu", -1), num(b, "worker_cpu", 0),
      num(r, "servo_hz", 1000))
EOF
)
NCPU=$(nproc)
PERIOD_US=$((1000000 / SERVO_HZ))
# A loop CPU this machine does not have: clamp it (and the helpers') in a copy
# of the board file, so pushstep and cyclictest both run on an existing CPU.
if [ "$LOOP_CPU" -ge "$NCPU" ] || [ "$WORKER_CPU" -ge "$NCPU" ]; then
    "$PY" - "$BOARD_FILE" "$NCPU" >"$RUN/board.yaml" <<'PYEOF'
import re, sys
n = int(sys.argv[2])
def clamp(m):
    v = int(m.group(2))
    v = min(v, n - 1) if m.group(1) == "loop_cpu" else (v if v < n else 0)
    return "%s: %d" % (m.group(1), v)
sys.stdout.write(re.sub(r"\b(loop_cpu|plant_cpu|worker_cpu):\s*(-?\d+)", clamp,
                        open(sys.argv[1]).read()))
PYEOF
    BOARD_FILE=$RUN/board.yaml
    if [ "$LOOP_CPU" -ge "$NCPU" ]; then LOOP_CPU=$((NCPU - 1)); fi
    if [ "$WORKER_CPU" -ge "$NCPU" ]; then WORKER_CPU=0; fi
    log "CPUs clamped to this machine's $NCPU: $BOARD_FILE"
fi

# Wake-up latency depends a lot on how deep an idle CPU sleeps. cyclictest
# and pushstep each hold /dev/cpu_dma_latency at 0 while they run; the bench
# holds it for the whole run too, so no block starts from deep idle states.
DMA_HELD=no
if [ -w /dev/cpu_dma_latency ] && { exec {DMA_FD}>/dev/cpu_dma_latency; } 2>/dev/null; then
    if printf 0 >&"$DMA_FD"; then DMA_HELD=yes; fi
fi

STRESS_CMD=(stress-ng --cpu 0 --quiet) # what `pushstep profile --stress cpu` runs
HAS_STRESS=no
command -v stress-ng >/dev/null && HAS_STRESS=yes

log "RT privileges: $RT; board $BOARD_FILE priority $PRIO loop CPU $LOOP_CPU, period ${PERIOD_US} us;" \
    "$NCPU CPUs; cpu_dma_latency held: $DMA_HELD; stress-ng: $HAS_STRESS"
PS_ARGS=(--board "$BOARD_FILE" --robot "$ROBOT" --hist-us "$HIST_US" --quiet)
[ "$RT" = yes ] && PS_ARGS+=(--require-rt)

# ---- blocks -----------------------------------------------------------------

LAST_TICKS=0
CT_FLAGS=()

# After a pushstep block: mirror what it was granted in cyclictest's flags.
mirror_profile() {
    local json=$1
    read -r LAST_TICKS fifo mlocked pinned prio cpu period < <("$PY" - "$json" <<'EOF'
import json, sys
d = json.load(open(sys.argv[1])); p = d["profile"]
print(d["ticks"], int(p["is_fifo"]), int(p["is_mlocked"]), int(p["is_pinned"]),
      p["priority"], p["loop_cpu"], p["period_us"])
EOF
)
    CT_FLAGS=(-t 1 -i "$period" -h "$HIST_US" -q)
    if [ "$mlocked" = 1 ]; then CT_FLAGS=(-m "${CT_FLAGS[@]}"); fi
    if [ "$fifo" = 1 ]; then CT_FLAGS+=(-p "$prio"); fi
    if [ "$pinned" = 1 ]; then CT_FLAGS+=(-a "$cpu"); fi
    # cyclictest's main thread only sleeps and collects; keep it off the
    # measured CPU as pushstep keeps its logger and plant off it.
    if [ "$pinned" = 1 ] && [ "$NCPU" -gt 1 ] && [ "$WORKER_CPU" != "$cpu" ]; then
        CT_FLAGS+=(--mainaffinity="$WORKER_CPU")
    fi
    PRIO=$prio LOOP_CPU=$cpu PERIOD_US=$period
}

record() { # section tool block path wall_s command...
    local section=$1 tool=$2 block=$3 path=$4 wall=$5
    shift 5
    printf '%s\t%s\t%s\t%s\t%s\t%s\n' "$section" "$tool" "$block" "$path" "$wall" "$*" \
        >>"$RUN/blocks.tsv"
}

now_ns() { date +%s%N; }
since_s() { # start_ns -> seconds since, 3 decimals
    local d=$(($(now_ns) - $1))
    printf '%d.%03d' $((d / 1000000000)) $((d / 1000000 % 1000))
}

run_pushstep() { # section block seconds [extra args]
    local section=$1 block=$2 secs=$3
    shift 3
    local dir=$RUN/$section-pushstep-$block a
    local cmd=("$BIN" profile "${PS_ARGS[@]}" --duration "$secs" --out "$dir" "$@")
    a=$(now_ns)
    "${cmd[@]}" >"$dir.log" 2>&1 || {
        cat "$dir.log" >&2
        die "pushstep profile failed (log above)"
    }
    record "$section" pushstep "$block" "$dir" "$(since_s "$a")" "${cmd[*]}"
    mirror_profile "$dir/profile.json"
    if [ "$block" = 1 ]; then COMMANDS+=("${cmd[*]}"); fi
    log "  $section block $block pushstep: $(grep -E '^# Max' "$dir/wakeup.hist"), $LAST_TICKS ticks"
}

run_cyclictest() { # section block [stress]
    local section=$1 block=$2 stress=${3:-} out a spid=""
    out=$RUN/$section-cyclictest-$block.hist
    # -l: as many cycles as the last pushstep block had ticks, so both tools
    # contribute the same number of samples (the max grows with samples).
    local cmd=(cyclictest "${CT_FLAGS[@]}" -l "$LAST_TICKS")
    a=$(now_ns)
    if [ -n "$stress" ]; then
        "${STRESS_CMD[@]}" --timeout "$((LAST_TICKS / 1000 + 30))" &
        spid=$!
    fi
    "${cmd[@]}" >"$out" 2>"$out.err" || {
        cat "$out.err" >&2
        die "cyclictest failed: ${cmd[*]}"
    }
    if [ -n "$spid" ]; then
        kill "$spid" 2>/dev/null || true
        wait "$spid" 2>/dev/null || true
    fi
    local desc="${cmd[*]}"
    if [ -n "$stress" ]; then desc="${STRESS_CMD[*]} --timeout T & $desc"; fi
    record "$section" cyclictest "$block" "$out" "$(since_s "$a")" "$desc"
    if [ "$block" = 1 ]; then COMMANDS+=("$desc"); fi
    log "  $section block $block cyclictest: $(grep -E '^# Max' "$out")"
}

# Pairs alternate P C, C P, P C, ... (ABBA): a linear drift of the background
# cancels between the tools; the first block is pushstep's, whose
# profile.json sets cyclictest's flags and cycle count.
interleave() { # section pairs seconds [stress]
    local section=$1 pairs=$2 secs=$3 stress=${4:-} p
    local ps_extra=()
    if [ -n "$stress" ]; then ps_extra=(--stress "$stress"); fi
    for ((p = 1; p <= pairs; p++)); do
        if [ $((p % 2)) = 1 ]; then
            run_pushstep "$section" "$p" "$secs" "${ps_extra[@]}"
            if [ "$RT" = yes ]; then run_cyclictest "$section" "$p" "$stress"; fi
        else
            if [ "$RT" = yes ]; then run_cyclictest "$section" "$p" "$stress"; fi
            run_pushstep "$section" "$p" "$secs" "${ps_extra[@]}"
        fi
    done
}

log "latency: $PAIRS pairs of ${BLOCK_S} s (+ pushstep's damping) blocks"
interleave latency "$PAIRS" "$BLOCK_S"
if [ "$HAS_STRESS" = yes ] && [ "$STRESS_PAIRS" -gt 0 ]; then
    log "stress_cpu: $STRESS_PAIRS pairs of ${STRESS_BLOCK_S} s blocks under ${STRESS_CMD[*]}"
    interleave stress_cpu "$STRESS_PAIRS" "$STRESS_BLOCK_S" cpu
fi
if [ "$RT" = no ]; then
    log "no RT privileges: cyclictest cannot run (it requires them); pushstep alone"
fi

# ---- report -----------------------------------------------------------------

wall=$(($(date +%s) - t0))
rt_detail=$RT
[ "$RT" = yes ] && rt_detail="yes (chrt -f 1 works; pushstep run with --require-rt)"
[ "$RT" = no ] && rt_detail="no (chrt -f 1 refused): pushstep under SCHED_OTHER, cyclictest not run"
{
    echo "date=$(date '+%Y-%m-%d %H:%M:%S %z')"
    echo "wall_s=$wall"
    echo "rt=$RT"
    echo "rt_detail=$rt_detail"
    echo "priority=$PRIO"
    echo "cpu=$LOOP_CPU"
    echo "main_cpu=$WORKER_CPU"
    echo "interval_us=$PERIOD_US"
    echo "hist_us=$HIST_US"
    echo "block_s=$BLOCK_S"
    echo "n_pairs=$PAIRS"
    echo "stress_block_s=$STRESS_BLOCK_S"
    echo "stress_n_pairs=$STRESS_PAIRS"
    echo "order=P C C P ... (ABBA)"
    echo "dma_latency_held=$DMA_HELD"
    echo "stress_cmd=${STRESS_CMD[*]}"
    printf 'commands=make bench (bash bench/run.sh; BENCH_PAIRS=%s BENCH_BLOCK_S=%s BENCH_STRESS_PAIRS=%s BENCH_STRESS_BLOCK_S=%s BENCH_HIST_US=%s) ;; ' \
        "$PAIRS" "$BLOCK_S" "$STRESS_PAIRS" "$STRESS_BLOCK_S" "$HIST_US"
    for c in "${COMMANDS[@]}"; do printf '%s ;; ' "$c"; done
    echo
} >"$RUN/conditions.env"
"$PY" bench/analyze.py report "$RUN" "$RESULTS" >"$RUN/report.log" || {
    cat "$RUN/report.log" >&2
    die "analysis failed"
}

# ---- simulation speed (lockstep) -----------------------------------------------
# The whole system (loop, emulated devices, MuJoCo plant) on simulated time, as
# fast as it goes: simulated seconds per wall second, beside real time (1.0).
SIM_S=${BENCH_SIM_S:-20}
log "lockstep: $SIM_S simulated s"
sim_cmd=("$BIN" --lockstep --board "$BOARD_FILE" --robot "$ROBOT" --duration "$SIM_S" --quiet
    --summary "$RUN/lockstep.json")
"${sim_cmd[@]}" >"$RUN/lockstep.log" 2>&1 || {
    cat "$RUN/lockstep.log" >&2
    die "lockstep run failed"
}
"$PY" - "$RUN/lockstep.json" "$RESULTS/sim.json" "$RESULTS/summary.md" "${sim_cmd[*]}" <<'EOF'
import json, sys
d = json.load(open(sys.argv[1]))
speed = d["loop_s"] / d["wall_s"]
out = {"command": sys.argv[4], "loop_s": d["loop_s"], "wall_s": d["wall_s"],
       "sim_s_per_wall_s": speed, "ratio_to_real_time": speed,
       "ticks": d["ticks"], "fall_detected": d["fall_detected"]}
json.dump(out, open(sys.argv[2], "w"), indent=2)
with open(sys.argv[3], "a") as f:
    f.write("\n## Simulation speed (lockstep)\n\n")
    f.write("| figure | value | peer | ratio |\n|---|---|---|---|\n")
    f.write("| simulated s per wall s | %.1f | real time (1.0) | %.1f |\n" % (speed, speed))
    f.write("| loop time / wall time | %.2f s / %.2f s | | |\n\n" % (d["loop_s"], d["wall_s"]))
    f.write("    %s\n" % sys.argv[4])
EOF

# ---- flight recorder -------------------------------------------------------
# Tick time with and without recording in this run, bytes per second,
# records lost (bench/recorder.sh: recorder.json and its summary section).
BUILD=$BUILD bash bench/recorder.sh

if command -v gnuplot >/dev/null; then
    for sec in latency stress_cpu; do
        [ -f "$RESULTS/${sec}_pushstep.dat" ] || continue
        plots=("\"$RESULTS/${sec}_pushstep.dat\" using (\$1+0.5):(\$2>0?\$2:0.5) with steps lw 1.5 title \"pushstep\"")
        [ -f "$RESULTS/${sec}_cyclictest.dat" ] &&
            plots+=("\"$RESULTS/${sec}_cyclictest.dat\" using (\$1+0.5):(\$2>0?\$2:0.5) with steps lw 1.5 title \"cyclictest\"")
        xmax=$(awk '!/^#/ && $2 > 0 { l = $1 } END { print l + 2 }' "$RESULTS/${sec}"_*.dat)
        gnuplot <<EOF
set terminal pngcairo size 1000,560 noenhanced font ",10"
set output "$RESULTS/$sec.png"
set title "wake-up latency, merged blocks ($sec): pushstep beside cyclictest"
set xlabel "latency (us, 1-us buckets)"
set ylabel "samples"
set logscale xy
set xrange [1:$xmax]
set yrange [0.8:*]
set grid
plot $(IFS=,; echo "${plots[*]}")
EOF
    done
    first=$RUN/latency-pushstep-1
    if [ -f "$first/stages.png" ]; then cp "$first/stages.png" "$RESULTS/stages.png"; fi
    if [ -f "$first/wakeup.png" ]; then cp "$first/wakeup.png" "$RESULTS/wakeup_block1.png"; fi
fi
rm -f "$RESULTS"/*.dat

wall=$(($(date +%s) - t0))
sed -i "s/bench wall time [0-9?]* s/bench wall time $wall s/" "$RESULTS/summary.md"
cat "$RESULTS/summary.md"
log "done in $wall s: $RESULTS/ (raw blocks in $RUN/)"

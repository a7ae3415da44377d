#!/usr/bin/env bash
# The flight recorder's cost (part of `make bench`, also runnable alone):
# `pushstep profile` blocks without and with recording, alternated in the
# same run (off on on off ... : ABBA, so a drift of the background cancels),
# each recording block with the defaults (continuous zstd file and a flight
# folder: --record and --flight, 5 s before and 2 s after a trigger, ring
# pre + post + 1 s). From each block's profile.json: the tick (read to
# write) p50 / p99 / p99.9 / max, the tap (the recorder's copy into its
# ring, after the tick), ticks and loop time, bytes written, records lost.
#
# Writes bench/results/recorder.json and appends a section to
# bench/results/summary.md (when it exists). Knobs: BENCH_REC_PAIRS (2),
# BENCH_REC_BLOCK_S (15), BENCH_BOARD (sim), BENCH_ROBOT (robots/ps1.yaml),
# BUILD (build).
set -euo pipefail
cd "$(dirname "$0")/.."

PAIRS=${BENCH_REC_PAIRS:-2}
BLOCK_S=${BENCH_REC_BLOCK_S:-15}
BOARD=${BENCH_BOARD:-sim}
ROBOT=${BENCH_ROBOT:-robots/ps1.yaml}
BUILD=${BUILD:-build}
BIN=$BUILD/pushstep
RESULTS=bench/results
PY=/usr/bin/python3
[ -x "$PY" ] || PY=python3

die() {
    echo "bench-recorder: $*" >&2
    exit 1
}
[ -x "$BIN" ] || die "$BIN missing: run make"
"$BIN" --help | grep -q -- "--record FILE.mcap" || die "$BIN has no flight recorder"

RUN=$BUILD/bench/recorder-$(date +%Y%m%d-%H%M%S)
mkdir -p "$RUN" "$RESULTS"
ARGS=(profile --board "$BOARD" --robot "$ROBOT" --duration "$BLOCK_S" --quiet)
if chrt -f 1 true 2>/dev/null; then ARGS+=(--require-rt); fi
: >"$RUN/blocks.tsv"
LOAD0=$(cut -d' ' -f1-3 /proc/loadavg)

block() { # mode index
    local mode=$1 i=$2 dir=$RUN/$1-$2 extra=()
    mkdir -p "$dir"
    if [ "$mode" = on ]; then
        mkdir -p "$dir/flight"
        extra=(--record "$dir/run.mcap" --flight "$dir/flight")
    fi
    "$BIN" "${ARGS[@]}" --out "$dir" "${extra[@]}" >"$dir.log" 2>&1 || {
        cat "$dir.log" >&2
        die "pushstep profile failed (log above)"
    }
    printf '%s\t%s\t%s\t%s\n' "$mode" "$i" "$dir/profile.json" \
        "$BIN ${ARGS[*]} --out $dir ${extra[*]}" >>"$RUN/blocks.tsv"
    echo "bench-recorder: block $i recording $mode: $(grep -E '^  tick ' "$dir.log" | head -1)"
}

for ((p = 1; p <= PAIRS; p++)); do
    if [ $((p % 2)) = 1 ]; then
        block off "$p"
        block on "$p"
    else
        block on "$p"
        block off "$p"
    fi
done

LOAD1=$(cut -d' ' -f1-3 /proc/loadavg)
"$PY" - "$RUN/blocks.tsv" "$RESULTS/recorder.json" "$RESULTS/summary.md" "$PAIRS" "$BLOCK_S" \
    "$LOAD0" "$LOAD1" <<'EOF'
import json, os, sys
blocks_path, out_path, md_path, pairs, block_s, load0, load1 = sys.argv[1:8]
blocks = []
for line in open(blocks_path):
    mode, idx, path, cmd = line.rstrip("\n").split("\t")
    p = json.load(open(path))
    rec = p.get("recorder") or {}
    cont = rec.get("continuous") or {}
    lat = p["latency"]
    blocks.append({
        "mode": mode, "block": int(idx), "command": cmd,
        "ticks": p["ticks"], "loop_s": p["loop_s"], "overruns": p["overruns"],
        "tick": {k: lat["tick"][k] for k in ("n", "p50_us", "p99_us", "p999_us", "max_us")},
        "tap": {k: lat["tap"][k] for k in ("n", "p50_us", "p99_us", "p999_us", "max_us")},
        "mallocs_after_init": p["after_init"]["mallocs"],
        "page_faults_after_init": p["after_init"]["page_faults"],
        "bytes_written": rec.get("bytes_written", 0),
        "records_pushed": rec.get("records_pushed", 0),
        "records_lost": rec.get("records_lost", 0),
        "records_in_file": cont.get("records", 0),
        "ring_slots": rec.get("ring_slots", 0),
        "rt": p["rt"],
    })
def mean(xs):
    return sum(xs) / len(xs) if xs else None
def agg(mode, stage, key):
    return mean([b[stage][key] for b in blocks if b["mode"] == mode])
on = [b for b in blocks if b["mode"] == "on"]
res = {
    "what": "pushstep profile blocks without and with the flight recorder (--record FILE "
            "--flight DIR, defaults), alternated off/on, on/off (ABBA) in one run",
    "pairs": int(pairs), "block_s": float(block_s),
    "loadavg_start": load0, "loadavg_end": load1,
    "overruns_off": sum(b["overruns"] for b in blocks if b["mode"] == "off"),
    "overruns_on": sum(b["overruns"] for b in on),
    "tick_off": {k: agg("off", "tick", k) for k in ("p50_us", "p99_us", "p999_us", "max_us")},
    "tick_on": {k: agg("on", "tick", k) for k in ("p50_us", "p99_us", "p999_us", "max_us")},
    "tap_on": {k: agg("on", "tap", k) for k in ("p50_us", "p99_us", "p999_us", "max_us")},
    "bytes_per_s": sum(b["bytes_written"] for b in on) / sum(b["loop_s"] for b in on),
    "records_per_s": sum(b["records_pushed"] for b in on) / sum(b["loop_s"] for b in on),
    "records_lost": sum(b["records_lost"] for b in on),
    "records_pushed": sum(b["records_pushed"] for b in on),
    "mallocs_after_init_on": sum(b["mallocs_after_init"] for b in on),
    "blocks": blocks,
}
res["tick_ratio_on_off"] = {k: (res["tick_on"][k] / res["tick_off"][k]) if res["tick_off"][k]
                            else None for k in res["tick_on"]}
json.dump(res, open(out_path, "w"), indent=2)
lines = ["", "## Flight recorder cost", "",
         "%s pairs of %s s `pushstep profile` blocks, recording off and on alternated (ABBA) in "
         "one run; recording = `--record FILE --flight DIR` at the defaults (zstd chunks, "
         "ring of %s records). Means over the blocks of each block's percentile." % (
             pairs, block_s, on[0]["ring_slots"] if on else "?"),
         "Load average (1, 5, 15 min) at the start %s, at the end %s (other work on the "
         "machine: the maxima are its stalls as much as the loop's)." % (load0, load1), "",
         "| figure | off | on | on / off |", "|---|---|---|---|"]
for k, name in (("p50_us", "tick p50"), ("p99_us", "tick p99"), ("p999_us", "tick p99.9"),
                ("max_us", "tick max")):
    off_v, on_v = res["tick_off"][k], res["tick_on"][k]
    lines.append("| %s (read to write) | %.1f us | %.1f us | %.2f |" % (
        name, off_v, on_v, on_v / off_v if off_v else float("nan")))
for k, name in (("p50_us", "p50"), ("p99_us", "p99"), ("p999_us", "p99.9"), ("max_us", "max")):
    lines.append("| tap %s (the recorder's copy, after the tick) | - | %.1f us | |" % (
        name, res["tap_on"][k]))
lines += ["| bytes written per second of loop time | - | %.0f B/s | |" % res["bytes_per_s"],
          "| records per second | - | %.0f | |" % res["records_per_s"],
          "| records lost (ring overwritten before written, or I/O) | - | %d of %d | |" % (
              res["records_lost"], res["records_pushed"]),
          "| mallocs on the loop thread after init | - | %d | |" % res["mallocs_after_init_on"],
          "| overruns (all blocks of the mode) | %d | %d | |" % (res["overruns_off"],
                                                          res["overruns_on"]),
          "", "    " + (on[0]["command"] if on else ""), ""]
if os.path.exists(md_path):
    with open(md_path, "a") as f:
        f.write("\n".join(lines) + "\n")
print("\n".join(lines))
EOF
echo "bench-recorder: $RESULTS/recorder.json (blocks in $RUN)"

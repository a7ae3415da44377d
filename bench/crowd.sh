#!/bin/bash
# The simulated crowd's cost (make bench): for 0, 20, 50, 100 and 200 agents
# pressed around the robot, the plant's speed (physics + crowd, simulated s
# per s) beside the bare mj_step of the same generated model from the same
# states, interleaved step by step, in thread CPU time (one core's work) and
# wall time; MuJoCo's stage timers (a separate pass); the crowd's own work as
# a share of mj_step. Each size runs REPEAT times so the spread on a shared machine shows.
# Writes bench/results/crowd.json and bench/results/crowd.md.
# Env: BUILD (build), CROWD_BENCH_S (simulated s per run, 2),
#      CROWD_BENCH_NS ("0 20 50 100 200"), CROWD_BENCH_DTS ("0.001 0": 1 ms is
#      the crowd scenes' step, 0 the robot model's own 0.5 ms),
#      CROWD_BENCH_REPEAT (3), CROWD_BENCH_CPU (0).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
BIN="$BUILD/crowd_bench"
[ -x "$BIN" ] || { echo "crowd.sh: $BIN missing: make $BIN" >&2; exit 1; }
S=${CROWD_BENCH_S:-2}
NS=${CROWD_BENCH_NS:-"0 20 50 100 200"}
DTS=${CROWD_BENCH_DTS:-"0.001 0"}
REPEAT=${CROWD_BENCH_REPEAT:-3}
OUT=bench/results
mkdir -p "$OUT"
tmp=$(mktemp)
trap 'rm -f "$tmp"' EXIT
for rep in $(seq 1 "$REPEAT"); do
    for dt in $DTS; do
        for n in $NS; do
            label=$dt; [ "$dt" = 0 ] && label=model
            echo "crowd bench: run $rep/$REPEAT, $n agents, timestep $label, $S s" >&2
            echo "load $(cut -d' ' -f1 /proc/loadavg)" >>"$tmp"
            CROWD_BENCH_DT=$dt taskset -c "${CROWD_BENCH_CPU:-0}" "$BIN" "$n" "$S" >>"$tmp"
        done
    done
done
/usr/bin/python3 - "$tmp" "$OUT" "$S" <<'PY'
import json, os, platform, sys, time
rows, load = [], None
for line in open(sys.argv[1]):
    if line.startswith("load "):
        load = float(line.split()[1])
    elif line.strip():
        r = json.loads(line)
        r["load_avg_1m_before"] = load
        rows.append(r)
out, sim_s = sys.argv[2], float(sys.argv[3])
loads = [r["load_avg_1m_before"] for r in rows]
meta = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "host": platform.node(),
        "cpus": os.cpu_count(), "load_avg_1m_min": min(loads), "load_avg_1m_max": max(loads),
        "command": "make bench (bench/crowd.sh: build/crowd_bench N S, pinned to one CPU)"}
json.dump({"meta": meta, "runs": rows}, open(os.path.join(out, "crowd.json"), "w"), indent=1)
groups = {}
for r in rows:
    groups.setdefault((r["timestep_s"], r["agents"]), []).append(r)
def span(vals, fmt):
    lo, hi = min(vals), max(vals)
    return (fmt % lo) if fmt % lo == fmt % hi else (fmt + "-" + fmt) % (lo, hi)
with open(os.path.join(out, "crowd.md"), "w") as f:
    f.write("# The simulated crowd's cost\n\n")
    f.write("`make bench` (bench/crowd.sh), %s, %d CPUs, 1-min load average %.1f-%.1f during the runs.\n"
            % (meta["date"], meta["cpus"], meta["load_avg_1m_min"], meta["load_avg_1m_max"]))
    f.write("Agents walk toward the robot (limp in its harness) at 1 m/s in a walled pen at 4 persons/m^2,\n"
            "social repulsion 100 N (a crush: they press into each other and the robot); after 1 s of\n"
            "settling, %g simulated s in which each plant step (MuJoCo step + the crowd's forces, decisions\n"
            "and measurements) follows the bare `mj_step` of the same model from a copy of the same state.\n"
            "Speed = simulated s per s of one core's CPU time (thread CPU time; wall-clock in the JSON),\n"
            "the range over %d runs; plant / bare = CPU time per plant step over per bare step (what\n"
            "the crowd and the plant's bookkeeping add); crowd share = the crowd's own time / mj_step\n"
            "time, both wall clock inside the plant.\n\n"
            % (sim_s, len(rows) // max(1, len(groups))))
    f.write("| timestep | agents | nv | contacts | rows | plant speed (CPU) | bare mj_step speed (CPU) | plant / bare | crowd share of mj_step |\n|---|---|---|---|---|---|---|---|---|\n")
    for (dt, n), rs in sorted(groups.items(), key=lambda kv: (-kv[0][0], kv[0][1])):
        f.write("| %g ms | %d | %d | %.0f | %.0f | %s x | %s x | %s | %s %% |\n" % (
            dt * 1e3, n, rs[0]["nv"], rs[0]["ncon_mean"], rs[0]["nefc_mean"],
            span([r["plant_rtf_cpu"] for r in rs], "%.2f"), span([r["bare_rtf_cpu"] for r in rs], "%.2f"),
            span([r["bare_us_per_step_cpu"] and r["plant_us_per_step_cpu"] / r["bare_us_per_step_cpu"] for r in rs], "%.2f"),
            span([100 * r["crowd_share_of_mj_step"] for r in rs], "%.1f")))
    f.write("\nMuJoCo's stage timers (us per bare step, CPU time, first run; a separate pass of 500 bare\n"
            "steps after the timed ones: the timers read the thread CPU clock, a system call, which\n"
            "the timed steps are spared):\n\n")
    keys = list(rows[0]["mujoco_stage_us_cpu"].keys())
    f.write("| timestep | agents | " + " | ".join(keys) + " |\n|---|---|" + "---|" * len(keys) + "\n")
    for (dt, n), rs in sorted(groups.items(), key=lambda kv: (-kv[0][0], kv[0][1])):
        st = rs[0]["mujoco_stage_us_cpu"]
        f.write("| %g ms | %d | " % (dt * 1e3, n) + " | ".join("%.0f" % st[k] for k in keys) + " |\n")
print(open(os.path.join(out, "crowd.md")).read())
PY

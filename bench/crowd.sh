#!/bin/bash
# The simulated crowd's cost (make bench): for 0, 20, 50, 100 and 200 agents
# pressed around the robot, the plant's speed (physics + crowd, simulated s
# per wall s) beside the bare mj_step of the same generated model from the
# same pressed state, and the crowd's own work as a share of mj_step.
# Writes bench/results/crowd.json and bench/results/crowd.md.
# Env: BUILD (build), CROWD_BENCH_S (simulated s per size, 2),
#      CROWD_BENCH_NS ("0 20 50 100 200"), CROWD_BENCH_DTS ("0 0.001": 0 is
#      the robot model's own step).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
BIN="$BUILD/crowd_bench"
[ -x "$BIN" ] || { echo "crowd.sh: $BIN missing: make $BIN" >&2; exit 1; }
S=${CROWD_BENCH_S:-2}
NS=${CROWD_BENCH_NS:-"0 20 50 100 200"}
DTS=${CROWD_BENCH_DTS:-"0 0.001"}
OUT=bench/results
mkdir -p "$OUT"
tmp=$(mktemp)
trap 'rm -f "$tmp"' EXIT
for dt in $DTS; do
    for n in $NS; do
        label=$dt; [ "$dt" = 0 ] && label=model
        echo "crowd bench: $n agents, timestep $label, $S s" >&2
        CROWD_BENCH_DT=$dt taskset -c "${CROWD_BENCH_CPU:-0}" "$BIN" "$n" "$S" >>"$tmp"
    done
done
/usr/bin/python3 - "$tmp" "$OUT" <<'PY'
import json, os, platform, sys, time
rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
out = sys.argv[2]
meta = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "host": platform.node(),
        "cpus": os.cpu_count(), "load_avg_1m": os.getloadavg()[0],
        "command": "make bench (bench/crowd.sh: build/crowd_bench N S on one CPU)"}
json.dump({"meta": meta, "runs": rows}, open(os.path.join(out, "crowd.json"), "w"), indent=1)
with open(os.path.join(out, "crowd.md"), "w") as f:
    f.write("# The simulated crowd's cost\n\n")
    f.write("`make bench` (bench/crowd.sh), %s, %d CPUs, 1-min load average %.2f when it ended.\n" % (meta["date"], meta["cpus"], meta["load_avg_1m"]))
    f.write("Agents walk toward the robot (limp in its harness) at 1 m/s in a walled pen at 4 persons/m^2, social\n")
    f.write("repulsion 100 N (a crush: they press into each other and the robot); after 1 s of\n")
    f.write("settling, S simulated seconds of the plant (MuJoCo step + the crowd's forces, decisions and\n")
    f.write("measurements), then the bare `mj_step` of the same generated model from the same state.\n")
    f.write("Speed = simulated s per wall s (RTF); crowd share = the crowd's own time / mj_step time, same run.\n\n")
    f.write("| timestep | agents | nv | contacts | plant RTF | bare mj_step RTF | plant us/step | crowd us/step | crowd share of mj_step |\n|---|---|---|---|---|---|---|---|---|\n")
    for r in rows:
        f.write("| %g ms | %d | %d | %.1f | %.2f | %.2f | %.0f | %.1f | %.1f %% |\n" % (r["timestep_s"] * 1e3, r["agents"], r["nv"], r["ncon_mean"], r["plant_rtf"], r["bare_mujoco_rtf"], r["plant_us_per_step"], r["crowd_us_per_step"], 100 * r["crowd_share_of_mj_step"]))
print(open(os.path.join(out, "crowd.md")).read())
PY

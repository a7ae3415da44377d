#!/usr/bin/env bash
# `make bench-hw` (and the last part of `make bench`): the real drivers'
# figures measured in the test VM of `make test-hw` (docs/testing-hw.md):
# e-stop edge to the first limp command over BENCH_HW_TRIALS trials (10),
# reaction from the newest reply in to the commands out, commands per second
# per bus and late commands over a BENCH_HW_LOAD_S (20) second run. Writes
# bench/results/hw.json and hw.md (the summary it prints). The VM is qemu without KVM on this host: its figures are the
# VM's, several times slower than a board.
set -euo pipefail
cd "$(dirname "$0")/.."
N=${BENCH_HW_TRIALS:-10}; LOAD_S=${BENCH_HW_LOAD_S:-20}
W=${QEMU_WORK:-build/qemu}; OUT=build/hw-bench; RESULTS=bench/results
PY=/usr/bin/python3; [ -x "$PY" ] || PY=python3
mkdir -p "$W" "$RESULTS"
if ! bash tools/qemu/ensure.sh "$W" > "$W.setup.log" 2>&1; then
    echo "bench-hw: skipped: the qemu VM could not be set up: $(tail -1 "$W.setup.log")"
    exit 0
fi
rm -rf "$OUT"; mkdir -p "$OUT"
t0=$(date +%s)
QEMU_WORK=$W VM_TIMEOUT=$((N * 12 + LOAD_S + 120)) bash tools/qemu/run-in-vm.sh \
    -s tools/qemu/guest-modules.sh -- sh bench/hw-in-vm.sh "$N" "$LOAD_S" "$OUT" > "$OUT/vm.log" 2>&1 || true
"$PY" - "$OUT" "$N" "$LOAD_S" "$RESULTS/hw.json" "$(($(date +%s) - t0))" <<'PYEOF'
import json, math, os, sys
out, n, load_s, dest, wall = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], int(sys.argv[5])
def load(p):
    try:
        return json.load(open(p))
    except Exception:
        return None
def pct(v, p):
    if not v: return None
    v = sorted(v); k = max(0, math.ceil(p / 100 * len(v)) - 1)
    return round(v[min(k, len(v) - 1)], 3)
est = []
for i in range(n):
    j = load(os.path.join(out, "estop-%d.json" % i))
    if j and j.get("estop_reaction_ms", -1) >= 0:
        est.append(j["estop_reaction_ms"])
emu = load(os.path.join(out, "load-emu.json")) or {}
summ = load(os.path.join(out, "load-summary.json")) or {}
lat = summ.get("latency", {})
res = {
    "where": "qemu TCG VM (no KVM), 2 vCPUs; robot tests/data/robots/ps1-mixed-vm.yaml at 100 Hz on 4 vxcan buses",
    "command": "make bench-hw (bench/hw.sh -> bench/hw-in-vm.sh)",
    "wall_s": wall,
    "estop_to_limp_ms": {"n": len(est), "of_trials": n, "min": pct(est, 0), "p50": pct(est, 50),
                         "p90": pct(est, 90), "max": pct(est, 100)},
    "loop_reaction_us": lat.get("reaction"),
    "loop_tick_us": lat.get("tick"),
    "emulator_reply_to_next_command_us": emu.get("reaction_us"),
    "commands_per_s_per_bus": emu.get("commands_per_s"),
    "late_commands": emu.get("late_commands"),
    "commands": emu.get("commands"),
    "load_run_s": load_s,
    "overruns": summ.get("overruns"),
    "final_state": summ.get("final_state"),
    "buses": [{k: b.get(k) for k in ("name", "planned_peak_tick_load", "observed_load", "late_frames")}
              for b in summ.get("buses", [])],
}
json.dump(res, open(dest, "w"), indent=1)
e = res["estop_to_limp_ms"]; r = res["loop_reaction_us"] or {}
import time
lines = ["## Real drivers in the VM (bench/results/hw.json)", "",
         "Measured %s with `make bench-hw` (%d e-stop trials, %d s load run)." % (time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), n, load_s), "",
         "qemu TCG, no KVM: a VM several times slower than a board; 100 Hz servo.", "",
         "- e-stop edge to first limp command: n=%s of %s trials, min %s, p50 %s, p90 %s, max %s ms"
         % (e["n"], n, e["min"], e["p50"], e["p90"], e["max"]),
         "- loop reaction (newest reply in to commands out): p50 %s, p99 %s, p99.9 %s, max %s us"
         % (r.get("p50_us"), r.get("p99_us"), r.get("p999_us"), r.get("max_us")),
         "- commands per second per bus: %s; late commands: %s of %s; overruns: %s in %s s"
         % (res["commands_per_s_per_bus"], res["late_commands"], res["commands"], res["overruns"], load_s)]
print("\n".join(lines))
open(os.path.join(os.path.dirname(dest), "hw.md"), "w").write("\n".join(lines) + "\n")
PYEOF

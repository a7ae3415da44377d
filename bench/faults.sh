#!/usr/bin/env bash
# The fault-injection matrix's figures (part of `make bench`, also runnable
# alone): runs the matrix (tests/test_e2e_faults.c, docs/safety.md "Fault
# matrix") and records how many faults were injected and the share that
# ended in the expected state (it must be all), with each row's ticks from
# the injection to the state it reached.
#
# Writes bench/results/faults.json and faults.md, and appends the table to
# bench/results/summary.md when it exists. Knob: BUILD (build).
set -euo pipefail
cd "$(dirname "$0")/.."

BUILD=${BUILD:-build}
BIN=$BUILD/tests/test_e2e_faults
RESULTS=bench/results
PY=/usr/bin/python3
[ -x "$PY" ] || PY=python3
[ -x "$BIN" ] || { echo "bench-faults: $BIN missing: make $BIN" >&2; exit 1; }
mkdir -p "$RESULTS" "$BUILD/bench"
RAW=$BUILD/bench/faults.json
LOG=$BUILD/bench/faults.log
t0=$(date +%s.%N)
rc=0
PUSHSTEP_FAULTS_JSON=$RAW "$BIN" >"$LOG" 2>&1 || rc=$?
t1=$(date +%s.%N)
"$PY" - "$RAW" "$RESULTS/faults.json" "$RESULTS/faults.md" "$RESULTS/summary.md" "$t0" "$t1" \
    "$rc" "PUSHSTEP_FAULTS_JSON=$RAW $BIN" <<'PYEOF'
import json, os, sys, time
raw, out_json, out_md, summary, t0, t1, rc, cmd = sys.argv[1:]
d = json.load(open(raw))
d["command"] = cmd
d["exit_status"] = int(rc)
d["wall_s"] = round(float(t1) - float(t0), 2)
d["date"] = time.strftime("%Y-%m-%d %H:%M:%S +0000", time.gmtime(float(t0)))
json.dump(d, open(out_json, "w"), indent=2)
n, ok = d["faults_injected"], d["ended_as_expected"]
lines = ["", "## Fault-injection matrix", "",
         "%d faults injected, %d ended in the expected state (%.0f %%); %.1f s wall; "
         "docs/safety.md has each row's hazard and stated outcome." % (
             n, ok, 100.0 * ok / n if n else 0.0, d["wall_s"]), "",
         "| fault | expected | as expected | ticks to the state |", "|---|---|---|---|"]
for r in d["rows"]:
    t = r["ticks_to_state"]
    lines.append("| %s | %s | %s | %s |" % (r["fault"], r["expected"],
                                           "yes" if r["as_expected"] else "**no**",
                                           t if t >= 0 else "(held throughout)"))
lines += ["", "    " + cmd, ""]
with open(out_md, "w") as f:
    f.write("# Fault-injection matrix\n\nDate: %s.\n" % d["date"] + "\n".join(lines) + "\n")
if os.path.exists(summary):
    with open(summary, "a") as f:
        f.write("\n".join(lines) + "\n")
print("\n".join(lines))
PYEOF
echo "bench-faults: $RESULTS/faults.json (log: $LOG)"
exit "$rc"

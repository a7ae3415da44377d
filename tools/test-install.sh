#!/usr/bin/env bash
# `make install` into a temporary DESTDIR, then the installed binary run from
# a folder with no data in it and without $PUSHSTEP_DATA_DIR: it must find
# its boards, robots, scenarios, model (and trained policies, when
# policy/weights/ exists) in PREFIX/share/pushstep. Prints
# cmocka-style lines for tools/run-tests.sh. Takes about 3 s.
set -uo pipefail
BIN=${PUSHSTEP_BIN:-build/pushstep}
BUILD=$(dirname "$BIN")
T=$(mktemp -d /tmp/ps-install.XXXXXX); trap 'rm -rf "$T"' EXIT
pass=0; fail=0
ok()  { echo "[       OK ] $1"; pass=$((pass + 1)); }
bad() { echo "[  FAILED  ] $1: $2"; fail=$((fail + 1)); }
check() { local name=$1; shift; if out=$("$@" 2>&1); then ok "$name"; else bad "$name" "$(tail -3 <<<"$out")"; fi; }

echo "[==========] install"
check install_runs make --no-print-directory -s install BUILD="$BUILD" PREFIX=/usr DESTDIR="$T/root"
R=$T/root/usr
missing=""
for f in bin/pushstep share/pushstep/boards/sim.yaml share/pushstep/boards/rpi5.yaml \
         share/pushstep/robots/ps1.yaml share/pushstep/scenarios/stand.yaml \
         share/pushstep/sim/models/ps1.xml share/pushstep/tools/plot-profile.sh \
         lib/systemd/system/pushstep@.service lib/udev/rules.d/60-pushstep.rules \
         share/doc/pushstep/deploy.md; do
    [ -e "$R/$f" ] || missing+=" $f"
done
if [ -z "$missing" ]; then ok install_tree_complete; else bad install_tree_complete "missing:$missing"; fi
for d in boards robots scenarios; do
    n_src=$(find "$d" -maxdepth 1 -name '*.yaml' | wc -l); n_dst=$(find "$R/share/pushstep/$d" -name '*.yaml' | wc -l)
    if [ "$n_src" -eq "$n_dst" ]; then ok "install_all_$d"; else bad "install_all_$d" "$n_dst of $n_src files"; fi
done
# Trained policy files (make train writes policy/weights/; none shipped yet)
if [ -d policy/weights ]; then
    n_src=$(find policy/weights -name '*.safetensors' | wc -l)
    n_dst=$(find "$R/share/pushstep/policy/weights" -name '*.safetensors' 2>/dev/null | wc -l)
    if [ "$n_src" -eq "$n_dst" ]; then ok install_all_policy_weights
    else bad install_all_policy_weights "$n_dst of $n_src files"; fi
fi
unit=$R/lib/systemd/system/pushstep@.service
if grep -q '^ExecStart=/usr/bin/pushstep --board %i' "$unit" && grep -q '^User=pushstep' "$unit" &&
   grep -q '^LimitRTPRIO=95' "$unit" && grep -q '^LimitMEMLOCK=infinity' "$unit" &&
   grep -q '^CapabilityBoundingSet=$' "$unit" && ! grep -q '@BINDIR@\|^RestrictRealtime=yes' "$unit"; then
    ok unit_unprivileged_with_rt_limits
else
    bad unit_unprivileged_with_rt_limits "$(grep -n 'Exec\|User\|Limit\|Capab' "$unit")"
fi
# systemd's own reading of the unit (systemd-analyze, from systemd): installed
# without DESTDIR so that its paths exist, instantiated for a board. Any
# complaint (an unknown key, a bad value, a missing binary) fails it.
if command -v systemd-analyze >/dev/null; then
    make --no-print-directory -s install BUILD="$BUILD" PREFIX="$T/live/usr" >/dev/null 2>&1
    cp "$T/live/usr/lib/systemd/system/pushstep@.service" "$T/live/pushstep@rpi5.service"
    out=$(systemd-analyze verify "$T/live/pushstep@rpi5.service" 2>&1)
    if [ -z "$out" ]; then ok unit_verified_by_systemd; else bad unit_verified_by_systemd "$out"; fi
fi
# The installed binary from an empty folder: data from PREFIX/share/pushstep.
mkdir -p "$T/empty"
cd "$T/empty" || exit 1
check installed_help env -u PUSHSTEP_DATA_DIR "$R/bin/pushstep" --help
if out=$(env -u PUSHSTEP_DATA_DIR "$R/bin/pushstep" --lockstep --duration 0.3 --quiet 2>&1) &&
   grep -q "share/pushstep/boards/sim.yaml" <<<"$out"; then
    ok installed_finds_share_data
else
    bad installed_finds_share_data "$(tail -3 <<<"$out")"
fi
out=$(env -u PUSHSTEP_DATA_DIR "$R/bin/pushstep" doctor --board rpi5 --root "$T/empty" 2>&1); rc=$?
if [ "$rc" -eq 1 ] && grep -q "share/pushstep/boards/rpi5.yaml" <<<"$out"; then
    ok installed_doctor_runs
else
    bad installed_doctor_runs "rc $rc: $(tail -3 <<<"$out")"
fi
# Nothing found anywhere: a clear error, not a crash.
mv "$R/share/pushstep" "$R/share/elsewhere"
out=$(env -u PUSHSTEP_DATA_DIR "$R/bin/pushstep" --lockstep --duration 0.1 2>&1); rc=$?
if [ "$rc" -eq 2 ] && grep -q "boards/sim.yaml" <<<"$out"; then ok installed_without_data_refused
else bad installed_without_data_refused "rc $rc: $(tail -2 <<<"$out")"; fi
echo "[==========] $((pass + fail)) test(s) run."
echo "[  PASSED  ] $pass test(s)."
[ "$fail" -eq 0 ] || { echo "[  FAILED  ] $fail test(s), listed below:"; exit 1; }

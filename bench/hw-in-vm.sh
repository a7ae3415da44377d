#!/bin/sh
# Runs inside the test VM (bench/hw.sh boots it): the real drivers' figures.
#   - N e-stop trials: the runtime in ACTIVE on tests/data/boards/vm-vxcan.yaml,
#     `pushstep emulate` presses gpio-mockup's e-stop line and times the first
#     limp command (one sample per trial: the runtime ends in ESTOP);
#   - one load run of LOAD_S seconds: commands per second per bus at the
#     planned load, late commands, the loop's reaction stage (newest reply in
#     to commands out) and the emulator's reply-to-next-command time.
# Writes $OUT/estop-N.json, $OUT/load-emu.json, $OUT/load-summary.json.
set -u
N=${1:-10}; LOAD_S=${2:-20}; OUT=${3:-build/hw-bench}
B=tests/data/boards/vm-vxcan.yaml; R=tests/data/robots/ps1-mixed-vm.yaml
I=vxcan1,vxcan3,vxcan5,vxcan7; G=/sys/kernel/debug/gpio-mockup/gpiochip0
BIN=build/pushstep
mkdir -p "$OUT"
sh tools/qemu/in-vm.sh
i=0
while [ "$i" -lt "$N" ]; do
    $BIN emulate --board $B --robot $R --ifaces $I --duration 5 --heartbeat-file $G/1 \
        --estop-file $G/0 --press-estop-at 3.2 --report "$OUT/estop-$i.json" > "$OUT/estop-$i.emu" 2>&1 &
    sleep 0.3
    $BIN --board $B --robot $R --start-after 1 --duration 3.6 --quiet > "$OUT/estop-$i.out" 2>&1
    wait
    i=$((i + 1))
done
$BIN emulate --board $B --robot $R --ifaces $I --duration $((LOAD_S + 5)) --heartbeat-file $G/1 \
    --estop-file $G/0 --report "$OUT/load-emu.json" > "$OUT/load.emu" 2>&1 &
sleep 0.3
$BIN --board $B --robot $R --start-after 1 --duration "$LOAD_S" --quiet \
    --summary "$OUT/load-summary.json" > "$OUT/load.out" 2>&1
wait
echo "hw-in-vm: done"

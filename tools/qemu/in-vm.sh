#!/bin/sh
# Runs inside the test VM (chrooted into the host's root, repository as the
# current directory): makes the CAN interfaces the hardware tests expect and
# runs each test binary given. Interfaces: vcan0, vcan1 (FD capable, mtu 72),
# vcan2 (classical, mtu 16) and the pair vxcan0 <-> vxcan1. A binary that
# ends without cmocka's summary is reported as one failed test. Exit: 0 when
# every binary exited 0.
set -u
ip link add dev vcan0 type vcan && ip link set vcan0 up
ip link add dev vcan1 type vcan && ip link set vcan1 up
ip link add dev vcan2 type vcan && ip link set vcan2 mtu 16 && ip link set vcan2 up
ip link add vxcan0 type vxcan peer name vxcan1 && ip link set vxcan0 up && ip link set vxcan1 up
status=0
for t in "$@"; do
    echo "=== $(basename "$t") (in the VM)"
    "$t" > /tmp/hw.out 2>&1; rc=$?
    cat /tmp/hw.out
    if [ "$rc" -ne 0 ]; then
        status=1
        grep -q '^\[  PASSED  \]' /tmp/hw.out ||
            printf '[  FAILED  ] 1 test(s), listed below:\n[  FAILED  ] %s (ended with rc %s)\n' "$(basename "$t")" "$rc"
    fi
done
exit $status

#!/bin/sh
# Runs inside the test VM (chrooted into the host's root, repository as the
# current directory): makes the CAN interfaces the hardware tests expect and
# runs each test binary given. Interfaces: vcan0, vcan1 (FD capable, mtu 72),
# vcan2 (classical, mtu 16) and the pairs vxcan0 <-> vxcan1, vxcan2 <-> vxcan3,
# vxcan4 <-> vxcan5, vxcan6 <-> vxcan7 (tests/data/boards/vm-vxcan.yaml), and
# udevd around the camera tests. A binary that
# ends without cmocka's summary is reported as one failed test. Exit: 0 when
# every binary exited 0.
set -u
ip link add dev vcan0 type vcan && ip link set vcan0 up
ip link add dev vcan1 type vcan && ip link set vcan1 up
ip link add dev vcan2 type vcan && ip link set vcan2 mtu 16 && ip link set vcan2 up
for i in 0 2 4 6; do
    ip link add vxcan$i type vxcan peer name vxcan$((i + 1)) &&
        ip link set vxcan$i up && ip link set vxcan$((i + 1)) up
done
# libcamera finds cameras through udev (only devices udev has initialised
# count), so the camera tests run with udevd; the others without it.
udev_start() {
    export SYSTEMD_IGNORE_CHROOT=1 # the VM runs the host's root in a chroot
    if ! /lib/systemd/systemd-udevd --daemon 2>/dev/null; then
        echo "in-vm: udevd did not start (is the host's udev package installed?)"
        return
    fi
    # only the cameras' devices: a short queue even on a slow VM
    udevadm trigger --action=add --subsystem-match=media --subsystem-match=video4linux &&
        udevadm settle -t 60 || echo "in-vm: udev did not settle within 60 s"
}
udev_stop() { udevadm control --exit 2>/dev/null; }
status=0
run_one() {
    t=$1
    echo "=== $(basename "$t") (in the VM)"
    case $(basename "$t") in test_hw_camera*) udev_start ;; esac
    "$t" > /tmp/hw.out 2>&1; rc=$?
    case $(basename "$t") in test_hw_camera*) udev_stop ;; esac
    cat /tmp/hw.out
    if [ "$rc" -ne 0 ]; then
        status=1
        grep -q '^\[  PASSED  \]' /tmp/hw.out ||
            printf '[  FAILED  ] 1 test(s), listed below:\n[  FAILED  ] %s (ended with rc %s)\n' "$(basename "$t")" "$rc"
    fi
}
# The camera tests last: they start udevd and stream from vimc, which must
# not share the VM's time with the drivers' timing tests.
for t in "$@"; do case $(basename "$t") in test_hw_camera*) ;; *) run_one "$t" ;; esac; done
for t in "$@"; do case $(basename "$t") in test_hw_camera*) run_one "$t" ;; esac; done
exit $status

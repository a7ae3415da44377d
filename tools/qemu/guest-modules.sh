# Runs in the VM's busybox initramfs before the tests (run-in-vm.sh -s): load
# the kernel modules; the interfaces are made by in-vm.sh with the host's
# iproute2. gpio-mockup: one chip of 8 lines, gpiochip0, named lines so
# lookups by name can be tested. vimc: the emulated camera (libcamera's vimc
# pipeline, tests/hw/test_hw_camera.c).
for m in can-raw can-bcm vcan vxcan sch_tbf; do modprobe $m || echo "modprobe $m failed"; done
modprobe gpio-mockup gpio_mockup_ranges=-1,8 gpio_mockup_named_lines=1
modprobe vimc || echo "modprobe vimc failed"

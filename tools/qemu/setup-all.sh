#!/bin/bash
# From scratch: fetch Debian bookworm amd64 kernel + busybox, build out-of-tree gpio-mockup/gpio-sim/irq-sim/vimc
# (Debian's kernel lacks CONFIG_GPIO_MOCKUP/GPIO_SIM/IRQ_SIM/VIDEO_VIMC), and build the 9p "run host command" initramfs.
# usage: setup-all.sh WORKDIR      (needs root; apt-get update done). Then: export QEMU_WORK=WORKDIR; run-in-vm.sh ...
set -euo pipefail
W=$(realpath -m "${1:?workdir}"); S=$(dirname "$(realpath "$0")"); mkdir -p "$W"/{debs,x,oot}; cd "$W"
KPKG=$(apt-cache depends linux-image-amd64 | awk '/Depends: linux-image-/{print $2; exit}')   # e.g. linux-image-6.1.0-56-amd64
KVER=${KPKG#linux-image-}; SRCPKG=linux-source-$(echo "$KVER" | cut -d. -f1,2)
echo "kernel $KVER"
export DEBIAN_FRONTEND=noninteractive
apt-get install -y -q --no-install-recommends qemu-system-x86 gcc libc6-dev make kmod cpio xz-utils linux-headers-$KVER libgpiod-dev >/dev/null
(cd debs && apt-get download -q "$KPKG" busybox-static "$SRCPKG" 2>&1 | { grep -v '^W:' || true; } | tail -1)
dpkg-deb -x debs/${KPKG}_*.deb x/kernel; dpkg-deb -x debs/busybox-static_*.deb x/bb; dpkg-deb -x debs/${SRCPKG}_*.deb x/lsrc
T=$(ls x/lsrc/usr/src/linux-source-*.tar.xz); B=$(basename "$T" .tar.xz)
tar -xJf "$T" -C x/lsrc "$B/drivers/gpio/gpio-mockup.c" "$B/drivers/gpio/gpio-sim.c" "$B/kernel/irq/irq_sim.c" \
    --wildcards "$B/drivers/gpio/gpiolib*.h" "$B/drivers/media/test-drivers/vimc/*.[ch]"
rm -f x/lsrc/usr/src/*.tar.xz
mkdir -p oot/gpio oot/vimc
cp x/lsrc/$B/drivers/gpio/{gpio-mockup.c,gpio-sim.c,gpiolib*.h} oot/gpio/
sed 's/handle_simple_irq(irq_to_desc(irqnum));/generic_handle_irq(irqnum);/' x/lsrc/$B/kernel/irq/irq_sim.c > oot/gpio/irq-sim.c
printf '#include <linux/module.h>\nMODULE_LICENSE("GPL");\n' >> oot/gpio/irq-sim.c
echo 'obj-m += irq-sim.o gpio-mockup.o gpio-sim.o' > oot/gpio/Kbuild
cp x/lsrc/$B/drivers/media/test-drivers/vimc/*.[ch] oot/vimc/
printf 'vimc-y := vimc-core.o vimc-common.o vimc-streamer.o vimc-capture.o vimc-debayer.o vimc-scaler.o vimc-sensor.o vimc-lens.o\nobj-m += vimc.o\n' > oot/vimc/Kbuild
# The filter may find nothing to print; a failing make must still fail here.
for d in gpio vimc; do make -s -C /usr/src/linux-headers-$KVER M="$W/oot/$d" -j2 modules 2>&1 | { grep -v 'Skipping BTF' || true; }; done
mkdir -p bin   # files here are copied into the initramfs /bin (empty by default)
"$S/mkinitramfs.sh" x/kernel "$KVER" x/bb/bin/busybox initrd-share.cpio.gz \
  "virtio_pci 9pnet_virtio 9p can-raw can-bcm can-isotp can-gw vcan vxcan sch_tbf gpio-mockup gpio-sim configfs vivid vimc" bin "oot/gpio oot/vimc"
ln -sf "$W/x/kernel/boot/vmlinuz-$KVER" vmlinuz   # run-in-vm.sh boots $QEMU_WORK/vmlinuz
du -sh debs x initrd-share.cpio.gz
echo "done: export QEMU_WORK=$W"

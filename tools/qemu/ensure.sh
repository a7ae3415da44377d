#!/usr/bin/env bash
# Makes sure the qemu test VM of `make test-hw` is ready in WORKDIR: a Debian
# kernel and its initramfs with vcan, vxcan and gpio-mockup (setup-all.sh,
# about 40 s and ~610 MB the first time, nothing when it is there and current).
# usage: ensure.sh WORKDIR      exit 0 ready | 1 could not (needs root and apt)
set -euo pipefail
W=$1; D=$(dirname "$(realpath "$0")")
# What the guest runs comes from the host's root: ip/tc (iproute2), candump.
bash "$D/../deps.sh" iproute2 can-utils
kver() { apt-cache depends linux-image-amd64 2>/dev/null | awk '/Depends: linux-image-/{print $2; exit}'; }
want=$(kver || true)
if [ -z "$want" ] && [ "$(id -u)" -eq 0 ]; then apt-get update -qq; want=$(kver || true); fi
# A new kernel or a changed recipe (module list, init) makes a new VM.
recipe=$(cat "$D/setup-all.sh" "$D/mkinitramfs.sh" "$D/init-hostshare" | sha256sum | cut -c1-16)
want="$want $recipe"
have=$(cat "$W/stamp" 2>/dev/null || true)
# Where apt cannot name the kernel (no root, no lists) a VM built from this
# recipe is still good: compare the recipe alone then.
if command -v qemu-system-x86_64 >/dev/null && [ -r "$W/vmlinuz" ] && [ -r "$W/initrd-share.cpio.gz" ] &&
    { [ "$want" = "$have" ] || { [ -z "${want%% *}" ] && [ "${have##* }" = "$recipe" ]; }; }; then
    exit 0
fi
[ "$(id -u)" -eq 0 ] || { echo "ensure: the VM is not set up and this is not root" >&2; exit 1; }
[ -n "${want%% *}" ] || { echo "ensure: apt knows no linux-image-amd64 (no package lists?)" >&2; exit 1; }
echo "test-hw: setting up the qemu VM in $W (kernel ${want%% *}, once, about 40 s)"
bash "$D/setup-all.sh" "$W"
echo "$want" > "$W/stamp"

#!/usr/bin/env bash
# The package `make deb` built (make test-deb): its control data, its
# contents, its maintainer script, lintian when installed, and the packaged
# binary unpacked and run from an empty folder. cmocka-style output for
# tools/run-tests.sh. Installing it on a clean Debian 12 is docs/deploy.md's
# `apt install ./...deb` (checked in a fresh chroot; see the commit notes).
set -uo pipefail
DIR=${PUSHSTEP_DEB_DIR:-build/deb}
ARCH=${PUSHSTEP_DEB_ARCH:-$(dpkg --print-architecture)}
# An arm64 package on another machine: its binary runs under qemu-user.
RUN=()
[ "$ARCH" = "$(dpkg --print-architecture)" ] || RUN=(qemu-aarch64)
DEB=$(ls -t "$DIR"/pushstep_*_"$ARCH".deb 2>/dev/null | head -1)
T=$(mktemp -d /tmp/ps-deb.XXXXXX); trap 'rm -rf "$T"' EXIT
pass=0; fail=0
ok()  { echo "[       OK ] $1"; pass=$((pass + 1)); }
bad() { echo "[  FAILED  ] $1: $2"; fail=$((fail + 1)); }
echo "[==========] deb ${DEB:-none}"
[ -n "$DEB" ] || { bad deb_built "no $DIR/pushstep_*_$ARCH.deb"; echo "[  PASSED  ] 0 test(s)."; exit 1; }

info=$(dpkg-deb -I "$DEB")
deps=$(dpkg-deb -f "$DEB" Depends)
if [ "$(dpkg-deb -f "$DEB" Package)" = pushstep ] && [ "$(dpkg-deb -f "$DEB" Architecture)" = "$ARCH" ] &&
   grep -q libmujoco <<<"$deps" && grep -q libcyaml <<<"$deps" && grep -q libgpiod <<<"$deps" &&
   grep -q adduser <<<"$deps"; then ok deb_control; else bad deb_control "$info"; fi

list=$(dpkg-deb -c "$DEB" | awk '{print $6}')
missing=""
for f in ./usr/bin/pushstep ./usr/share/pushstep/boards/rpi5.yaml ./usr/share/pushstep/boards/sim.yaml \
         ./usr/share/pushstep/robots/ps1.yaml ./usr/share/pushstep/scenarios/stand.yaml \
         ./usr/share/pushstep/sim/models/ps1.xml ./lib/systemd/system/pushstep@.service \
         ./lib/udev/rules.d/60-pushstep.rules ./usr/share/doc/pushstep/deploy.md; do
    grep -qxF "$f" <<<"$list" || missing+=" $f"
done
if [ -z "$missing" ]; then ok deb_contents; else bad deb_contents "missing:$missing"; fi

dpkg-deb -e "$DEB" "$T/ctl"
if grep -q 'adduser --system --group' "$T/ctl/postinst" 2>/dev/null; then ok deb_postinst_adds_user
else bad deb_postinst_adds_user "$(cat "$T/ctl/postinst" 2>&1 | head -5)"; fi

if command -v lintian >/dev/null; then
    out=$(lintian --fail-on error "$DEB" 2>&1); rc=$?
    if [ "$rc" -eq 0 ]; then ok deb_lintian_no_errors; else bad deb_lintian_no_errors "$(grep '^E:' <<<"$out" | head -5)"; fi
fi

dpkg-deb -x "$DEB" "$T/root"
mkdir -p "$T/empty"; cd "$T/empty" || exit 1
if env -u PUSHSTEP_DATA_DIR "${RUN[@]}" "$T/root/usr/bin/pushstep" --help >/dev/null; then ok deb_binary_help
else bad deb_binary_help "rc $?"; fi
out=$(env -u PUSHSTEP_DATA_DIR "${RUN[@]}" "$T/root/usr/bin/pushstep" --lockstep --duration 0.3 --quiet 2>&1)
if grep -q "share/pushstep/boards/sim.yaml" <<<"$out"; then ok deb_binary_finds_data
else bad deb_binary_finds_data "$(tail -3 <<<"$out")"; fi
out=$(env -u PUSHSTEP_DATA_DIR "${RUN[@]}" "$T/root/usr/bin/pushstep" doctor --board rpi5 2>&1); rc=$?
if [ "$rc" -le 1 ] && grep -q "fine, .* to fix" <<<"$out"; then ok deb_binary_doctor
else bad deb_binary_doctor "rc $rc: $(tail -3 <<<"$out")"; fi
echo "[==========] $((pass + fail)) test(s) run."
echo "[  PASSED  ] $pass test(s)."
[ "$fail" -eq 0 ] || { echo "[  FAILED  ] $fail test(s), listed below:"; exit 1; }

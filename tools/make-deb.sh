#!/usr/bin/env bash
# make deb [ARCH=aarch64]: the Debian package, built with dpkg-buildpackage
# in a copy of the tree (tracked and untracked-but-not-ignored files) whose
# debian/ is tools/debian/ (the top level of the repository is fixed).
# Output: BUILD/deb/pushstep_VERSION_ARCH.deb (and .buildinfo, .changes).
set -euo pipefail
BUILD=${1:-build}; ARCH=${2:-}
case "$ARCH" in
    "" | x86_64 | amd64) host=() ;;
    aarch64 | arm64) host=(-aarm64) ;;
    *) echo "make deb: ARCH=$ARCH: amd64 or aarch64" >&2; exit 2 ;;
esac
OUT=$BUILD/deb
rm -rf "$OUT/src"; mkdir -p "$OUT/src/pushstep"
git ls-files -co --exclude-standard -z | grep -zv '^tools/debian/' |
    xargs -0 cp -P --parents -t "$OUT/src/pushstep" 2>/dev/null ||
    { echo "make deb: copying the tree failed" >&2; exit 1; }
cp -R tools/debian "$OUT/src/pushstep/debian"
(cd "$OUT/src/pushstep" && dpkg-buildpackage -us -uc -b "${host[@]}") > "$OUT/build.log" 2>&1 ||
    { tail -30 "$OUT/build.log"; echo "make deb: dpkg-buildpackage failed (log: $OUT/build.log)" >&2; exit 1; }
mv -f "$OUT"/src/pushstep_* "$OUT"/
rm -rf "$OUT/src"
ls -1 "$OUT"/*.deb

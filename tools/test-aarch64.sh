#!/usr/bin/env bash
# make test ARCH=aarch64: the aarch64 unit test binaries given, each run
# under qemu-user (qemu-aarch64; no binfmt_misc registration needed) through
# tools/run-tests.sh, so the result ends with the same "N passed, N failed".
# Tests that start the runtime get the aarch64 pushstep the same way
# (PUSHSTEP_BIN="qemu-aarch64 BUILD/pushstep": they run it through a shell).
#
# Every test binary runs unless it is listed below with the reason it cannot
# run under qemu-user, or (AARCH64_TESTS=quick, what the native `make test`
# uses) it is one of the slow ones: qemu's TCG runs the MuJoCo plant about
# 150 times slower than the host, so the simulation-heavy tests take minutes.
# AARCH64_TESTS=all runs those too. The quick set keeps test_mlp and
# test_weights: they run the inference engine's NEON build against the
# PyTorch vectors of tests/data/policy (docs/policy.md), under a second each.
#
# Without arguments (an item of the native `make test`): the binaries of
# $AARCH64_BUILD (default build-aarch64) that `make test` built when the
# cross tools are installed, in quick mode; skipped (exit 77) when there are
# none.
set -uo pipefail
if [ $# -eq 0 ]; then
    B=${AARCH64_BUILD:-build-aarch64}
    shopt -s nullglob
    set -- "$B"/tests/test_*
    [ $# -gt 0 ] && [ -x "$B/pushstep" ] ||
        { echo "[  SKIPPED ] aarch64: no $B/tests (the cross toolchain or the arm64 libraries are not installed)"; exit 77; }
    PUSHSTEP_BIN=$B/pushstep
    MODE=${AARCH64_TESTS:-quick}
fi
BIN=${PUSHSTEP_BIN:?PUSHSTEP_BIN: the aarch64 pushstep}
MODE=${MODE:-${AARCH64_TESTS:-all}}
QEMU=${QEMU_AARCH64:-qemu-aarch64}
command -v "$QEMU" >/dev/null || { echo "[  SKIPPED ] aarch64: no $QEMU (package qemu-user)"; exit 77; }
# Cannot run under qemu-user:
#  test_e2e_cli: real-time runs of the runtime (1 kHz deadlines, SIGINT while
#    braking, profile as nobody): qemu's emulation misses every deadline.
#  test_e2e_lockstep: runs of 10 to 20 s of simulated time; at ~150x slower
#    than the host each takes half an hour (measured: not done in 300 s).
#  test_e2e_recorder: an 8 s lockstep run and real-time runs of the runtime,
#    read by the host's Node packages (as test_e2e_lockstep and test_e2e_cli).
# Single tests that measure the kernel's memory handling or real time skip
# themselves when PS_QEMU_USER is set (test_guard's other-thread page faults,
# test_rtsetup's residency after prefault, test_sim's real-time smoke test).
#  test_e2e_camera: a 4 s lockstep run and a real-time run with the simulated
#    camera rendering beside the loop; under qemu-user (measured, 82 s) the
#    lockstep robot was still in STANDBY after 4 s and the real-time run got
#    no frame in 3 s.
#  test_crowd: crowds of up to 105 people for about 60 s of simulated time
#    (23-37 s natively): not done after several minutes under qemu-user,
#    whose TCG runs the plant some 150 times slower.
#  test_e2e_faults: the fault matrix, 35 lockstep runs of 1.7 to 3.5 s of
#    simulated time (8 to 11 s natively): over a quarter of an hour at ~150x.
declare -A CANNOT=([test_e2e_cli]=1 [test_e2e_lockstep]=1 [test_e2e_recorder]=1 \
                   [test_e2e_camera]=1 [test_crowd]=1 [test_e2e_faults]=1)
# Offscreen OpenGL (test_render, test_camera_sim) goes through Mesa's arm64
# software rasteriser, libgl1-mesa-dri:arm64 (in the Makefile's CROSS_LIBS;
# without it test_camera_sim exits 255). llvmpipe's JIT dies of SIGSEGV under
# qemu-user; its non-JIT sibling softpipe runs (measured: test_camera_sim
# 18 s, test_render 235 s).
export GALLIUM_DRIVER=softpipe
# Slow under qemu, run only by AARCH64_TESTS=all (measured here: test_plant
# 127 s, test_sim 83 s, test_render 235 s):
declare -A SLOW=([test_plant]=1 [test_sim]=1 [test_render]=1)
dir=$(dirname "$BIN")/qemu-user
rm -rf "$dir"; mkdir -p "$dir"
wrappers=()
for t in "$@"; do
    name=$(basename "$t")
    [ -n "${CANNOT[$name]:-}" ] && continue
    [ "$MODE" = quick ] && [ -n "${SLOW[$name]:-}" ] && continue
    printf '#!/bin/sh\nexec %s %s "$@"\n' "$QEMU" "$(realpath "$t")" > "$dir/$name"
    chmod +x "$dir/$name"
    wrappers+=("$dir/$name")
done
echo "aarch64 under $QEMU: ${#wrappers[@]} of $# test binaries ($MODE)"
PS_QEMU_USER=1 PUSHSTEP_BIN="$QEMU $(realpath "$BIN")" exec bash "$(dirname "$0")/run-tests.sh" "${wrappers[@]}"

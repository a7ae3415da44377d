#!/usr/bin/env bash
# `make bench` (after bench/run.sh), camera perception on this machine's CPU:
#
#   detection   `pushstep camera` on the simulated camera of
#               tests/data/boards/sim-camera.yaml (640 x 480, 15 frames/s
#               asked, the scene of tests/data/robots/ps1-tags.yaml: six tags
#               in view): frames and tags per second, latency from exposure
#               (the scene's state taken for rendering) to the mailbox, and
#               the detection's own time (grey conversion and AprilTags),
#               with the check against the plant's truth
#   beside      the loop's tick time with perception running beside it versus
#               without, in the same run: `pushstep profile` on the same
#               robot alternating board sim-camera (camera) and sim (none),
#               BENCH_CAM_PAIRS pairs of BENCH_CAM_BLOCK_S s blocks, order
#               C N N C ... (ABBA), merged per side (worst block per
#               percentile), and their ratio
#
# Writes bench/results/camera.json and camera.md (the summary it prints);
# raw outputs in $BUILD/bench-camera/. Knobs: BENCH_CAM_S (20),
# BENCH_CAM_PAIRS (2), BENCH_CAM_BLOCK_S (10), BUILD (build).
set -euo pipefail
cd "$(dirname "$0")/.."
CAM_S=${BENCH_CAM_S:-20}
PAIRS=${BENCH_CAM_PAIRS:-2}
BLOCK_S=${BENCH_CAM_BLOCK_S:-10}
BUILD=${BUILD:-build}
BIN=$BUILD/pushstep
CAM_BOARD=tests/data/boards/sim-camera.yaml
PLAIN_BOARD=boards/sim.yaml
ROBOT=tests/data/robots/ps1-tags.yaml
# The robot file's scene alone (its six tagged people): the default crowd
# would stand between them and the camera, and load the plant beside the loop
SCENARIO=scenarios/stand.yaml
RESULTS=bench/results
OUT=$BUILD/bench-camera
PY=/usr/bin/python3
[ -x "$PY" ] || PY=python3
log() { echo "bench-camera: $*"; }
die() {
    echo "bench-camera: $*" >&2
    exit 1
}
[ -x "$BIN" ] || die "$BIN missing: run make"
rm -rf "$OUT"
mkdir -p "$OUT" "$RESULTS"
t0=$(date +%s)

det_cmd=("$BIN" camera --board "$CAM_BOARD" --robot "$ROBOT" --scenario "$SCENARIO" --duration "$CAM_S"
    --out "$OUT/detect")
log "detection: ${det_cmd[*]}"
"${det_cmd[@]}" >"$OUT/detect.log" 2>&1 || {
    cat "$OUT/detect.log" >&2
    die "pushstep camera failed"
}

: >"$OUT/blocks.tsv"
block() { # side n
    local side=$1 n=$2 board=$PLAIN_BOARD
    [ "$side" = camera ] && board=$CAM_BOARD
    local dir=$OUT/$side-$n
    local cmd=("$BIN" profile --board "$board" --robot "$ROBOT" --scenario "$SCENARIO"
        --duration "$BLOCK_S" --quiet --out "$dir")
    "${cmd[@]}" >"$dir.log" 2>&1 || {
        cat "$dir.log" >&2
        die "pushstep profile failed: ${cmd[*]}"
    }
    printf '%s\t%s\t%s\t%s\n' "$side" "$n" "$dir" "${cmd[*]}" >>"$OUT/blocks.tsv"
    log "  $side block $n: $(grep -E '^camera:' "$dir.log" || echo 'no camera')"
}
log "beside: $PAIRS pairs of ${BLOCK_S} s profile blocks, camera (C) and none (N), C N N C ..."
for ((p = 1; p <= PAIRS; p++)); do
    if [ $((p % 2)) = 1 ]; then
        block camera "$p"
        block none "$p"
    else
        block none "$p"
        block camera "$p"
    fi
done

"$PY" - "$OUT" "$RESULTS" "$(($(date +%s) - t0))" "${det_cmd[*]}" "$BLOCK_S" <<'PYEOF'
import json, os, re, sys, time
out, results, wall, det_cmd = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
block_s = float(sys.argv[5])
det = json.load(open(os.path.join(out, "detect", "camera.json")))
st = det["stats"]
blocks = [l.rstrip("\n").split("\t") for l in open(os.path.join(out, "blocks.tsv"))]
STAGES = ("tick", "tick_plain", "tick_policy", "wake")
FIELDS = ("p50_us", "p99_us", "p999_us", "max_us")
side = {"camera": {}, "none": {}}
cam_lines, cmds = [], {}
for s, n, d, cmd in blocks:
    p = json.load(open(os.path.join(d, "profile.json")))
    cmds.setdefault(s, cmd)
    for stage in STAGES:
        lat = p["latency"][stage]
        acc = side[s].setdefault(stage, {f: 0.0 for f in FIELDS})
        for f in FIELDS:  # worst block per percentile
            acc[f] = max(acc[f], lat[f])
    side[s].setdefault("ticks", 0)
    side[s]["ticks"] += p["ticks"]
    side[s].setdefault("overruns", 0)
    side[s]["overruns"] += p["overruns"]
    after = p["after_init"]
    side[s].setdefault("after_init_mallocs", 0)
    side[s]["after_init_mallocs"] += after["mallocs"]
    side[s].setdefault("after_init_locks", 0)
    side[s]["after_init_locks"] += after["locks"]
    if s == "camera":
        m = re.search(r"^camera: .*$", open(d + ".log").read(), re.M)
        cam_lines.append(m.group(0) if m else "no camera line")
ratio = {stage: {f: (side["camera"][stage][f] / side["none"][stage][f]
                     if side["none"][stage][f] > 0 else None) for f in FIELDS}
         for stage in STAGES}
res = {
    "date": time.strftime("%Y-%m-%d %H:%M:%S %z"),
    "wall_s": wall,
    "detection": {
        "command": det_cmd,
        "width": det["width"], "height": det["height"], "fps_asked": det["fps_asked"],
        "frames_per_s": st["frames_per_s"], "tags_per_s": st["tags_per_s"],
        "frames": st["frames"], "tags": st["tags"], "errors": st["errors"],
        "latency_exposure_to_mailbox_ms": st["latency_ms"],
        "detect_ms": st["detect_ms"],
        "truth_last_frame": det.get("truth"),
    },
    "beside_loop": {
        "blocks": [{"side": s, "block": int(n), "dir": d} for s, n, d, _ in blocks],
        "block_s": block_s, "commands": cmds,
        "camera": side["camera"], "none": side["none"],
        "ratio_camera_to_none": ratio,
        "camera_lines": cam_lines,
    },
}
json.dump(res, open(os.path.join(results, "camera.json"), "w"), indent=2)
d = res["detection"]
L, D = d["latency_exposure_to_mailbox_ms"], d["detect_ms"]
md = []
md.append("# Camera perception (bench/camera.sh)\n")
md.append("Date: %s; wall time %d s. Raw outputs in build/bench-camera/.\n" % (res["date"], wall))
md.append("## Detection on this machine's CPU, %dx%d, simulated camera\n" % (d["width"], d["height"]))
md.append("| figure | value |\n|---|---|")
md.append("| frames per second (%.0f asked) | %.1f |" % (d["fps_asked"], d["frames_per_s"]))
md.append("| tags detected per second | %.1f |" % d["tags_per_s"])
md.append("| exposure to mailbox, p50 / p90 / p99 / max | %.1f / %.1f / %.1f / %.1f ms |"
          % (L["p50"], L["p90"], L["p99"], L["max"]))
md.append("| of which detection (grey + AprilTags), p50 / p99 | %.1f / %.1f ms |" % (D["p50"], D["p99"]))
t = d["truth_last_frame"]
if t:
    md.append("| last frame against the plant's truth | %d of %d tags seen whole detected, largest error %.1f mm |"
              % (t["tags_detected"], t["tags_seen_whole"], t["max_error_mm"]))
md.append("\nExposure is when the camera took the scene's state for rendering: the latency holds the offscreen")
md.append("rendering (Mesa's software rasteriser), the grey conversion, the detection and the publish.\n")
md.append("    %s\n" % det_cmd)
md.append("## The loop's tick time with perception beside it (C) and without (N), same run\n")
md.append("| stage | C p50 / p99 / p99.9 / max (us) | N p50 / p99 / p99.9 / max (us) | C / N at p99 | C / N at max |")
md.append("|---|---|---|---|---|")
for stage in STAGES:
    c, n = side["camera"][stage], side["none"][stage]
    r = ratio[stage]
    fmt = lambda x: "%.1f" % x
    md.append("| %s | %s | %s | %s | %s |" % (
        stage, " / ".join(fmt(c[f]) for f in FIELDS), " / ".join(fmt(n[f]) for f in FIELDS),
        "%.2f" % r["p99_us"] if r["p99_us"] else "n/a", "%.2f" % r["max_us"] if r["max_us"] else "n/a"))
md.append("| ticks, overruns | %d, %d | %d, %d | | |" % (
    side["camera"]["ticks"], side["camera"]["overruns"], side["none"]["ticks"], side["none"]["overruns"]))
md.append("| loop thread after init: mallocs, locks | %d, %d | %d, %d | | |" % (
    side["camera"]["after_init_mallocs"], side["camera"]["after_init_locks"],
    side["none"]["after_init_mallocs"], side["none"]["after_init_locks"]))
md.append("\nWorst block per percentile on each side; tick = read to write; wake = wake-up latency.")
md.append("Perception in the camera blocks:\n")
for l in cam_lines:
    md.append("    " + l)
md.append("")
for s in ("camera", "none"):
    md.append("    %s" % cmds[s])
open(os.path.join(results, "camera.md"), "w").write("\n".join(md) + "\n")
print("\n".join(md))
PYEOF
log "done in $(($(date +%s) - t0)) s: $RESULTS/camera.json, camera.md"

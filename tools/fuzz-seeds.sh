#!/usr/bin/env bash
# Regenerates the fuzz targets' seed corpora in tests/fuzz/corpus/ (make fuzz,
# tests/test_fuzz.sh, docs/fuzzing.md) from real data:
#   - CAN frames: candump logs of short lockstep runs of the simulated robot
#     (build/pushstep --candump) with MIT + RobStride (ps1-mixed), moteus over
#     CAN FD (ps1-moteus on sim-fd) and an Xsens IMU (ps1-xsens); every frame
#     becomes a frame record (tests/fuzz/fuzz.h), a few per seed;
#   - candump lines and a short log for the replay, from the same logs;
#   - the shipped board, robot and scenario files and the test data's;
#   - the smallest policy files of tests/data/policy;
#   - a flight recording of a 0.1 s run (--record), zstd and lz4 chunks;
#   - GPIO edge sequences: a clean press, a bounce, a held button.
# Usage: tools/fuzz-seeds.sh [BUILD]   (needs BUILD/pushstep)
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
bin=$build/pushstep
out=tests/fuzz/corpus
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
rm -rf "$out"
mkdir -p "$out"

run() { # robot board log
    "$bin" --lockstep --quiet --duration 0.25 --scenario scenarios/stand.yaml --robot "$1" \
        --board "$2" --candump "$3" >/dev/null
}
run tests/data/robots/ps1-mixed.yaml sim "$tmp/mixed.log"
run tests/data/robots/ps1-moteus.yaml tests/data/boards/sim-fd.yaml "$tmp/moteus.log"
run tests/data/robots/ps1-xsens.yaml sim "$tmp/xsens.log"
run robots/ps1.yaml sim "$tmp/ps1.log"

/usr/bin/python3 - "$tmp" "$out" <<'PY'
import hashlib, os, re, struct, sys
tmp, out = sys.argv[1], sys.argv[2]
LINE = re.compile(r"\((\d+)\.(\d+)\) (\S+) ([0-9A-Fa-f]+)(##|#)(\S*)")

def frames(log, bus=None):
    for line in open(os.path.join(tmp, log)):
        m = LINE.match(line)
        if not m or (bus is not None and m.group(3) != bus):
            continue
        ident, sep, rest = m.group(4), m.group(5), m.group(6)
        ext = len(ident) == 8
        fd = sep == "##"
        brs = False
        if fd:
            brs = int(rest[0], 16) & 1 == 1
            rest = rest[1:]
        yield ext, fd, brs, int(ident, 16), bytes.fromhex(rest)

def record(f):
    ext, fd, brs, ident, data = f
    return bytes([ext | fd << 1 | brs << 2]) + struct.pack("<I", ident) + bytes([len(data)]) + data

def save(target, blob):
    d = os.path.join(out, target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, hashlib.sha1(blob).hexdigest()[:16]), "wb") as f:
        f.write(blob)

def frame_seeds(target, fs, per_seed=1, max_seeds=24):
    """Distinct frames (by id, kind and first bytes), per_seed in a row."""
    seen, picked = set(), []
    for f in fs:
        key = (f[0], f[1], f[3], f[4][:2])
        if key not in seen:
            seen.add(key)
            picked.append(f)
    step = max(1, len(picked) // max_seeds)
    for k in range(0, min(len(picked), max_seeds * step), step):
        for mount in (b"\x00", b"\x01"):
            save(target, mount + b"".join(record(f) for f in picked[k:k + per_seed]))

frame_seeds("fuzz_mit", [f for f in frames("mixed.log", "can3") if not f[0]])
frame_seeds("fuzz_robstride", [f for f in frames("mixed.log", "can0") if f[0]])
frame_seeds("fuzz_moteus", list(frames("moteus.log", "can0")))

def stream(target, fs, n):
    fs = list(fs)
    for start in range(0, min(len(fs), 40 * n), 4 * n):
        save(target, b"".join(record(f) for f in fs[start:start + n]))

stream("fuzz_imu_msg", [f for f in frames("ps1.log", "can3") if f[3] in (0x080, 0x081)], 4)
stream("fuzz_imu_xsens", [f for f in frames("xsens.log", "can3") if 0x205 <= f[3] <= 0x234], 10)

# candump lines: a few of each kind (classical, 29-bit, FD), and short logs
for log in ("mixed.log", "moteus.log", "xsens.log"):
    lines = open(os.path.join(tmp, log)).read().splitlines(True)
    for k in range(0, len(lines), max(1, len(lines) // 6)):
        save("fuzz_candump", "".join(lines[k:k + 3]).encode())
    # the replay's robot: tests/fuzz/fuzz_can_replay.c
    save("fuzz_can_replay", "".join(lines[:60]).encode())
# GPIO: debounce 5 ms (5000 us), released at t = 1 s, then op records
def gpio(deb_us, pressed, ops):
    b = struct.pack("<HB", deb_us, pressed) + struct.pack("<q", 1000000000)
    for op, dt_us in ops:
        b += bytes([op]) + struct.pack("<H", dt_us)
    save("fuzz_gpio_debounce", b)
EDGE_P, EDGE_R, POLL, TAKE = 4, 0, 1, 2
gpio(5000, 0, [(EDGE_P, 100), (POLL, 6000), (TAKE, 0), (EDGE_R, 200), (POLL, 6000), (TAKE, 0)])
gpio(5000, 0, [(EDGE_P, 100), (EDGE_R, 300), (EDGE_P, 200), (EDGE_R, 100), (POLL, 9000), (TAKE, 0)])
gpio(5000, 1, [(TAKE, 0), (POLL, 1000), (TAKE, 0), (EDGE_R, 10), (EDGE_P | 3, 5), (TAKE, 0)])
gpio(0, 0, [(EDGE_P, 1), (EDGE_R, 1), (TAKE, 0), (TAKE, 0)])
PY

for f in boards/*.yaml tests/data/boards/*.yaml tests/data/config/board_ok.yaml; do
    mkdir -p "$out/fuzz_config_board" && cp "$f" "$out/fuzz_config_board/$(basename "$f")"
done
for f in robots/*.yaml tests/data/robots/*.yaml tests/data/config/robot_ok.yaml; do
    mkdir -p "$out/fuzz_config_robot" && cp "$f" "$out/fuzz_config_robot/$(basename "$f")"
done
mkdir -p "$out/fuzz_config_scenario"
for f in scenarios/stand.yaml scenarios/estop.yaml scenarios/push.yaml scenarios/crowd.yaml \
         scenarios/fault-drop.yaml tests/data/config/scenario_ok.yaml tests/data/config/crowd_ok.yaml; do
    cp "$f" "$out/fuzz_config_scenario/$(basename "$f")"
done
# Dictionaries for the YAML targets: every key the seeds use, and YAML's
# own tokens (libFuzzer -dict; tools/fuzz.sh passes tests/fuzz/NAME.dict).
for t in board robot scenario; do
    /usr/bin/python3 - "$out/fuzz_config_$t" "tests/fuzz/fuzz_config_$t.dict" <<'PY'
import os, re, sys
keys = set()
for f in sorted(os.listdir(sys.argv[1])):
    for line in open(os.path.join(sys.argv[1], f)):
        line = line.split("#")[0]
        keys.update(re.findall(r"([A-Za-z_][A-Za-z0-9_]*):", line))
toks = ["- ", ": ", "{", "}", "[", "]", ", ", "&a", "*a", "!!str", "~", "null", "true",
        "false", ".nan", ".inf", "-.inf", "0x", "1e39", "-1", "4294967296", "'", '"', "|", ">"]
with open(sys.argv[2], "w") as o:
    o.write("# generated by tools/fuzz-seeds.sh from the seeds' keys\n")
    for k in sorted(keys):
        o.write('"%s: "\n' % k)
    for t in toks:
        o.write('"%s"\n' % t.replace("\\", "\\\\").replace('"', '\\"'))
PY
done
mkdir -p "$out/fuzz_weights"
for f in golden_vectors golden_acts ps1_zero; do
    cp "tests/data/policy/$f.safetensors" "$out/fuzz_weights/$f.safetensors"
done
mkdir -p "$out/fuzz_mcap"
for c in zstd lz4; do
    "$bin" --lockstep --quiet --duration 0.05 --scenario scenarios/stand.yaml \
        --record "$tmp/r.mcap" --record-compression "$c" >/dev/null
    cp "$tmp/r.mcap" "$out/fuzz_mcap/stand-$c.mcap"
done
# a recording cut short, as by a power cut
head -c 3000 "$out/fuzz_mcap/stand-zstd.mcap" >"$out/fuzz_mcap/cut.mcap"
du -sh --apparent-size "$out"

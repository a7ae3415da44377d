#!/usr/bin/env bash
# make bench, the balance policy's part (docs/policy.md):
#  1. inference at batch 1: the engine (policy/ps_mlp) beside an OpenBLAS
#     cblas_sgemv chain and libtorch on the same networks, in one run:
#     bench/results/inference.json
#  2. the push-recovery grid in the real runtime (build/pushstep --lockstep):
#     16 directions x delta-v 0.15 .. 0.80 m/s x 0.1 s bumps and 0.3 s shoves,
#     for the standing controller, the capture-point controller and the
#     trained policy (when policy/weights/ps1_stage1.safetensors exists),
#     PUSH_TRIALS trials a cell (make bench: 1; the issue's full grid: 20,
#     bench/policy.sh --full), parallel over the cores with GNU parallel:
#     bench/results/push.json, push.md, push_dv50_0.1s.png, push_dv50_0.3s.png
#  3. with a trained policy, the same pushes in the training environment
#     (policy/train/eval.py, each trial starting as the runtime's: held limp,
#     then the ramp) beside the runtime's: bench/results/train_env.*
# PUSH_DIRECTIONS=8 halves the grid (the shipped results: docs/policy.md).
# PUSH_SSH="host1,host2" runs the grid with parallel --sshlogin on those hosts
# (the repository and build at the same path there); bench/push-slurm.sh is a
# Slurm job array for clusters.
set -euo pipefail
cd "$(dirname "$0")/.."
RES=bench/results
mkdir -p "$RES" build/bench
TRIALS=${PUSH_TRIALS:-1}
[ "${1:-}" = "--full" ] && TRIALS=20
JOBS=${PUSH_JOBS:-$(nproc)}
DIRS=${PUSH_DIRECTIONS:-16}
WEIGHTS=policy/weights/ps1_stage1.safetensors

echo "== inference at batch 1"
make -s build/obj/policy/ps_mlp.o
gcc -O2 -std=c11 -D_GNU_SOURCE bench/infer/infer_c.c build/obj/policy/ps_mlp.o \
    -o build/bench/infer_c -lopenblas -lm
has_torch=0
if [ -f /usr/include/torch/csrc/api/include/torch/torch.h ]; then
    [ build/bench/infer_torch -nt bench/infer/infer_torch.cpp ] ||
        g++ -O2 -std=c++17 bench/infer/infer_torch.cpp -o build/bench/infer_torch \
            -I/usr/include/torch/csrc/api/include -ltorch -ltorch_cpu -lc10
    has_torch=1
fi
{
    echo "["
    first=1
    for net in 100,256,256,128,20 77,128,128,12; do
        c=$(OPENBLAS_NUM_THREADS=1 build/bench/infer_c $net build/bench/w.bin)
        t='{}'
        [ $has_torch = 1 ] && t=$(OMP_NUM_THREADS=1 build/bench/infer_torch $net build/bench/w.bin)
        [ $first = 1 ] || echo ","
        first=0
        python3 -c 'import json,sys; c=json.loads(sys.argv[1]); t=json.loads(sys.argv[2]);
c.update(t); c["same_output"] = ("out0" not in t) or abs(c["out0"] - t["out0"]) < 1e-4
print(json.dumps(c))' "$c" "$t"
    done
    echo "]"
} >"$RES/inference.json"
cat "$RES/inference.json"

echo "== push-recovery grid: $DIRS directions, $TRIALS trial(s) a cell, $JOBS jobs"
ctl=stand,capture
[ -f "$WEIGHTS" ] && ctl=$ctl,mlp
rm -rf "$RES/push_trials"
start=$(date +%s)
ssh_opt=()
[ -n "${PUSH_SSH:-}" ] && ssh_opt=(--sshlogin "$PUSH_SSH" --workdir "$PWD")
python3 bench/push.py jobs --controllers "$ctl" --trials "$TRIALS" --directions "$DIRS" |
    parallel -j "$JOBS" "${ssh_opt[@]}" --halt soon,fail=1 \
        python3 bench/push.py trial {} --out "$RES/push_trials"
python3 bench/push.py merge "$RES/push_trials" --out "$RES/push.json" >"$RES/push.md"
python3 bench/push.py plot "$RES/push.json" --out "$RES/push_dv50.png"
echo "grid: $(ls "$RES/push_trials" | wc -l) trials in $(($(date +%s) - start)) s" | tee -a "$RES/push.md"
rm -rf "$RES/push_trials"

if [ -f "$WEIGHTS" ]; then
    echo "== the same grid in the training environment (nominal robot, the runtime's start), beside the runtime's"
    make -s build/libpsenv.so
    /usr/bin/python3 policy/train/eval.py --weights "$WEIGHTS" --runtime "$RES/push.json" \
        --directions "$DIRS" --harness --ramp-start \
        --out "$RES/train_env.json" >"$RES/train_env.md"
    cat "$RES/train_env.md"
fi

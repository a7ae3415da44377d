#!/usr/bin/env bash
# Smoke test of the training pipeline (make test): a few iterations of
# policy/train/train.py on the C environment (build/libpsenv.so), then the
# runtime loads the policy file it wrote and runs it in lockstep. Prints
# cmocka's summary lines for tools/run-tests.sh. About 30 s.
set -uo pipefail
cd "$(dirname "$0")/.."
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
pass=0; fail=0
check() { if "$@"; then pass=$((pass + 1)); echo "[       OK ] $name"; else fail=$((fail + 1)); echo "[  FAILED  ] $name"; fi; }

name="train.py writes a policy file and its learning curve"
check bash -c "/usr/bin/python3 policy/train/train.py --envs 4 --threads 2 --steps 16 \
    --bc-iters 3 --ppo-iters 2 --out $out/p.safetensors --log-dir $out >$out/train.out 2>&1 \
    && test -s $out/p.safetensors && test \$(wc -l <$out/log.csv) -eq 6"
name="the runtime runs the trained file in lockstep (contract checked against ps1)"
check bash -c "${PUSHSTEP_BIN:-build/pushstep} --lockstep --quiet --duration 3 --scenario scenarios/stand.yaml --policy mlp \
    --weights $out/p.safetensors --summary $out/s.json >$out/run.out 2>&1 \
    && grep -Eq '\"fall_detected\":[[:space:]]*false' $out/s.json"
name="same seed, same first iterations (deterministic environment and trainer)"
check bash -c "/usr/bin/python3 policy/train/train.py --envs 4 --threads 2 --steps 16 \
    --bc-iters 3 --ppo-iters 2 --out $out/q.safetensors --log-dir $out/b >/dev/null 2>&1 \
    && cmp -s <(cut -d, -f1-8 $out/log.csv) <(cut -d, -f1-8 $out/b/log.csv)"
name="eval.py runs the benchmark's pushes in the training environment"
check bash -c "/usr/bin/python3 policy/train/eval.py --weights $out/p.safetensors --dv 0.15 \
    --durations 0.1 --directions 2 --out $out/e.json >$out/eval.out 2>&1 \
    && grep -q '\"controller\": \"mlp\"' $out/e.json"
name="the shipped policy (policy/weights/ps1_stage1.safetensors) stands in lockstep, contract checked"
check bash -c "${PUSHSTEP_BIN:-build/pushstep} --lockstep --quiet --duration 6 --scenario scenarios/stand.yaml \
    --policy mlp --weights policy/weights/ps1_stage1.safetensors --summary $out/shipped.json \
    >$out/run.out 2>&1 && grep -Eq '\"fall_detected\":[[:space:]]*false' $out/shipped.json \
    && grep -Eq '\"policy_runs\":[[:space:]]*[1-9]' $out/shipped.json"
[ $fail -gt 0 ] && { cat "$out/train.out" "$out/run.out" 2>/dev/null | tail -20; }
echo "[  PASSED  ] $pass test(s)."
[ $fail -gt 0 ] && echo "[  FAILED  ] $fail test(s), listed below:"
[ $fail -eq 0 ]

#!/usr/bin/env bash
# Smoke test of the training pipeline (make test): a few iterations of
# policy/train/train.py on the C environment (build/libpsenv.so), then the
# runtime loads the policy file it wrote and runs it in lockstep. Prints
# cmocka's summary lines for tools/run-tests.sh. About 50 s.
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
# make train's runs (TRAIN_ARGS with each member's seed and options,
# residual policies; TRAIN_MEMBERS, policy/weights/ps1_stage1.members) have
# the learning logs of make train on the portable float path
# (policy/train/portable.py), recorded in bench/results/pinned/memberN/
# (the shipped members were trained before that path, on machines of
# another kind, and their logs are not made again: docs/policy.md);
# make train-clone's first stage
# (TRAIN_CLONE_ARGS, --expert slow) the previous file's, train_log.csv; with
# the runtime's capture-point controller as its expert (--expert quick) it is
# bench/results/train_log_make_train.csv (docs/policy.md)
# a make variable's value, continuation lines joined
make_var() {
    awk -v name="$1" 'index($0, name " ?=") == 1 { on = 1; $0 = substr($0, length(name) + 4) }
        on { more = sub(/\\$/, ""); printf "%s ", $0; if (!more) exit }' Makefile
}
args=$(make_var TRAIN_ARGS)
read -r members <<<"$(make_var TRAIN_MEMBERS)"
n=0
while read -r seed file log opts; do
    case "$seed" in '' | '#'*) continue ;; esac
    n=$((n + 1))
    log=bench/results/pinned/member$n/log.csv
    name="make train's member $n (seed $seed${opts:+ $opts}) reproduces its learning log on the portable path ($log, first 3 iterations)"
    check bash -c "/usr/bin/python3 policy/train/train.py $args --seed $seed $opts --threads 2 \
        --stop-after 3 --out $out/t$n.safetensors --log-dir $out/t$n >/dev/null 2>&1 </dev/null \
        && cmp -s <(cut -d, -f1-9 $out/t$n/log.csv) <(head -4 $log | cut -d, -f1-9)"
done <$members
name="TRAIN_MEMBERS ($members) lists members"
check test "$n" -ge 1
name="make train-clone's first stage reproduces the previous file's learning log (first 2 iterations)"
args=$(make_var TRAIN_CLONE_ARGS)
check bash -c "/usr/bin/python3 policy/train/train.py $args --threads 2 \
    --stop-after 2 --out $out/r.safetensors --log-dir $out/r >/dev/null 2>&1 \
    && cmp -s <(cut -d, -f1-9 $out/r/log.csv) <(head -3 bench/results/train_log.csv | cut -d, -f1-9)"
name="with the runtime's controller as the expert, the first stage's recorded log (2 iterations)"
check bash -c "/usr/bin/python3 policy/train/train.py $args --expert quick --threads 2 \
    --stop-after 2 --out $out/r2.safetensors --log-dir $out/r2 >/dev/null 2>&1 \
    && cmp -s <(cut -d, -f1-9 $out/r2/log.csv) <(head -3 bench/results/train_log_make_train.csv | cut -d, -f1-9)"
# held episodes (zero actions, 4 environments): the left knee's first
# observation (joint_pos, less the stance, after gravity and gyro) and each
# episode's end time; a fall fails the check
EPISODES_PY="
import sys; sys.path.insert(0, 'policy/train'); import numpy as np, psenv, contract as ct
knee = 6 + [j['name'] for j in ct.robot()['joints']].index('l_knee')
def run(harness_p, ramp=False):
    e = psenv.Env(4, 2, seed=3, episode_s=1.0, push_dv_max=0.06, dr=False, harness_p=harness_p,
                  ramp_start=ramp)
    first = e.reset()[:, knee].copy(); t = [None] * 4
    for _ in range(200):
        _, _, done, _, info = e.step(np.zeros((4, e.n_act), np.float32))
        for i in range(4):
            if done[i] and t[i] is None:
                assert info[i, 0] == 0, 'fell'
                t[i] = float(info[i, 2])
    e.close(); return first, t
"
name="held episodes (--harness-p 1) end later by the time held, free ones at episode_s"
check /usr/bin/python3 -c "$EPISODES_PY
free, held = run(0.0)[1], run(1.0)[1]
assert all(abs(x - 1.0) < 0.03 for x in free), free
assert all(1.2 <= x <= 3.03 for x in held) and len(set(held)) > 1, held
"
name="--ramp-start: held limp, the joints sag, the servo ramp brings them back, let go 1.2-2 s in"
check /usr/bin/python3 -c "$EPISODES_PY
still, _ = run(1.0); sag, ends = run(1.0, ramp=True)
assert np.abs(still).max() < 0.05 and np.abs(sag).min() > 0.1, (still, sag)
assert all(1.0 + 1.2 - 0.03 <= x <= 1.0 + 2.0 + 0.03 for x in ends) and len(set(ends)) > 1, ends
"
name="fine-tuning (--init) keeps the file's policy while only the critic learns, then moves it"
same_policy() { /usr/bin/python3 -c "
import sys, json, numpy as np; sys.path.insert(0, 'policy/train'); import psfile
a, ma = psfile.read_safetensors('$1'); b, mb = psfile.read_safetensors('$2')
o = lambda m: json.loads(m[psfile.CONTRACT_KEY])['observation']
sys.exit(0 if all(np.array_equal(a[k], b[k]) for k in a) and o(ma)['mean'] == o(mb)['mean']
         and np.allclose(o(ma)['std'], o(mb)['std'], rtol=1e-12) else 1)"; }
export -f same_policy
check bash -c "/usr/bin/python3 policy/train/train.py --envs 4 --threads 2 --steps 16 --bc-iters 0 \
    --ppo-iters 2 --critic-warmup 2 --init $out/p.safetensors --harness-p 0.5 --focus-p 0.5 \
    --out $out/f.safetensors --log-dir $out/f >/dev/null 2>&1 && same_policy $out/p.safetensors $out/f.safetensors \
    && /usr/bin/python3 policy/train/train.py --envs 4 --threads 2 --steps 16 --bc-iters 0 --ppo-iters 2 \
    --critic-warmup 0 --ppo-lr 1e-3 --init $out/p.safetensors --out $out/g.safetensors --log-dir $out/g \
    >/dev/null 2>&1 && ! same_policy $out/p.safetensors $out/g.safetensors"
name="--residual: base capture in the contract, the last layer moved from zero, the runtime runs it, --init wants --residual"
# a residual run's first policy is the capture-point controller (its last
# layer zero); after 2 PPO iterations at a high learning rate it is not
check bash -c "/usr/bin/python3 policy/train/train.py --envs 4 --threads 2 --steps 16 --bc-iters 0 \
    --ppo-iters 2 --ppo-lr 1e-3 --residual --out $out/res.safetensors --log-dir $out/res >/dev/null 2>&1 \
    && /usr/bin/python3 -c \"
import sys, json, numpy as np; sys.path.insert(0, 'policy/train'); import psfile
t, m = psfile.read_safetensors('$out/res.safetensors')
assert json.loads(m[psfile.CONTRACT_KEY])['action']['base'] == 'capture'
assert '--residual' in json.loads(m[psfile.CONTRACT_KEY])['trained_by']
assert np.abs(t['base.2.weight']).max() > 0\" \
    && ${PUSHSTEP_BIN:-build/pushstep} --lockstep --quiet --duration 3 --scenario scenarios/stand.yaml \
    --weights $out/res.safetensors --summary $out/rs.json >$out/rs.out 2>&1 \
    && grep -q 'a residual on capture' $out/rs.out \
    && ! /usr/bin/python3 policy/train/train.py --envs 4 --threads 2 --bc-iters 0 --ppo-iters 1 \
    --init $out/res.safetensors --out $out/res2.safetensors --log-dir $out/res2 >/dev/null 2>&1"
name="--obs-base-action: the observation ends with the controller's action of that step; the file says so and runs"
# the environment: the observation's tail is the expert output of the same
# step (auto-resets included), the rest the stage-1 layout; train.py: the
# contract lists base_action, the runtime runs the file (its builder puts
# the base there, tests/test_capture.c), refused without --residual and
# for an --init file of the other layout; eval.py runs the controller in an
# environment without the field whatever the file (one that fills it steps
# the controller once more at each reset), the file in one with its layout
check bash -c "/usr/bin/python3 -c \"
import sys; sys.path.insert(0, 'policy/train'); import numpy as np, psenv
plain = psenv.Env(4, 2, seed=3, episode_s=1.5, push_dv_max=0.4, dr=True)
based = psenv.Env(4, 2, seed=3, episode_s=1.5, push_dv_max=0.4, dr=True, obs_base_action=True)
n = plain.n_obs; assert based.n_obs == n + plain.n_act, (based.n_obs, n)
assert np.array_equal(plain.reset(), based.reset()[:, :n])
_, _, _, e, _ = based.step(np.zeros((4, plain.n_act), np.float32)); moved = 0.0; ends = 0
for k in range(150):
    o, _, d, e, _ = based.step(e)
    assert np.array_equal(o[:, n:], e), k
    moved = max(moved, float(np.abs(e).max())); ends += int(d.sum())
assert moved > 0.2 and ends > 0, (moved, ends)\" \
    && /usr/bin/python3 policy/train/train.py --envs 4 --threads 2 --steps 16 --bc-iters 0 \
    --ppo-iters 2 --ppo-lr 1e-3 --residual --obs-base-action --out $out/rb.safetensors \
    --log-dir $out/rb >/dev/null 2>&1 \
    && /usr/bin/python3 -c \"
import sys, json; sys.path.insert(0, 'policy/train'); import psfile
c = json.loads(psfile.read_safetensors('$out/rb.safetensors')[1][psfile.CONTRACT_KEY])
assert c['observation']['fields'][-1] == 'base_action' and len(c['observation']['mean']) == 89, c
assert '--obs-base-action' in c['trained_by']\" \
    && ${PUSHSTEP_BIN:-build/pushstep} --lockstep --quiet --duration 3 --scenario scenarios/stand.yaml \
    --weights $out/rb.safetensors --summary $out/rbs.json >$out/rbs.out 2>&1 \
    && grep -q 'a residual on capture' $out/rbs.out \
    && grep -Eq '\"policy_runs\":[[:space:]]*[1-9]' $out/rbs.json \
    && ! /usr/bin/python3 policy/train/train.py --envs 4 --threads 2 --bc-iters 0 --ppo-iters 1 \
    --obs-base-action --out $out/rb2.safetensors --log-dir $out/rb2 >$out/rb2.out 2>&1 \
    && grep -q 'give --residual' $out/rb2.out \
    && ! /usr/bin/python3 policy/train/train.py --envs 4 --threads 2 --bc-iters 0 --ppo-iters 1 \
    --residual --obs-base-action --init $out/res.safetensors --out $out/rb3.safetensors \
    --log-dir $out/rb3 >$out/rb3.out 2>&1 && grep -q 'are not this run' $out/rb3.out \
    && /usr/bin/python3 -c \"
import sys; sys.path.insert(0, 'policy/train'); import eval as ev, psenv
made = []
class Env(psenv.Env):
    def __init__(self, *a, **k):
        made.append(k.get('obs_base_action')); super().__init__(*a, **k)
ev.psenv.Env = Env
for f, want in (('rb', [False, True]), ('res', [False])):
    made.clear()
    sys.argv = ['eval.py', '--weights', '$out/' + f + '.safetensors', '--dv', '0.3',
                '--durations', '0.1', '--directions', '2']
    ev.main(); assert made == want, (f, made)\" >/dev/null 2>&1"
# n_steps rollout steps of one zero-residual policy (4 environments with
# domain randomisation, seeded) with the reward costs given, after a first
# step of zero actions; the buffer and that first step's info
COST_PY="
import sys; sys.path.insert(0, 'policy/train'); import numpy as np, torch, psenv, train
def run(n_steps, env_kw, **cost):
    torch.manual_seed(5)
    env = psenv.Env(4, 2, seed=7, dr=True, **env_kw)
    net = train.Policy(env.n_obs, env.n_act, [32, 32])
    with torch.no_grad():
        net.pi[-1].weight.zero_(); net.pi[-1].bias.zero_(); net.log_std.fill_(np.log(0.05))
    env.reset(); _, _, _, expert, info0 = env.step(np.zeros((4, env.n_act), np.float32))
    buf = train.rollout(env, net, train.RunningNorm(env.n_obs), env.obs.copy(), n_steps, 0.0,
                        expert, np.random.default_rng(1), residual=True, **cost)[0]
    return buf, info0"
# A residual's reward option: one iteration of train.py writes it into the
# contract's trained_by (WANT: text it must hold), and train.py refuses it
# without --residual. residual_option TAG "OPTIONS" "WANT"
residual_option() {
    /usr/bin/python3 policy/train/train.py --envs 4 --threads 2 --steps 16 --bc-iters 0 \
        --ppo-iters 1 --residual $2 --out $out/$1.safetensors --log-dir $out/$1 >/dev/null 2>&1 \
        && /usr/bin/python3 -c "
import sys, json; sys.path.insert(0, 'policy/train'); import psfile
c = json.loads(psfile.read_safetensors('$out/$1.safetensors')[1][psfile.CONTRACT_KEY])
assert '$3' in c['trained_by'], c" \
        && ! /usr/bin/python3 policy/train/train.py --envs 4 --threads 2 --bc-iters 0 \
        --ppo-iters 1 $2 --out $out/$1-nr.safetensors --log-dir $out/$1-nr >$out/$1-nr.out 2>&1 \
        && grep -q 'give --residual' $out/$1-nr.out
}
export -f residual_option; export out
name="--swing-cost: info flags the controller's swings; the cost is on the residual of the steps whose expert swings"
# two rollouts of one zero-residual policy (same seeds, so the same actions
# and states): their rewards differ by k x 0.25 rad x |residual| of the
# joints named, on exactly the steps whose expert action was taken in a
# swing (the flag of the step before); train.py writes the option into the
# contract and refuses it without --residual and for a joint not in the action
check bash -c "/usr/bin/python3 -c \"$COST_PY
env_kw = dict(episode_s=2.5, push_dv_max=0.6)
(b0, i0), (b1, _) = run(200, env_kw), run(200, env_kw, swing_cost=(2.0, [1, 7]))
assert np.array_equal(b0['act'], b1['act']) and np.array_equal(b0['info'], b1['info'])
flag = np.concatenate([i0[None, :, 8], b0['info'][:-1, :, 8]])
assert set(np.unique(flag)) == {0.0, 1.0} and flag.mean() < 0.5, flag.mean()
want = 2.0 * flag * 0.25 * np.abs(b0['act'][:, :, [1, 7]]).sum(-1)
assert np.allclose(b0['rew'] - b1['rew'], want, atol=1e-6) and want.max() > 0\" \
    && residual_option sw '--swing-cost 1' '--swing-cost 1 --swing-cost-joints l_hip_roll,r_hip_roll' \
    && ! /usr/bin/python3 policy/train/train.py --envs 4 --threads 2 --bc-iters 0 --ppo-iters 1 \
    --residual --swing-cost 1 --swing-cost-joints l_hip_rol --out $out/sw3.safetensors \
    --log-dir $out/sw3 >$out/sw3.out 2>&1 && grep -q 'l_hip_rol not among' $out/sw3.out"
name="--quiet-cost: info counts the seconds since the harness or a push; the cost is on the residual of the quiet steps"
# held environments (--harness-p 1): info[9] is -1 while held or pushed,
# else grows by the policy period (0.02 s) a step until the next push or
# episode; two rollouts of one zero-residual policy differ in reward by k x
# 0.25 rad x the residual of every joint on exactly the steps taken 1 s or
# more after the last disturbance with the expert not in a swing (the info
# of the step before); train.py writes the option into the contract and
# refuses it without --residual
check bash -c "/usr/bin/python3 -c \"$COST_PY
env_kw = dict(episode_s=4.0, push_dv_max=0.4, harness_p=1.0)
(b0, i0), (b1, _) = run(300, env_kw), run(300, env_kw, quiet_cost=(3.0, 1.0))
assert np.array_equal(b0['act'], b1['act']) and np.array_equal(b0['info'], b1['info'])
q = b0['info'][:, :, 9]
assert (q == -1.0).any() and q.max() > 1.0, q
grow = (q[1:] > 0) & (q[:-1] >= 0) & (b0['done'][:-1] == 0)
assert grow.sum() > 100 and np.allclose((q[1:] - q[:-1])[grow], 0.02, atol=1e-4)
prev = np.concatenate([i0[None], b0['info'][:-1]])
flag = (prev[:, :, 9] >= 1.0) & (prev[:, :, 8] == 0.0)
assert 0.1 < flag.mean() < 0.9, flag.mean()
want = 3.0 * flag * 0.25 * np.abs(b0['act']).sum(-1)
assert np.allclose(b0['rew'] - b1['rew'], want, atol=1e-6) and want.max() > 0\" \
    && residual_option qc '--quiet-cost 1 --quiet-after 0.5' '--quiet-cost 1 --quiet-after 0.5'"
name="--width-cost: info gives the feet's distance apart; the cost is on the steps that end wider than the target (or closer than --width-min)"
# info[10] is the horizontal distance between the feet bodies (the
# controller's stance: 0.16 m); two rollouts of one zero-residual policy
# differ in reward by k x (distance - target) where the step ends with the
# feet further apart than the target, the robot standing (before its first
# push, or 1 s or more after the last disturbance), the expert not in a
# swing and the episode going on (that step's own info), and with
# --width-min also by k x (min - distance) where it ends closer; train.py
# writes the options into the contract and refuses --width-cost without
# --residual, --width-min without --width-cost
check bash -c "/usr/bin/python3 -c \"$COST_PY
env_kw = dict(episode_s=2.5, push_dv_max=0.6)
(b0, i0), (b1, _) = run(200, env_kw), run(200, env_kw, width_cost=(2.0, 0.15, 0.0))
assert np.array_equal(b0['act'], b1['act']) and np.array_equal(b0['info'], b1['info'])
apart = b0['info'][:, :, 10]
assert abs(i0[0, 10] - 0.16) < 0.005 and apart.max() > 0.2, (i0[:, 10], apart.max())
i = b0['info']; q = i[:, :, 9]
standing = (q >= 1.0) | ((q < 0.0) & (i[:, :, 7] == 0))
assert 0.05 < standing.mean() < 0.95, standing.mean()
over = np.maximum(0.0, apart - 0.15) * (i[:, :, 8] == 0) * (b0['done'] == 0) * standing
assert np.allclose(b0['rew'] - b1['rew'], 2.0 * over, atol=1e-6) and (over > 0).sum() > 20, (over > 0).sum()
assert ((apart > 0.2) & ~standing).any(), 'a step (feet apart) while pushed costs nothing'
b2 = run(200, env_kw, width_cost=(2.0, 0.20, 0.17))[0]  # --width-min: closer than 0.17 m costs too
off = np.maximum(0.0, apart - 0.20) + np.maximum(0.0, 0.17 - apart)
on = (i[:, :, 8] == 0) * (b0['done'] == 0) * standing
assert np.allclose(b0['rew'] - b2['rew'], 2.0 * off * on, atol=1e-6)
assert ((apart < 0.17) & on).sum() > 20 and ((apart > 0.20) & on).sum() > 5, 'both sides'\" \
    && residual_option wc '--width-cost 1 --width-target 0.25' '--width-cost 1 --width-target 0.25' \
    && residual_option wm '--width-cost 1 --width-target 0.25 --width-min 0.1' '--width-target 0.25 --width-min 0.1' \
    && ! /usr/bin/python3 policy/train/train.py --ppo-iters 1 --bc-iters 0 --residual --width-min 0.1 \
    --out $out/wm2.safetensors --log-dir $out/wm2 >$out/wm2.out 2>&1 && grep -q 'width-min: with --width-cost' $out/wm2.out"
name="--stagger-cost: info gives the feet's offset along and across the heading; the cost is on standing steps staggered beyond the tolerance"
# info[11] and [12] are the left foot's offset from the right one along and
# across the floating base's heading (the controller's stance: 0 and 0.16
# m), together as long as info[10]'s distance; two rollouts of one
# zero-residual policy differ in reward by k x (|stagger| - tolerance) on
# exactly the steps the width cost weighs (train.stands_still) that end
# staggered beyond it; train.py writes the option into the contract and
# refuses it without --residual
check bash -c "/usr/bin/python3 -c \"$COST_PY
env_kw = dict(episode_s=2.5, push_dv_max=0.6)
(b0, i0), (b1, _) = run(200, env_kw), run(200, env_kw, stagger_cost=(2.0, 0.02))
assert np.array_equal(b0['act'], b1['act']) and np.array_equal(b0['info'], b1['info'])
i = b0['info']; K = psenv.INFO_KEYS.index
st, lat = i[:, :, K('feet_stagger_m')], i[:, :, K('feet_lateral_m')]
assert (np.abs(i0[:, 11]) < 0.005).all() and (np.abs(i0[:, 12] - 0.16) < 0.005).all(), i0[:, 11:13]
assert np.allclose(np.hypot(st, lat), i[:, :, 10], atol=1e-5) and np.abs(st).max() > 0.1
q = i[:, :, 9]
standing = (q >= 1.0) | ((q < 0.0) & (i[:, :, 7] == 0))
over = np.maximum(0.0, np.abs(st) - 0.02) * (i[:, :, 8] == 0) * (b0['done'] == 0) * standing
assert np.array_equal(over > 0, (np.abs(st) > 0.02) & (train.stands_still(i.reshape(-1, i.shape[-1]), b0['done'].ravel()).reshape(st.shape) > 0))
assert np.allclose(b0['rew'] - b1['rew'], 2.0 * over, atol=1e-6) and (over > 0).sum() > 10, (over > 0).sum()\" \
    && residual_option sc '--stagger-cost 1 --stagger-tol 0.04' '--stagger-cost 1 --stagger-tol 0.04'"
name="--priv-critic: info carries the plant's privileged state; the critic sees it after the observation, the policy file does not"
# held environments with domain randomisation: the harness flag is 1 exactly
# while held (quiet_s -1 and no push yet), a push acts exactly while it is
# pushing (quiet_s -1, not held) with |force| / weight x g x duration = its
# delta-v (info[3]) for a duration of 0.1 or 0.3 s, the episode's draws lie
# in their ranges and stay put within an episode, the feet carry the weight
# when the robot stands free, not while it hangs in the harness; a rollout's critic input is the observation followed by
# the normalised privileged state and its values are the critic's on it;
# train.py writes the option into trained_by and a file of the actor alone
check bash -c "/usr/bin/python3 -c \"
import sys; sys.path.insert(0, 'policy/train'); import numpy as np, torch, psenv, train
K = psenv.PRIV_KEYS; P = lambda k: psenv.PRIV.start + K.index(k)
env = psenv.Env(4, 2, seed=7, dr=True, episode_s=2.5, push_dv_max=0.6, harness_p=1.0)
torch.manual_seed(5)
net = train.Policy(env.n_obs, env.n_act, [32, 32], len(K))
env.reset(); _, _, _, expert, _ = env.step(np.zeros((4, env.n_act), np.float32))
npriv = train.RunningNorm(len(K))
buf = train.rollout(env, net, train.RunningNorm(env.n_obs), env.obs.copy(), 300, 0.0, expert,
                    np.random.default_rng(1), residual=True, norm_priv=npriv)[0]
i = np.concatenate([buf['info'][:, e] for e in range(4)])
# a step that ends an episode has the new one's quiet_s and privileged state
i = i[np.concatenate([buf['done'][:, e] for e in range(4)]) == 0]
held, q, left = i[:, P('held')], i[:, 9], i[:, P('push_left_s')]
assert set(np.unique(held)) == {0.0, 1.0}, np.unique(held)
assert np.array_equal(held == 1, (q < 0) & (i[:, 7] == 0)), 'held'
pushing = (q < 0) & (held == 0)
assert pushing.sum() > 10 and np.array_equal(left > 0, pushing), 'push timing'
dv = np.hypot(i[:, P('push_x')], i[:, P('push_y')]) * 9.81
ok = np.isclose(dv * 0.1, i[:, 3], rtol=1e-3) | np.isclose(dv * 0.3, i[:, 3], rtol=1e-3)
assert ok[pushing].all() and (dv[~pushing] == 0).all(), 'push force'
for k, lo, hi in (('friction', 0.6, 1.4), ('strength', 0.85, 1.15), ('latency_ms', 0, 2),
                  ('torso_mass', 0.9, 1.1), ('pelvis_mass', 0.9, 1.1)):
    v = buf['info'][:, :, P(k)]
    assert (v >= lo).all() and (v <= hi).all() and len(np.unique(v)) > 1, k
    same = buf['done'][1:] == 0  # step t's state is the episode of step t + 1's
    assert (v[1:] == v[:-1])[same].all(), k + ' moved within an episode'
w = i[:, P('force_l')] + i[:, P('force_r')]
assert np.median(w[held == 1]) < 0.2 and abs(np.median(w[q > 1.0]) - 1.0) < 0.1, 'weight'
c, o = buf['cobs'], buf['obs']
assert c.shape[-1] == env.n_obs + len(K) and np.array_equal(c[..., :env.n_obs], o)
assert np.allclose(c[-1, :, env.n_obs:], npriv(buf['info'][-2][:, psenv.PRIV]), atol=1e-6)
with torch.no_grad():
    v = net.v(torch.from_numpy(c[5])).squeeze(-1).numpy()
assert np.allclose(v, buf['val'][5], atol=1e-6)\" \
    && /usr/bin/python3 policy/train/train.py --envs 4 --threads 2 --steps 16 --bc-iters 0 \
    --ppo-iters 2 --residual --priv-critic --out $out/pc.safetensors --log-dir $out/pc \
    >/dev/null 2>&1 && /usr/bin/python3 -c \"
import sys, json; sys.path.insert(0, 'policy/train'); import psfile
t, m = psfile.read_safetensors('$out/pc.safetensors')
c = json.loads(m[psfile.CONTRACT_KEY])
assert '--priv-critic' in c['trained_by'] and t['base.0.weight'].shape[1] == len(c['observation']['mean'])\""
name="psenv refuses a libpsenv whose info size is not the one its keys name"
check /usr/bin/python3 -c "
import sys; sys.path.insert(0, 'policy/train'); import psenv
assert psenv.Env(2, 1).info.shape == (2, psenv.INFO)
psenv.INFO -= 1
try:
    psenv.Env(2, 1)
except RuntimeError as e:
    assert 'rebuild' in str(e), e
else:
    raise AssertionError('a stale library was accepted')
"
name="GAE: a time-limit cut bootstraps from the state's value, a fall does not (--bootstrap-timeouts)"
# one environment, 2 steps, reward 1, values 10 and 20, both episodes end at
# step 0: a fall (info[0] = 1) gives delta = 1 - 10; a cut gives
# 1 + 0.5 * 10 - 10 with gamma 0.5; without the option a cut is a fall
check /usr/bin/python3 -c "
import sys; sys.path.insert(0, 'policy/train'); import numpy as np, train
def adv0(fell, boot):
    info = np.zeros((2, 1, 8), np.float32); info[0, 0, 0] = fell; info[0, 0, 1] = 1
    buf = {'rew': np.ones((2, 1), np.float32), 'done': np.array([[1], [0]]),
           'val': np.array([[10], [20]], np.float32), 'info': info}
    return float(train.gae(buf, np.array([0], np.float32), 0.5, 0.9, boot)[0][0, 0])
assert adv0(1, True) == -9.0 and adv0(0, False) == -9.0, (adv0(1, True), adv0(0, False))
assert adv0(0, True) == -4.0, adv0(0, True)
"
name="--stair-p: each direction's delta-v steps down after a fall, up after a push withstood"
# a stand-in environment records the pushes set; info rows as psenv's:
# [0] fell, [1] ended, [7] pushes so far
check /usr/bin/python3 -c "
import sys; sys.path.insert(0, 'policy/train'); import numpy as np, train
class Env:
    n = 2
    def __init__(self): self.set = []
    def set_push(self, i, t_s, dur_s, dv, direction): self.set.append((i, t_s, dur_s, dv, direction))
def ended(i, fell, pushes):
    info = np.zeros((2, 8), np.float32); info[i, :2] = (fell, 1); info[i, 7] = pushes
    return info
env = Env(); st = train.Staircase(env, 1.0, 0.1, 0.5, np.random.default_rng(1))
for i, t_s, dur_s, dv, d in env.set:
    assert 0.8 <= t_s <= 2.0 and dur_s in (0.1, 0.3) and abs(dv - 0.5) <= 0.05, env.set
k, j = st.queued[0]; w = 2 * np.pi / 16
assert abs(env.set[0][4] - k * w) <= w / 2 and env.set[0][2] == (0.1, 0.3)[j], (env.set[0], k, j)
first = list(st.queued); st.started()
assert st.running == first and len(env.set) == 4
a = st.running[0]; st.observe(ended(0, 1, 1))          # fell after the push: down
assert abs(st.dv[a] - 0.4) < 1e-9 and st.n[a] == 1 and st.fell[a] == 1, st.dv[a]
b = st.running[1]; before = st.dv[b]; st.observe(ended(1, 0, 1))  # withstood: up
assert abs(st.dv[b] - before - 0.1) < 1e-9 and st.n[b] == (1 if b != a else 2)
c = st.running[0]; before = st.dv[c]; st.observe(ended(0, 1, 0))  # fell before its push: kept
assert st.dv[c] == before and st.n.sum() == 2 and len(env.set) == 7
random = train.Staircase(Env(), 0.0, 0.1, 0.5, np.random.default_rng(1))
assert random.queued == [None, None] and all(s[2] == 0.0 for s in random.env.set)
"
name="eval.py runs the benchmark's pushes in the training environment"
check bash -c "/usr/bin/python3 policy/train/eval.py --weights $out/p.safetensors --dv 0.15 \
    --durations 0.1 --directions 2 --harness --out $out/e.json >$out/eval.out 2>&1 \
    && grep -q '\"controller\": \"mlp\"' $out/e.json"
name="eval.py --zero-residual: those joints get the controller's targets, the rest the policy's"
# on the residual file above: all 12 joints zeroed is the controller itself,
# one zeroed differs from the full policy there only; names are checked
check bash -c "/usr/bin/python3 -c \"
import sys, numpy as np; sys.path.insert(0, 'policy/train'); import eval as ev
full = ev.Mlp('$out/res.safetensors'); joints = full.c['action']['joints']
rng = np.random.default_rng(5); obs = rng.normal(size=(4, full.mean.size)).astype(np.float32)
expert = rng.normal(size=(4, len(joints))).astype(np.float32)
assert np.array_equal(ev.Mlp('$out/res.safetensors', joints)(obs, expert), expert)
one = ev.Mlp('$out/res.safetensors', ['l_hip_roll'])(obs, expert); k = joints.index('l_hip_roll')
want = full(obs, expert); assert not np.array_equal(want[:, k], expert[:, k])
want[:, k] = expert[:, k]; assert np.array_equal(one, want)\" \
    && /usr/bin/python3 policy/train/eval.py --weights $out/res.safetensors --dv 0.15 --durations 0.1 \
    --directions 2 --dr --only-dir-deg 90 --zero-residual l_hip_roll,r_hip_roll --out $out/z.json >/dev/null 2>&1 \
    && /usr/bin/python3 -c \"
import json; d = json.load(open('$out/z.json'))
assert d['zero_residual'] == ['l_hip_roll', 'r_hip_roll'] and d['dr'] is True, d
assert all(c['direction_deg'] == [90.0, 90.0] for c in d['cells']), d['cells']\" \
    && ! /usr/bin/python3 policy/train/eval.py --weights $out/res.safetensors --directions 2 \
    --zero-residual l_hip_rol >$out/zr.out 2>&1 && grep -q 'l_hip_rol is not one of' $out/zr.out \
    && ! /usr/bin/python3 policy/train/eval.py --weights $out/p.safetensors --directions 2 \
    --zero-residual l_hip_roll >$out/zp.out 2>&1 && grep -q 'not a residual policy' $out/zp.out \
    && ! /usr/bin/python3 policy/train/eval.py --directions 2 --dr --runtime bench/results/push.json \
    >$out/zd.out 2>&1 && grep -q 'not with --dr or --only-dir-deg' $out/zd.out"
# the whole scene (20 s, let go at 2 s): a policy that shuffles can fall
# seconds after it was let go with no push at all (r18: at 7.6 s)
name="the shipped policy (policy/weights/ps1_stage1.safetensors) stands through scenarios/stand.yaml in lockstep, contract checked"
check bash -c "${PUSHSTEP_BIN:-build/pushstep} --lockstep --quiet --scenario scenarios/stand.yaml \
    --policy mlp --weights policy/weights/ps1_stage1.safetensors --summary $out/shipped.json \
    >$out/run.out 2>&1 && grep -Eq '\"fall_detected\":[[:space:]]*false' $out/shipped.json \
    && grep -Eq '\"fell_while_active\":[[:space:]]*false' $out/shipped.json \
    && grep -Eq '\"policy_runs\":[[:space:]]*[1-9]' $out/shipped.json"
[ $fail -gt 0 ] && { cat "$out/train.out" "$out/run.out" 2>/dev/null | tail -20; }
echo "[  PASSED  ] $pass test(s)."
[ $fail -gt 0 ] && echo "[  FAILED  ] $fail test(s), listed below:"
[ $fail -eq 0 ]

#!/usr/bin/python3
"""Train ps1's stage-1 balance/stepping policy (docs/policy.md).

The environment is the C one (tools/psenv, build/libpsenv.so: the MuJoCo
plant, the emulated drives, the estimator and the observation builder of
the runtime, batched over --threads cores). Two phases, seeded:

  1. behaviour cloning of the capture-point controller (policy/ps_capture,
     computed inside the environment) with DAgger: the student acts with
     probability growing from 0 to 1, the expert labels every state it
     visits. Push-and-Step imitates motion capture, which we do not have;
     the expert plays that role (a starting point that already steps).
  2. PPO on Push-and-Step's reward (balance + quality, tools/psenv/ps_env.h)
     from the cloned policy, with a behaviour-cloning term that decays.

With --init FILE a run fine-tunes a policy file instead (no cloning; its
observation normalisation is kept as it is; the critic, which the file does
not hold, first learns alone for --critic-warmup iterations); with
--harness-p, --push-dv-min and --focus-p its episodes can start held by the
harness as the runtime's do, and its pushes can be harder or come more often
from one side (docs/policy.md).

With --residual the policy is a residual on the capture-point controller
(the contract's action.base "capture"; the runtime adds the two the same
way, policy/ps_mlp_policy.h): the network starts at zero, i.e. at the
controller, and PPO starts there with no cloning.

Observations are normalised by running mean and standard deviation, which
go into the policy file's contract, so the runtime's observation builder
normalises exactly as here. One torch thread (a measured probe found two
slower than one here: docs/policy.md).

Writes --out (safetensors with the contract), --log-dir/log.csv (one line
per iteration), --log-dir/curves.png (gnuplot, when installed).
"""
import argparse
import csv
import json
import os
import shutil
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import portable  # noqa: E402

# The same floats on every x86-64 machine (policy/train/portable.py): before numpy
# and torch load, the script re-executes itself once with the portable BLAS,
# libm and ATen kernels. Not when imported as a module.
FLOAT_PATH = portable.pin() if __name__ == "__main__" else (False, "as a module")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from tqdm import tqdm  # noqa: E402

import contract as ct  # noqa: E402
import psenv  # noqa: E402
import psfile  # noqa: E402

OBS_CLIP = 10.0


class RunningNorm:
    def __init__(self, n):
        self.n = 0
        self.mean = np.zeros(n)
        self.m2 = np.zeros(n)

    def update(self, x):
        for row in np.asarray(x, np.float64).reshape(-1, self.mean.size):
            self.n += 1
            d = row - self.mean
            self.mean += d / self.n
            self.m2 += d * (row - self.mean)

    def std(self):
        s = np.sqrt(self.m2 / max(self.n - 1, 1))
        return np.maximum(s, 1e-2)  # a constant input (contact, ...) keeps a sane scale

    def __call__(self, x):
        return np.clip((x - self.mean) / self.std(), -OBS_CLIP, OBS_CLIP).astype(np.float32)


class Policy(torch.nn.Module):
    def __init__(self, n_obs, n_act, hidden, n_priv=0):
        """n_priv: the critic sees this many privileged inputs after the
        observation (--priv-critic); the actor never does."""
        super().__init__()
        layers, a = [], n_obs
        for h in hidden:
            layers += [torch.nn.Linear(a, h), torch.nn.ELU()]
            a = h
        self.pi = torch.nn.Sequential(*layers, torch.nn.Linear(a, n_act))
        layers, a = [], n_obs + n_priv
        for h in hidden:
            layers += [torch.nn.Linear(a, h), torch.nn.ELU()]
            a = h
        self.v = torch.nn.Sequential(*layers, torch.nn.Linear(a, 1))
        self.log_std = torch.nn.Parameter(torch.full((n_act,), -2.3))
        with torch.no_grad():
            self.pi[-1].weight.mul_(0.1)

    def dist(self, obs):
        return torch.distributions.Normal(self.pi(obs), self.log_std.exp())

    def linears(self):
        return [m for m in self.pi if isinstance(m, torch.nn.Linear)]


def load_init(path, net, norm, hidden, fields):
    """The actor's layers and the observation normalisation of a policy file
    observing fields; returns its contract."""
    t, meta = psfile.read_safetensors(path)
    c = json.loads(meta[psfile.CONTRACT_KEY])
    if any(g != 1 for g in c.get("groups", [])):
        raise SystemExit("--init %s: has grouped layers (an ensemble, policy/train/ensemble.py): "
                         "fine-tune one of its members" % path)
    if c["observation"]["fields"] != fields:
        raise SystemExit("--init %s: its observation fields (%s) are not this run's (%s)" % (
            path, ", ".join(c["observation"]["fields"]), ", ".join(fields)))
    lin = net.linears()
    if len(lin) != len(hidden) + 1:
        raise SystemExit("--init: --hidden does not match")
    with torch.no_grad():
        for k, m in enumerate(lin):
            w, b = t["base.%d.weight" % k], t["base.%d.bias" % k]
            if tuple(w.shape) != tuple(m.weight.shape):
                raise SystemExit("--init %s: layer %d is %s, this network's %s"
                                 % (path, k, w.shape, tuple(m.weight.shape)))
            m.weight.copy_(torch.from_numpy(w.copy()))
            m.bias.copy_(torch.from_numpy(b.copy()))
    o = c["observation"]
    norm.n = 1 << 30  # only for std(): the statistics stay as the file has them
    norm.mean = np.asarray(o["mean"], np.float64)
    norm.m2 = np.asarray(o["std"], np.float64) ** 2 * (norm.n - 1)
    return c


def save(path, net, norm, doc, hidden, trained_by, residual=False, fields=None):
    c = ct.contract(doc, mean=norm.mean, std=norm.std(), trained_by=trained_by, fields=fields)
    if residual:
        c["action"]["base"] = "capture"
    c["observation"]["clip"] = OBS_CLIP
    c["activations"] = ["elu"] * len(hidden) + ["identity"]
    layers = [(m.weight.detach().numpy(), m.bias.detach().numpy()) for m in net.linears()]
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    psfile.write_policy(path, layers, c)


def plot(log_csv, png):
    if shutil.which("gnuplot") is None:
        return False
    script = ("set terminal png size 900,600; set output '%s'; set datafile separator ',';"
              "set key autotitle columnhead; set xlabel 'environment steps';"
              "set multiplot layout 2,1;"
              "plot '%s' using 2:4 with lines title 'mean reward per step';"
              "plot '%s' using 2:5 with lines title 'falls per episode', "
              "'' using 2:7 with lines title 'r_balance';"
              "unset multiplot" % (png, log_csv, log_csv))
    return subprocess.run(["gnuplot", "-e", script]).returncode == 0


STANDING_AFTER_S = 1.0  # --width-cost: a robot undisturbed this long stands


def residual_rad(a, idx=slice(None)):
    """Per environment, the sum of |residual target| in radians over the
    action joints idx (all by default): the swing and quiet costs' measure."""
    return ct.ACTION_SCALE * np.abs(a[:, idx]).sum(axis=1)


def stands_still(info, done):
    """Per environment, 1 where the step ended with the robot standing (before
    its first push, or STANDING_AFTER_S or more after the last disturbance),
    the expert not stepping and the episode going on, else 0: the steps the
    stance costs (--width-cost, --stagger-cost) weigh."""
    stepping = info[:, psenv.INFO_KEYS.index("expert_swing")]
    q = info[:, psenv.INFO_KEYS.index("quiet_s")]
    before_push = (q < 0.0) & (info[:, psenv.INFO_KEYS.index("pushes")] == 0)
    standing = (q >= STANDING_AFTER_S) | before_push  # not pushed or recovering
    return standing * (stepping == 0.0) * (done == 0)


def critic_input(o, env, norm_priv, update_norm):
    """The critic's input for the observations o (normalised) of env's last
    step: o alone, or with norm_priv (--priv-critic) o followed by the
    privileged state of the same states (the info's psenv.PRIV part, which
    follows the new observation as the swing flag does), normalised."""
    if norm_priv is None:
        return o
    p = env.info[:, psenv.PRIV]
    if update_norm:
        norm_priv.update(p)
    return np.concatenate([o, norm_priv(p)], axis=1)


def rollout(env, net, norm, obs, n_steps, beta_expert, expert, rng, update_norm=True,
            explore=True, dart_std=0.0, stair=None, residual=False, swing_cost=None,
            quiet_cost=None, width_cost=None, stagger_cost=None, norm_priv=None):
    """n_steps of every environment. beta_expert: probability that an
    environment follows the expert this step (DAgger). swing_cost (k, joint
    indices): a residual's cost, k per radian of those joints' residual
    targets, on the steps whose expert action is part of a step. quiet_cost
    (k, s): a residual's cost, k per radian of every joint's residual
    target, on the steps taken s seconds or more after the robot was last
    disturbed (the harness, a push) whose expert action is not a step's.
    width_cost (k, m, n): k per metre the feet stand further apart than m or
    closer than n
    (horizontal distance between the feet bodies), on the steps that end
    with the robot standing (before its first push, or STANDING_AFTER_S or
    more after the last disturbance) and the expert not stepping.
    stagger_cost (k, m): k per metre the feet stand further than m apart
    along the floating base's heading, on the same steps. norm_priv:
    the critic also sees the privileged state (critic_input); its statistics
    always learn (the critic is not in the policy file: a fine-tuning run's
    critic starts new too)."""
    n = env.n
    buf = {k: [] for k in ("obs", "raw", "act", "logp", "rew", "done", "val", "expert", "info",
                           "cobs")}
    for _ in range(n_steps):
        if update_norm:
            norm.update(obs)
        o = norm(obs)
        c = critic_input(o, env, norm_priv, True)
        with torch.no_grad():
            t = torch.from_numpy(o)
            d = net.dist(t)
            # DAgger visits the states of the learner's own (mean) actions;
            # PPO explores around them
            a = d.sample() if explore else d.mean
            logp = d.log_prob(a).sum(-1)
            v = net.v(torch.from_numpy(c)).squeeze(-1)
        a = a.numpy()
        if beta_expert > 0.0:
            use = rng.random(n) < beta_expert
            a[use] = expert[use]
        if dart_std > 0.0:
            # DART: the executed action is perturbed (the labels are not), so
            # the data set holds the states a noisy action leads to, the
            # previous-action input included; without it the clone copies
            # its previous action and integrates PPO's exploration noise
            a = a + dart_std * rng.standard_normal(a.shape).astype(np.float32)
        # the expert's swing flag belongs to the state the expert acted on: the
        # last step's info (psenv.INFO_KEYS), read before this step replaces it
        swing = env.info[:, psenv.INFO_KEYS.index("expert_swing")].copy()
        quiet_s = env.info[:, psenv.INFO_KEYS.index("quiet_s")].copy()
        # a residual policy's action is added to the expert's (both in action units)
        obs2, rew, done, expert2, info = env.step(a + expert if residual else a)
        if swing_cost is not None:
            k, idx = swing_cost
            rew = (rew - k * swing * residual_rad(a, idx)).astype(np.float32)
        if quiet_cost is not None:
            k, after_s = quiet_cost
            quiet = (quiet_s >= after_s) & (swing == 0.0)
            rew = (rew - k * quiet * residual_rad(a)).astype(np.float32)
        if width_cost is not None:
            k, target_m, min_m = width_cost
            apart = info[:, psenv.INFO_KEYS.index("feet_apart_m")]
            off = np.maximum(0.0, apart - target_m) + np.maximum(0.0, min_m - apart)
            over = off * stands_still(info, done)
            rew = (rew - k * over).astype(np.float32)
        if stagger_cost is not None:
            k, tol_m = stagger_cost
            stagger = np.abs(info[:, psenv.INFO_KEYS.index("feet_stagger_m")])
            over = np.maximum(0.0, stagger - tol_m) * stands_still(info, done)
            rew = (rew - k * over).astype(np.float32)
        if stair is not None:
            stair.observe(info)
        buf["obs"].append(o)
        buf["raw"].append(obs)
        buf["act"].append(a)
        buf["logp"].append(logp.numpy())
        buf["rew"].append(rew)
        buf["done"].append(done)
        buf["val"].append(v.numpy())
        buf["expert"].append(np.zeros_like(expert) if residual else expert)
        buf["info"].append(info)
        buf["cobs"].append(c)
        obs, expert = obs2, expert2
    with torch.no_grad():
        c = critic_input(norm(obs), env, norm_priv, False)
        last_v = net.v(torch.from_numpy(c)).squeeze(-1).numpy()
    return {k: np.asarray(v) for k, v in buf.items()}, obs, expert, last_v


def gae(buf, last_v, gamma, lam, bootstrap_timeouts=False):
    """Advantages and returns. An episode that ends without a fall is cut by
    the time limit, not ended by the robot: with bootstrap_timeouts its last
    step bootstraps from that state's own value (the environment resets
    before the next observation is seen), instead of counting the lost
    future like a fall's."""
    rew, done, val = buf["rew"], buf["done"].astype(np.float32), buf["val"]
    timeout = np.zeros_like(done)
    if bootstrap_timeouts:
        timeout = done * (1.0 - buf["info"][..., 0].astype(np.float32))
    adv = np.zeros_like(rew)
    g = np.zeros(rew.shape[1], np.float32)
    for t in reversed(range(rew.shape[0])):
        nv = last_v if t == rew.shape[0] - 1 else val[t + 1]
        nv = (1 - done[t]) * nv + timeout[t] * val[t]
        delta = rew[t] + gamma * nv - val[t]
        g = delta + gamma * lam * (1 - done[t]) * g
        adv[t] = g
    return adv, adv + val


class Staircase:
    """Per-direction push sampling (--stair-p): each of N_DIR directions and
    both durations keeps its own delta-v, one step up after a push the robot
    withstood, one step down after a fall, so it settles where half of them
    fall (that direction's dv50 in training) and the pushes a direction
    handles worst come at its own edge instead of the whole circle's.

    An episode's push is set for the environment's episode after next (the C
    environment has begun the next one when it reports an end), so each
    environment holds the push of its running episode and of the one queued."""
    N_DIR = 16
    DURS = (0.1, 0.3)

    def __init__(self, env, p, step, dv0, rng):
        self.env, self.p, self.step, self.rng = env, p, step, rng
        self.dv = np.full((self.N_DIR, len(self.DURS)), dv0)
        self.n = np.zeros((self.N_DIR, len(self.DURS)), np.int64)
        self.fell = np.zeros_like(self.n)
        self.running = [None] * env.n
        self.queued = [self._queue(i) for i in range(env.n)]

    def _queue(self, i):
        """Set environment i's next push: a staircase one with probability p
        (direction bin k, duration j), else a random one (None)."""
        if self.rng.random() >= self.p:
            self.env.set_push(i, 0.0, 0.0, 0.0, 0.0)
            return None
        k, j = int(self.rng.integers(self.N_DIR)), int(self.rng.integers(len(self.DURS)))
        width = 2.0 * np.pi / self.N_DIR
        direction = k * width + self.rng.uniform(-0.5, 0.5) * width
        dv = max(0.05, self.dv[k, j] + self.rng.uniform(-0.5, 0.5) * self.step)
        self.env.set_push(i, float(self.rng.uniform(0.8, 2.0)), self.DURS[j], float(dv),
                          float(direction))
        return (k, j)

    def started(self):
        """After env.reset(): the queued pushes are running; queue the next."""
        self.running = self.queued
        self.queued = [self._queue(i) for i in range(self.env.n)]

    def observe(self, info):
        """One step's info of every environment (psenv.INFO_KEYS)."""
        for i in np.flatnonzero(info[:, 1] > 0):
            kj = self.running[i]
            # a fall before the push (released from the harness badly) says
            # nothing about the push
            if kj is not None and info[i, 7] >= 1:
                fell = info[i, 0] > 0
                self.n[kj] += 1
                self.fell[kj] += int(fell)
                self.dv[kj] = float(np.clip(self.dv[kj] + (-self.step if fell else self.step),
                                            0.05, 1.2))
            self.running[i] = self.queued[i]
            self.queued[i] = self._queue(i)

    def write(self, path):
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["force_dir_deg", "dur_s", "dv_m_s", "pushes", "falls"])
            for k in range(self.N_DIR):
                for j, d in enumerate(self.DURS):
                    w.writerow(["%.1f" % (360.0 * k / self.N_DIR), d, "%.3f" % self.dv[k, j],
                                self.n[k, j], self.fell[k, j]])


def stats(buf):
    info = buf["info"]
    ended = info[..., 1].sum()
    return {"rew": float(buf["rew"].mean()), "falls_per_ep": float(info[..., 0].sum() / max(ended, 1)),
            "ep_len_s": float(info[..., 2][info[..., 1] > 0].mean()) if ended else 0.0,
            "r_bal": float(info[..., 4].mean()), "r_q": float(info[..., 5].mean())}


def residual_cost(is_residual, name, k, param_name, param, param_ok, param_rule):
    """(k, param) of a residual's reward option --NAME-cost k --NAME-PARAM_NAME
    param, None when k is 0; exits naming the rule a bad pair breaks."""
    if k == 0.0:
        return None
    if not is_residual or k < 0.0 or not param_ok:
        raise SystemExit("--%s-cost: a cost (>= 0) on a residual (give --residual), --%s-%s %s"
                         % (name, name, param_name, param_rule))
    return (k, param)


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--envs", type=int, default=16)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--steps", type=int, default=64, help="steps per environment per iteration")
    ap.add_argument("--bc-iters", type=int, default=100)
    ap.add_argument("--ppo-iters", type=int, default=600)
    ap.add_argument("--hidden", default="128,128")
    ap.add_argument("--lr", type=float, default=3e-4)
    ap.add_argument("--dart-std", type=float, default=0.0,
                    help="noise on the executed actions while cloning (action units; "
                         "0.03 already makes the expert fall 5 times as often)")
    ap.add_argument("--ppo-lr", type=float, default=3e-5, help="PPO's actor learning rate")
    ap.add_argument("--target-kl", type=float, default=0.01,
                    help="PPO stops an iteration's epochs past this mean KL estimate")
    ap.add_argument("--ppo-std", type=float, default=0.02,
                    help="PPO's initial action standard deviation (action units)")
    ap.add_argument("--push-dv-max", type=float, default=0.8,
                    help="largest push at the end of the curriculum (m/s)")
    ap.add_argument("--push-dv-start", type=float, default=0.3,
                    help="largest push while cloning and at PPO's start; grows linearly "
                         "over 70 %% of the PPO iterations")
    ap.add_argument("--out", default=os.path.join(HERE, "..", "weights", "ps1_stage1.safetensors"))
    ap.add_argument("--log-dir", default=os.path.join(psenv.ROOT, "build", "train"))
    ap.add_argument("--no-dr", action="store_true", help="no domain randomisation")
    ap.add_argument("--stop-after", type=int, default=0,
                    help="stop after this many iterations (tests: the schedule stays "
                         "that of --bc-iters and --ppo-iters)")
    ap.add_argument("--init", help="fine-tune this policy file (with --bc-iters 0)")
    ap.add_argument("--critic-warmup", type=int, default=20,
                    help="with --init: PPO iterations in which only the critic learns")
    ap.add_argument("--bc-weight", type=float, default=0.5,
                    help="PPO's behaviour-cloning term's weight at its start (decays to 0 "
                         "over half of the PPO iterations)")
    ap.add_argument("--gamma", type=float, default=0.99, help="discount per policy step")
    ap.add_argument("--gae-lambda", type=float, default=0.95)
    ap.add_argument("--fixed-std", action="store_true",
                    help="PPO's action standard deviation stays at --ppo-std")
    ap.add_argument("--bootstrap-timeouts", action="store_true",
                    help="an episode cut by the time limit bootstraps from its last "
                         "state's value instead of ending like a fall")
    ap.add_argument("--push-dv-min", type=float, default=0.05, help="smallest push (m/s)")
    ap.add_argument("--harness-p", type=float, default=0.0,
                    help="fraction of episodes that start held by the harness, released "
                         "at a random time in [0.2, 2] s as in the runtime")
    ap.add_argument("--focus-p", type=float, default=0.0,
                    help="fraction of pushes from --focus-dir-deg +-45 deg")
    ap.add_argument("--focus-dir-deg", type=float, default=180.0,
                    help="direction of the focused pushes' force (0 = +x, forward)")
    ap.add_argument("--stair-p", type=float, default=0.0,
                    help="fraction of episodes whose one push comes from a per-direction "
                         "staircase (16 directions x 0.1/0.3 s, delta-v up a step after a "
                         "push withstood, down after a fall); log-dir/stair.csv has the levels")
    ap.add_argument("--stair-step", type=float, default=0.02, help="staircase step (m/s)")
    ap.add_argument("--stair-dv0", type=float, default=0.4,
                    help="staircase starting delta-v (m/s)")
    ap.add_argument("--ramp-start", action="store_true",
                    help="a harnessed episode (--harness-p) starts as the runtime's trials: "
                         "limp in the harness, then the servo layer's ramp to the policy's "
                         "targets over ramp_s, let go 0.2-1 s after")
    ap.add_argument("--residual", action="store_true",
                    help="the policy's action is added to the expert's (the runtime's "
                         "capture-point controller, --expert quick): PPO from a zero residual, "
                         "no cloning (--bc-iters 0); the cloning term pulls toward zero")
    ap.add_argument("--swing-cost", type=float, default=0.0,
                    help="with --residual: a cost, this much reward per radian, on the "
                         "residual's targets of --swing-cost-joints while the capture-point "
                         "controller swings a foot (its step is left to it)")
    ap.add_argument("--swing-cost-joints", default="l_hip_roll,r_hip_roll",
                    help="the action joints --swing-cost applies to")
    ap.add_argument("--quiet-cost", type=float, default=0.0,
                    help="with --residual: a cost, this much reward per radian, on the "
                         "residual's targets of every action joint while the robot stands "
                         "undisturbed (--quiet-after seconds after the harness let go or a "
                         "push ended, the controller not stepping): its stance is left to the "
                         "controller")
    ap.add_argument("--quiet-after", type=float, default=1.0,
                    help="seconds after a disturbance from which --quiet-cost applies")
    ap.add_argument("--width-cost", type=float, default=0.0,
                    help="with --residual: a cost, this much reward per metre, on feet "
                         "further apart than --width-target (horizontal distance between the "
                         "feet bodies) while the robot stands (before its first push, or "
                         "1 s or more after the last disturbance) and the controller is not "
                         "stepping")
    ap.add_argument("--width-target", type=float, default=0.20,
                    help="metres between the feet from which --width-cost applies")
    ap.add_argument("--width-min", type=float, default=0.0,
                    help="with --width-cost: its cost also on feet closer than this many "
                         "metres (0: none), so that the stance keeps a width between the two")
    ap.add_argument("--stagger-cost", type=float, default=0.0,
                    help="with --residual: a cost, this much reward per metre, on feet "
                         "further apart along the robot's heading than --stagger-tol (one "
                         "foot ahead of the other) while the robot stands, the steps "
                         "--width-cost weighs")
    ap.add_argument("--stagger-tol", type=float, default=0.05,
                    help="metres of stagger from which --stagger-cost applies")
    ap.add_argument("--priv-critic", action="store_true",
                    help="an asymmetric critic: the value network also sees the plant's "
                         "privileged state, which the policy does not observe (true CoM "
                         "and velocity, the push acting and the next one's time, the "
                         "episode's randomised friction, strength, latency and masses: "
                         "tools/psenv/ps_env.h); the policy file is unchanged")
    ap.add_argument("--obs-base-action", action="store_true",
                    help="with --residual: the observation ends with the controller's action "
                         "of this step (field base_action), which prev_action (the total "
                         "applied) does not separate from the policy's own part")
    ap.add_argument("--expert", choices=psenv.EXPERTS, default="quick",
                    help="the capture-point controller cloned and used for the cloning term: "
                         "quick, the runtime's (0.15 s swings, the swing leg solved from the "
                         "trunk's pose); slow, as it was until 2026-12-03 (0.3 s swings, 5 cm "
                         "lift, 0.1 s trigger lookahead, 0.3 s settling, the swing leg solved "
                         "for a level trunk), what make train clones: its clone measured better "
                         "(docs/policy.md)")
    a = ap.parse_args()
    if not 0.0 <= a.stair_p <= 1.0 or not a.stair_step > 0.0 or not a.stair_dv0 > 0.0:
        raise SystemExit("--stair-p is in [0, 1], --stair-step and --stair-dv0 > 0")

    is_pinned, float_path = FLOAT_PATH
    refusal = portable.check_loaded() if is_pinned else None
    if refusal is not None:
        raise SystemExit(refusal)
    print("floating point: " + float_path, flush=True)
    torch.set_num_threads(1)
    torch.manual_seed(a.seed)
    np.random.seed(a.seed)
    rng = np.random.default_rng(a.seed)
    hidden = [int(x) for x in a.hidden.split(",")]
    doc = ct.robot()
    if a.residual and (a.bc_iters or a.expert != "quick"):
        raise SystemExit("--residual: give --bc-iters 0; the runtime adds the quick expert")
    if a.obs_base_action and not a.residual:
        raise SystemExit("--obs-base-action: a residual policy's field (give --residual)")
    swing_cost = None
    if a.swing_cost != 0.0:
        if not a.residual or a.swing_cost < 0.0:
            raise SystemExit("--swing-cost: a cost (>= 0) on a residual (give --residual)")
        names = [j for j in a.swing_cost_joints.split(",") if j]
        unknown = [j for j in names if j not in ct.LEGS]
        if unknown or not names:
            raise SystemExit("--swing-cost-joints: %s not among the action joints (%s)"
                             % (",".join(unknown) or "none given", ",".join(ct.LEGS)))
        swing_cost = (a.swing_cost, [ct.LEGS.index(j) for j in names])
    width_cost = residual_cost(a.residual, "width", a.width_cost, "target", a.width_target,
                               a.width_target > 0.0, "> 0")
    if a.width_min != 0.0 and (width_cost is None or not 0.0 < a.width_min < a.width_target):
        raise SystemExit("--width-min: with --width-cost, 0 < --width-min < --width-target")
    if width_cost is not None:
        width_cost += (a.width_min,)
    stagger_cost = residual_cost(a.residual, "stagger", a.stagger_cost, "tol", a.stagger_tol,
                                 a.stagger_tol >= 0.0, ">= 0")
    quiet_cost = residual_cost(a.residual, "quiet", a.quiet_cost, "after", a.quiet_after,
                               a.quiet_after >= 0.0, ">= 0")
    fields = ct.OBS_FIELDS_BASE if a.obs_base_action else ct.OBS_FIELDS
    if a.init and a.bc_iters:
        raise SystemExit("--init fine-tunes: give --bc-iters 0")
    env = psenv.Env(a.envs, a.threads, seed=a.seed, push_dv_max=a.push_dv_start,
                    dr=not a.no_dr, push_dv_min=a.push_dv_min, harness_p=a.harness_p,
                    focus_p=a.focus_p, focus_dir_rad=float(np.radians(a.focus_dir_deg)),
                    expert=a.expert, ramp_start=a.ramp_start, obs_base_action=a.obs_base_action)
    n_obs_contract = psfile.obs_size(fields, len(doc["joints"]), len(ct.LEGS))
    if env.n_obs != n_obs_contract or env.n_act != len(ct.LEGS):
        raise SystemExit("environment (%d obs, %d actions) and contract.py (%d, %d) disagree"
                         % (env.n_obs, env.n_act, n_obs_contract, len(ct.LEGS)))
    n_priv = len(psenv.PRIV_KEYS) if a.priv_critic else 0
    net = Policy(env.n_obs, env.n_act, hidden, n_priv)
    norm_priv = RunningNorm(n_priv) if a.priv_critic else None
    if a.residual:  # a zero residual: exactly the expert
        with torch.no_grad():
            net.pi[-1].weight.zero_()
            net.pi[-1].bias.zero_()
    opt = torch.optim.Adam(net.parameters(), lr=a.lr)
    # PPO fine-tunes the clone: a small step for the actor (a clone that
    # stands needs its joint targets right to a few hundredths of a radian),
    # the critic at the cloning rate, each clipped on its own so the value
    # loss's large gradients do not set the actor's scale
    actor_params = list(net.pi.parameters()) + ([] if a.fixed_std else [net.log_std])
    opt_pi = torch.optim.Adam(actor_params, lr=a.ppo_lr)
    opt_v = torch.optim.Adam(net.v.parameters(), lr=a.lr)
    norm = RunningNorm(env.n_obs)
    init_c = load_init(a.init, net, norm, hidden, fields) if a.init else None
    if init_c and (init_c["action"].get("base") == "capture") != a.residual:
        raise SystemExit("--init %s: a residual policy file fine-tunes with --residual, "
                         "no other" % a.init)
    os.makedirs(a.log_dir, exist_ok=True)
    log_path = os.path.join(a.log_dir, "log.csv")
    logf = open(log_path, "w", newline="")
    log = csv.writer(logf)
    log.writerow(["iter", "env_steps", "phase", "mean_reward", "falls_per_episode",
                  "episode_s", "r_balance", "r_quality", "loss", "wall_s", "push_dv_max"])
    trained_by = ("make train: policy/train/train.py --seed %d --envs %d --threads %d "
                  "--bc-iters %d --ppo-iters %d --steps %d --hidden %s --push-dv-start %g "
                  "--push-dv-max %g --dart-std %g --ppo-std %g --ppo-lr %g --target-kl %g%s" % (
                      a.seed, a.envs, a.threads, a.bc_iters, a.ppo_iters, a.steps, a.hidden,
                      a.push_dv_start, a.push_dv_max, a.dart_std, a.ppo_std, a.ppo_lr,
                      a.target_kl, " --no-dr" if a.no_dr else ""))
    if a.init:
        trained_by += (" --init %s --critic-warmup %d --bc-weight %g --push-dv-min %g "
                       "--harness-p %g --focus-p %g --focus-dir-deg %g --gamma %g "
                       "--gae-lambda %g%s" % (
                           os.path.basename(a.init), a.critic_warmup, a.bc_weight,
                           a.push_dv_min, a.harness_p, a.focus_p, a.focus_dir_deg, a.gamma,
                           a.gae_lambda, " --fixed-std" if a.fixed_std else ""))
    else:  # the options a fine-tuning run lists above, where a first run changed them
        for key in ("bc_weight", "harness_p", "push_dv_min", "focus_p", "focus_dir_deg", "gamma",
                    "gae_lambda"):
            if getattr(a, key) != ap.get_default(key):
                trained_by += " --%s %g" % (key.replace("_", "-"), getattr(a, key))
        if a.fixed_std:
            trained_by += " --fixed-std"
    if a.stair_p > 0.0:
        trained_by += " --stair-p %g --stair-step %g --stair-dv0 %g" % (
            a.stair_p, a.stair_step, a.stair_dv0)
    if a.bootstrap_timeouts:
        trained_by += " --bootstrap-timeouts"
    if a.residual:
        trained_by += " --residual"
    if a.obs_base_action:
        trained_by += " --obs-base-action"
    if a.priv_critic:
        trained_by += " --priv-critic"
    if swing_cost is not None:
        trained_by += " --swing-cost %g --swing-cost-joints %s" % (a.swing_cost,
                                                                   a.swing_cost_joints)
    if quiet_cost is not None:
        trained_by += " --quiet-cost %g --quiet-after %g" % quiet_cost
    if width_cost is not None:
        trained_by += " --width-cost %g --width-target %g" % width_cost[:2]
        if a.width_min > 0.0:
            trained_by += " --width-min %g" % a.width_min
    if stagger_cost is not None:
        trained_by += " --stagger-cost %g --stagger-tol %g" % stagger_cost
    if a.ramp_start:
        trained_by += " --ramp-start"
    if a.expert != "quick":
        trained_by += " --expert %s" % a.expert
    if a.init:  # and how the file it started from was made
        trained_by += "; %s was: %s" % (os.path.basename(a.init), init_c.get("trained_by", "?"))
    stair = Staircase(env, a.stair_p, a.stair_step, a.stair_dv0, rng) if a.stair_p > 0 else None
    stair_csv = os.path.join(a.log_dir, "stair.csv")

    def checkpoint():
        save(a.out, net, norm, doc, hidden, trained_by, a.residual, fields)
        if stair:
            stair.write(stair_csv)

    obs = env.reset()
    if stair:
        stair.started()
    expert = np.zeros((env.n, env.n_act), np.float32)
    _, _, _, expert, _ = env.step(expert)  # the expert's first labels
    obs = env.obs.copy()
    t0 = time.time()
    n_env_steps = 0
    ds_o, ds_a = [], []
    total = a.bc_iters + a.ppo_iters
    n_run = min(total, a.stop_after) if a.stop_after > 0 else total
    bar = tqdm(range(n_run), desc="train", unit="it", dynamic_ncols=True)
    for it in bar:
        is_bc = it < a.bc_iters
        # the clone learns from pushes the expert survives; PPO goes further
        ppo_frac = 0.0 if is_bc else (it - a.bc_iters) / max(1.0, 0.7 * a.ppo_iters)
        dv_max = a.push_dv_start + (a.push_dv_max - a.push_dv_start) * min(1.0, ppo_frac)
        env.set_push_dv_max(dv_max)
        if it == a.bc_iters:
            with torch.no_grad():  # explore no more than the robot tolerates
                net.log_std.fill_(float(np.log(a.ppo_std)))
        beta = max(0.0, 1.0 - it / max(1, a.bc_iters * 0.75)) if is_bc else 0.0
        buf, obs, expert, last_v = rollout(env, net, norm, obs, a.steps, beta, expert, rng,
                                           update_norm=not a.init, explore=not is_bc,
                                           dart_std=a.dart_std if is_bc else 0.0, stair=stair,
                                           residual=a.residual, swing_cost=swing_cost,
                                           quiet_cost=quiet_cost, width_cost=width_cost,
                                           stagger_cost=stagger_cost, norm_priv=norm_priv)
        n_env_steps += a.steps * env.n
        st = stats(buf)
        O = torch.from_numpy(buf["obs"].reshape(-1, env.n_obs))
        C = torch.from_numpy(buf["cobs"].reshape(O.shape[0], -1))  # the critic's input
        E = torch.from_numpy(buf["expert"].reshape(-1, env.n_act).astype(np.float32))
        if is_bc:
            ds_o.append(buf["raw"].reshape(-1, env.n_obs))
            ds_a.append(E)
            ds_o, ds_a = ds_o[-60:], ds_a[-60:]  # the aggregate, bounded
            # raw observations, normalised with today's statistics
            X, Y = torch.from_numpy(norm(np.concatenate(ds_o))), torch.cat(ds_a)
            loss_v = 0.0
            for _ in range(4):
                perm = torch.randperm(X.shape[0])
                for i in range(0, X.shape[0], 1024):
                    idx = perm[i:i + 1024]
                    loss = ((net.pi(X[idx]) - Y[idx]) ** 2).mean()
                    opt.zero_grad()
                    loss.backward()
                    opt.step()
                    loss_v = float(loss)
            # the critic learns the expert's returns meanwhile
            adv, ret = gae(buf, last_v, a.gamma, a.gae_lambda, a.bootstrap_timeouts)
            R = torch.from_numpy(ret.reshape(-1).astype(np.float32))
            for _ in range(4):
                vl = ((net.v(C).squeeze(-1) - R) ** 2).mean()
                opt.zero_grad()
                vl.backward()
                opt.step()
        else:
            adv, ret = gae(buf, last_v, a.gamma, a.gae_lambda, a.bootstrap_timeouts)
            A = torch.from_numpy(buf["act"].reshape(-1, env.n_act).astype(np.float32))
            LP = torch.from_numpy(buf["logp"].reshape(-1).astype(np.float32))
            ADV = torch.from_numpy(adv.reshape(-1).astype(np.float32))
            ADV = (ADV - ADV.mean()) / (ADV.std() + 1e-8)
            R = torch.from_numpy(ret.reshape(-1).astype(np.float32))
            w_bc = a.bc_weight * max(0.0, 1.0 - (it - a.bc_iters) / max(1, 0.5 * a.ppo_iters))
            # a fine-tuning run's critic starts untrained: it learns alone first
            train_actor = not a.init or it >= a.critic_warmup
            loss_v = 0.0
            for _ in range(5):
                perm = torch.randperm(O.shape[0])
                kl = 0.0
                for i in range(0, O.shape[0], 2048):
                    idx = perm[i:i + 2048]
                    d = net.dist(O[idx])
                    logp = d.log_prob(A[idx]).sum(-1)
                    ratio = (logp - LP[idx]).exp()
                    pg = -torch.min(ratio * ADV[idx],
                                    ratio.clamp(0.8, 1.2) * ADV[idx]).mean()
                    bc = ((net.pi(O[idx]) - E[idx]) ** 2).mean()
                    loss = pg + w_bc * bc
                    if train_actor:
                        opt_pi.zero_grad()
                        loss.backward()
                        torch.nn.utils.clip_grad_norm_(actor_params, 1.0)
                        opt_pi.step()
                    vl = ((net.v(C[idx]).squeeze(-1) - R[idx]) ** 2).mean()
                    opt_v.zero_grad()
                    vl.backward()
                    torch.nn.utils.clip_grad_norm_(net.v.parameters(), 1.0)
                    opt_v.step()
                    loss_v = float(loss)
                    kl = max(kl, float((LP[idx] - logp.detach()).mean()))
                if kl > a.target_kl:
                    break
        wall = time.time() - t0
        log.writerow([it, n_env_steps, "bc" if is_bc else "ppo", "%.4f" % st["rew"],
                      "%.3f" % st["falls_per_ep"], "%.2f" % st["ep_len_s"],
                      "%.4f" % st["r_bal"], "%.4f" % st["r_q"], "%.4f" % loss_v, "%.1f" % wall,
                      "%.3f" % dv_max])
        logf.flush()
        bar.set_postfix(phase="bc" if is_bc else "ppo", rew="%.3f" % st["rew"],
                        falls="%.2f" % st["falls_per_ep"])
        if (it + 1) % 20 == 0 or it + 1 == total:
            checkpoint()
    logf.close()
    env.close()
    checkpoint()  # also when --stop-after cut the run short
    png = os.path.join(a.log_dir, "curves.png")
    print("wrote %s (%d env steps, %.0f s); log %s%s" % (
        a.out, n_env_steps, time.time() - t0, log_path,
        ", curves " + png if plot(log_path, png) else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())

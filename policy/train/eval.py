#!/usr/bin/env python3
"""The benchmark's pushes in the training environment (tools/psenv; the
nominal robot unless --dr), for a policy file and for the capture-point
expert, so that the runtime's grid (bench/results/push.json, made by
`pushstep --lockstep`) and the environment the policy was trained in can be
compared cell by cell.

One trial: released at once (or, with --harness, held by the sim harness
while the controller acts and let go at a random time in [0.2, 2] s, as the
runtime's trials are), a torso push of delta-v dv (impulse / mass) over the
push's duration at a random time in [1, 2] s after the release, success = no
fall before the push's start + 5 s. The directions of a
cell's trials are the grid's (--directions, 16), one environment each.

For a look at where a policy wins or loses (docs/policy.md, "Pushes from
behind"): --dr draws the robot as training does (domain randomisation),
--only-dir-deg D pushes every trial of a cell from D, and --zero-residual
JOINTS runs a residual policy with its residual on those action joints set
to zero (the controller's own targets there):

  policy/train/eval.py --weights policy/weights/ps1_stage1.safetensors --dr \\
      --harness --ramp-start --dv 0.45 --durations 0.1 --only-dir-deg 0 \\
      --zero-residual l_hip_roll,r_hip_roll

(--runtime, the comparison with the runtime's grid, takes neither --dr nor
--only-dir-deg.)

  policy/train/eval.py --weights policy/weights/ps1_stage1.safetensors \\
      --runtime bench/results/push.json --out bench/results/train_env.json
"""
import argparse
import json
import math
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import psenv  # noqa: E402
import psfile  # noqa: E402


class Mlp:
    def __init__(self, path, zero_residual=()):
        self.t, meta = psfile.read_safetensors(path)
        self.c = json.loads(meta[psfile.CONTRACT_KEY])
        o = self.c["observation"]
        self.fields = o["fields"]
        self.mean = np.asarray(o["mean"])
        self.std = np.asarray(o["std"])
        self.clip = float(o["clip"])
        self.act_clip = float(self.c["action"]["clip"])
        self.is_residual = self.c["action"].get("base") == "capture"
        joints = self.c["action"]["joints"]
        self.keep = np.ones(len(joints), np.float32)
        for name in zero_residual:
            if not self.is_residual:
                raise SystemExit("--zero-residual: %s is not a residual policy "
                                 "(its contract's action.base is not capture)" % path)
            if name not in joints:
                raise SystemExit("--zero-residual: %s is not one of %s's action joints (%s)"
                                 % (name, path, ", ".join(joints)))
            self.keep[joints.index(name)] = 0.0

    def __call__(self, obs, expert):
        x = np.clip((obs - self.mean) / self.std, -self.clip, self.clip)
        a = psfile.forward(self.t, x, contract=self.c)
        a = np.clip(a, -self.act_clip, self.act_clip).astype(np.float32)
        return a * self.keep + expert if self.is_residual else a


def expert_ctl(obs, expert):
    return expert


def run_cell(env, ctl, dv, dur, dirs, rng, policy_hz):
    """One trial per direction; returns the list of successes (bools)."""
    n = len(dirs)
    t_push = rng.uniform(1.0, 2.0, n)
    for i in range(n):
        env.set_push(i, float(t_push[i]), dur, dv, dirs[i])
    obs = env.reset()
    _, _, _, expert, _ = env.step(np.zeros((env.n, env.n_act), np.float32))
    obs = env.obs.copy()
    ok = [None] * n
    # the push's start moves on by the time held (info[2] is episode time)
    push_start = np.full(n, np.inf)
    for _ in range(int((float(t_push.max()) + 2.0 + 5.5) * policy_hz)):
        obs, _, _, expert, info = env.step(ctl(obs, expert))
        for i in range(n):
            if info[i, 7] > 0 and not np.isfinite(push_start[i]):
                push_start[i] = info[i, 2]
            if ok[i] is not None:
                continue
            if info[i, 0] > 0:  # fell
                ok[i] = False
            elif info[i, 2] >= push_start[i] + 5.0 or info[i, 1] > 0:  # inf until the push
                ok[i] = True
        if all(x is not None for x in ok):
            break
    return [bool(x) for x in ok]


def runtime_rates(path):
    """(controller, dur, dv) -> success rate from bench/push.py merge's JSON."""
    with open(path) as f:
        doc = json.load(f)
    acc = {}
    for t in doc.get("trials", []):
        k = (t["controller"], round(float(t["duration_s"]), 3), round(float(t["dv_m_s"]), 3))
        s = acc.setdefault(k, [0, 0])
        s[0] += 0 if t["fell"] else 1
        s[1] += 1
    return acc


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--weights", help="policy file (without it, the expert only)")
    ap.add_argument("--dv", default="0.15,0.30,0.45,0.60,0.80")
    ap.add_argument("--durations", default="0.1,0.3")
    ap.add_argument("--directions", type=int, default=16)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--runtime", help="bench/results/push.json to compare with")
    ap.add_argument("--out", help="JSON results")
    ap.add_argument("--lib", help="the environment library (default build/libpsenv.so)")
    ap.add_argument("--harness", action="store_true",
                    help="start each trial held by the harness, as the runtime does")
    ap.add_argument("--ramp-start", action="store_true",
                    help="with --harness: limp in the harness, then the servo layer's ramp, "
                         "as the runtime's trials start (train.py --ramp-start)")
    ap.add_argument("--expert", choices=psenv.EXPERTS, default="quick",
                    help="the capture-point controller's tunables (train.py --expert)")
    ap.add_argument("--dr", action="store_true",
                    help="domain randomisation as in training (default: the nominal robot)")
    ap.add_argument("--only-dir-deg", type=float,
                    help="every trial's push from this force direction (0 = +x, forward); "
                         "--directions then counts the trials of a cell")
    ap.add_argument("--zero-residual", default="",
                    help="comma-separated action joints whose residual is set to zero "
                         "(a residual policy only)")
    a = ap.parse_args()
    dvs = [float(x) for x in a.dv.split(",")]
    durs = [float(x) for x in a.durations.split(",")]
    dirs = [2 * math.pi * k / a.directions for k in range(a.directions)]
    if a.only_dir_deg is not None:
        dirs = [math.radians(a.only_dir_deg)] * a.directions
    zero = [j for j in a.zero_residual.split(",") if j]
    if zero and not a.weights:
        raise SystemExit("--zero-residual needs --weights")
    if a.runtime and (a.dr or a.only_dir_deg is not None):
        raise SystemExit("--runtime compares the nominal robot over the grid's directions: "
                         "not with --dr or --only-dir-deg")
    mlp = Mlp(a.weights, zero) if a.weights else None
    ctls = [("capture", expert_ctl)] + ([("mlp", mlp)] if mlp else [])
    rng = np.random.default_rng(a.seed)
    policy_hz = mlp.c["policy_hz"] if mlp else 50

    def make_env(is_base):
        return psenv.Env(a.directions, a.threads, seed=a.seed, episode_s=8.0, dr=a.dr,
                         lib=a.lib, harness_p=1.0 if a.harness else 0.0, expert=a.expert,
                         ramp_start=a.ramp_start, obs_base_action=is_base)
    env = make_env(False)
    cells = []
    for name, ctl in ctls:
        if ctl is mlp and "base_action" in mlp.fields:
            # an environment of its own: one that fills base_action steps
            # the controller once more at each reset, which must not change
            # the controller's rows (a file without the field shares the
            # controller's environment, as it always did)
            env.close()
            env = make_env(True)
        if ctl is mlp and env.n_obs != len(mlp.mean):
            raise SystemExit("%s: %d observation floats (%s), the environment gives %d" % (
                a.weights, len(mlp.mean), ", ".join(mlp.fields), env.n_obs))
        for dur in durs:
            for dv in dvs:
                ok = run_cell(env, ctl, dv, dur, dirs, rng, policy_hz)
                cells.append({"controller": name, "dur_s": dur, "dv_m_s": dv,
                              "success": sum(ok), "trials": len(ok),
                              "direction_deg": [round(math.degrees(d), 1) for d in dirs],
                              "held": ok})
                print("env %-8s %.1f s dv %.2f: %2d/%d" % (name, dur, dv, sum(ok), len(ok)),
                      file=sys.stderr)
    env.close()
    rt = runtime_rates(a.runtime) if a.runtime and os.path.exists(a.runtime) else {}
    print("| controller | push | dv (m/s) | training env | runtime (pushstep --lockstep) |")
    print("|---|---|---|---|---|")
    for c in cells:
        r = rt.get((c["controller"], round(c["dur_s"], 3), round(c["dv_m_s"], 3)))
        c["runtime"] = {"success": r[0], "trials": r[1]} if r else None
        print("| %s | %.1f s | %.2f | %d/%d | %s |" % (
            c["controller"], c["dur_s"], c["dv_m_s"], c["success"], c["trials"],
            "%d/%d" % tuple(r) if r else "-"))
    if a.out:
        with open(a.out, "w") as f:
            what = "training environment (%s), %s" % (
                "domain randomisation" if a.dr else "nominal",
                "every push from %g deg" % a.only_dir_deg if a.only_dir_deg is not None
                else "the push grid's directions")
            if a.runtime:
                what += ", beside the runtime's grid"
            json.dump({"what": what,
                       "seed": a.seed, "expert": a.expert, "harness": a.harness,
                       "ramp_start": a.ramp_start, "dr": a.dr,
                       "zero_residual": zero,
                       "weights": os.path.basename(a.weights) if a.weights else None,
                       "cells": cells}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())

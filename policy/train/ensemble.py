#!/usr/bin/python3
"""Average several policy files into one: an ensemble that the runtime's
engine (policy/ps_mlp) runs as a plain MLP.

  policy/train/ensemble.py --out OUT.safetensors A.safetensors B.safetensors ...

The members must share their contract (robot, rate, joints, gains, stance,
observation fields and clip, actions, activations; not the observation's
normalisation, nor the widths of their hidden layers), and carry no
adapters or embeddings. The file written computes the mean of the members' outputs: its
first layer stacks the members' first layers, each member's input
normalisation folded into its rows so that all read the first member's
normalised observation; its hidden layers are block-diagonal (each member
sees only its own units): grouped layers (contract "groups", policy/ps_mlp.h)
where the members' widths agree, which hold and compute the blocks alone,
else dense ones with the zeros; its last layer is the members' last layers
side by side, divided by their number. Exact wherever no normalised observation
reaches the clip (10 standard deviations in make train's files), up to
float32 rounding. Why an ensemble: runs of one recipe that differ only in
their seed hold different pushes (docs/policy.md, "An ensemble of seeds"),
and their mean holds more than any of them.

The output's contract is the first member's, with its trained_by naming
this tool and the members' commands (a member's that differs from the
first's only in some options is given as those options). Deterministic: the
same members give the same file, byte for byte.
"""
import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import psfile  # noqa: E402

# Contract entries every member must share (observation mean/std may differ).
SHARED = ("version", "robot", "policy_hz", "joints", "kp", "kd", "stance", "activations")
SHARED_OBS = ("fields", "clip")


class Refused(Exception):
    pass


def load(path):
    try:
        t, meta = psfile.read_safetensors(path)
        c = json.loads(meta[psfile.CONTRACT_KEY])
    except (OSError, ValueError, KeyError) as e:
        raise Refused("%s: not a policy file (%s)" % (path, e))
    extra = sorted(k for k in t if not k.startswith("base."))
    if extra:
        raise Refused("%s: has %s; only plain MLPs (base.K layers) can be averaged" % (path, extra[0]))
    if any(g != 1 for g in c.get("groups", [])):
        raise Refused("%s: has grouped layers (an ensemble?); only plain MLPs can be averaged" % path)
    n = len(c.get("activations", []))
    for k in range(n):
        if "base.%d.weight" % k not in t:
            raise Refused("%s: no tensor base.%d.weight for its %d activations" % (path, k, n))
    return t, c


def check_same(paths, members):
    t0, c0 = members[0]
    for path, (t, c) in zip(paths[1:], members[1:]):
        for key in SHARED:
            if c.get(key) != c0.get(key):
                raise Refused("%s: contract %s differs from %s's" % (path, key, paths[0]))
        for key in SHARED_OBS:
            if c["observation"].get(key) != c0["observation"].get(key):
                raise Refused("%s: contract observation.%s differs from %s's" % (path, key, paths[0]))
        if c["action"] != c0["action"]:
            raise Refused("%s: contract action differs from %s's" % (path, paths[0]))


def layer(t, k):
    w = t["base.%d.weight" % k].astype(np.float64)
    b = t.get("base.%d.bias" % k)
    return w, (np.zeros(w.shape[0]) if b is None else b.astype(np.float64))


def same_widths(members):
    t0 = members[0][0]
    n = len(members[0][1]["activations"])
    return all(t["base.%d.weight" % k].shape == t0["base.%d.weight" % k].shape
               for t, _ in members for k in range(n))


def merge_layers(members, grouped):
    """The ensemble's (W, b) list, float64 (psfile writes float32); with
    grouped, the hidden layers as [K * out, in] weights of K groups."""
    c0 = members[0][1]
    mean0 = np.array(c0["observation"]["mean"], np.float64)
    std0 = np.array(c0["observation"]["std"], np.float64)
    n_layers = len(c0["activations"])
    out = []
    for k in range(n_layers):
        ws, bs = zip(*(layer(t, k) for t, _ in members))
        if k == 0:
            # member m reads (x - mean_m) / std_m = (z0 * std0 + mean0 - mean_m) / std_m
            ws, bs = list(ws), list(bs)
            for m, (_, c) in enumerate(members):
                mean_m = np.array(c["observation"]["mean"], np.float64)
                std_m = np.array(c["observation"]["std"], np.float64)
                bs[m] = bs[m] + ws[m] @ ((mean0 - mean_m) / std_m)
                ws[m] = ws[m] * (std0 / std_m)[None, :]
        if k == n_layers - 1:
            w = np.concatenate(ws, axis=1) / len(members)
            b = np.sum(bs, axis=0) / len(members)
        elif k == 0 or grouped:
            w, b = np.concatenate(ws, axis=0), np.concatenate(bs)
        else:
            w = np.zeros((sum(x.shape[0] for x in ws), sum(x.shape[1] for x in ws)))
            r = col = 0
            for x in ws:
                w[r:r + x.shape[0], col:col + x.shape[1]] = x
                r, col = r + x.shape[0], col + x.shape[1]
            b = np.concatenate(bs)
        out.append((w, b))
    return out


def describe(cmds):
    """trained_by of the ensemble: the first member's command in full, the
    others as the options in which theirs differ from it."""
    first = cmds[0].split()
    parts = ["policy/train/ensemble.py, the mean of %d policies: %s" % (len(cmds), cmds[0])]
    for cmd in cmds[1:]:
        words = cmd.split()
        if len(words) == len(first):
            diff = [i for i, (a, b) in enumerate(zip(first, words)) if a != b]
            if not diff:
                parts.append("and the same command")
                continue
            if all(i > 0 and words[i - 1].startswith("--") and first[i - 1] == words[i - 1] for i in diff):
                parts.append("and with " + " ".join("%s %s" % (words[i - 1], words[i]) for i in diff))
                continue
        parts.append("and " + cmd)
    return "; ".join(parts)


def ensemble(paths, out):
    if len(paths) < 2:
        raise Refused("an ensemble needs 2 or more policy files, %d given" % len(paths))
    members = [load(p) for p in paths]
    check_same(paths, members)
    c = dict(members[0][1])
    c["trained_by"] = describe([m[1].get("trained_by", os.path.basename(p))
                                for p, m in zip(paths, members)])
    grouped = same_widths(members)
    n_layers = len(c["activations"])
    c.pop("groups", None)
    if grouped and n_layers > 2:
        c["groups"] = [1] + [len(members)] * (n_layers - 2) + [1]
    layers = [(w.astype(np.float32), b.astype(np.float32))
              for w, b in merge_layers(members, grouped)]
    psfile.write_policy(out, layers, c)
    return layers


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog=__doc__.split("\n\n", 2)[2])
    ap.add_argument("--out", required=True, help="the ensemble's policy file")
    ap.add_argument("members", nargs="+", help="policy files (safetensors) to average")
    a = ap.parse_args()
    try:
        layers = ensemble(a.members, a.out)
    except Refused as e:
        print("ensemble.py: refused: %s" % e, file=sys.stderr)
        return 1
    print("%s: the mean of %d policies, layer weights %s" % (
        a.out, len(a.members), " ".join("%dx%d" % w.shape for w, _ in layers)))
    return 0


if __name__ == "__main__":
    sys.exit(main())

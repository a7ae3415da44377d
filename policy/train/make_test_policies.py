#!/usr/bin/python3
"""Policy files for ps1 used by the end-to-end tests (tests/data/policy):
  ps1_zero.safetensors  every weight and bias 0: actions 0, targets = stance
  ps1_wild.safetensors  last bias 100 (beyond the action clip of 4): the
                        runtime must refuse its actions and fall back
  ps1_zero_residual.safetensors  ps1_zero as a residual policy (action base
                        "capture"): targets = the capture-point controller's
  ps1_zero_residual_base.safetensors  the same observing its base (the
                        observation field base_action, train.py --obs-base-action)
All carry ps1's contract (policy/train/contract.py). numpy only.
"""
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import contract as ct  # noqa: E402
import psfile  # noqa: E402

OUT = os.path.join(HERE, "..", "..", "tests", "data", "policy")


def main():
    doc = ct.robot()
    c = ct.contract(doc, trained_by="policy/train/make_test_policies.py (not trained)")
    n_obs = len(c["observation"]["mean"])
    n_act = len(c["action"]["joints"])
    sizes = [n_obs, 32, n_act]
    c["activations"] = ["elu", "identity"]
    layers = [(np.zeros((b, a)), np.zeros(b)) for a, b in zip(sizes[:-1], sizes[1:])]
    psfile.write_policy(os.path.join(OUT, "ps1_zero.safetensors"), layers, c)
    layers[-1] = (layers[-1][0], np.full(n_act, 100.0))
    psfile.write_policy(os.path.join(OUT, "ps1_wild.safetensors"), layers, c)
    layers[-1] = (layers[-1][0], np.zeros(n_act))
    c["action"]["base"] = "capture"
    psfile.write_policy(os.path.join(OUT, "ps1_zero_residual.safetensors"), layers, c)
    cb = ct.contract(doc, trained_by=c["trained_by"], fields=ct.OBS_FIELDS_BASE)
    cb["activations"] = c["activations"]
    cb["action"]["base"] = "capture"
    n_obs_b = len(cb["observation"]["mean"])
    layers_b = [(np.zeros((32, n_obs_b)), np.zeros(32))] + layers[1:]
    psfile.write_policy(os.path.join(OUT, "ps1_zero_residual_base.safetensors"), layers_b, cb)
    print("n_obs %d, n_act %d" % (n_obs, n_act))


if __name__ == "__main__":
    main()

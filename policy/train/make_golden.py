#!/usr/bin/python3
"""Golden vectors for tests/test_mlp.c, from PyTorch (Debian's python3-torch).

Writes tests/data/policy/:
  golden_base.safetensors   15 -> 64 -> 64 -> 4, ELU, ELU, identity
  golden_adapt.safetensors  the same base with internal adapters on layers
                            0 and 1 and a latent injection (5 -> 16 tanh ->
                            64) into layer 0, all non-zero
  golden_acts.safetensors   15 -> 32 sigmoid -> 32 tanh -> 32 relu -> 32
                            silu -> 4 identity
  golden_onnx.onnx          golden_base exported by torch.onnx (the ONNX
                            importer's input in tests/test_mlp.c and the
                            Python tool tests)
  golden_from_onnx.safetensors  golden_onnx.onnx through policy/train/onnx2policy.py
  golden_vectors.safetensors  inputs and PyTorch's outputs of each network
Run: /usr/bin/python3 policy/train/make_golden.py (seed 1; the files are
committed, so the tests do not need torch).
"""
import json
import os
import sys

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import psfile  # noqa: E402

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tests", "data",
                   "policy")
JOINTS = ["j0", "j1", "j2", "j3"]


def contract(acts, extra=0, inject=0, embed_acts=()):
    c = {
        "version": 1, "robot": "golden", "policy_hz": 50, "joints": JOINTS,
        "kp": [100.0] * 4, "kd": [2.0] * 4, "stance": [0.0, 0.1, -0.1, 0.2],
        "observation": {"fields": ["gravity_body", "joint_pos", "joint_vel", "prev_action"],
                        "mean": [0.0] * 15, "std": [1.0] * 15, "clip": 10.0},
        "action": {"joints": JOINTS, "scale": [0.5] * 4, "clip": 10.0},
        "activations": list(acts), "trained_by": "policy/train/make_golden.py, seed 1",
    }
    if extra:
        c.update({"extra_size": extra, "inject_layer": inject,
                  "embed_activations": list(embed_acts)})
    return c


class Net(torch.nn.Module):
    ACT = {"elu": torch.nn.ELU(), "relu": torch.nn.ReLU(), "tanh": torch.nn.Tanh(),
           "sigmoid": torch.nn.Sigmoid(), "silu": torch.nn.SiLU(),
           "identity": torch.nn.Identity()}

    def __init__(self, sizes, acts, adapt=(), embed=None, inject=0):
        super().__init__()
        self.base = torch.nn.ModuleList(
            torch.nn.Linear(a, b) for a, b in zip(sizes[:-1], sizes[1:]))
        self.acts = acts
        self.adapt = torch.nn.ModuleDict(
            {str(k): torch.nn.Linear(sizes[k], sizes[k + 1]) for k in adapt})
        self.embed = None
        if embed:
            esz, eacts = embed
            self.embed = torch.nn.ModuleList(
                torch.nn.Linear(a, b) for a, b in zip(esz[:-1], esz[1:]))
            self.eacts = eacts
        self.inject = inject

    def forward(self, x, extra=None):
        inj = None
        if self.embed is not None and extra is not None:
            e = extra
            for l, a in zip(self.embed, self.eacts):
                e = self.ACT[a](l(e))
            inj = e
        h = x
        for k, (l, a) in enumerate(zip(self.base, self.acts)):
            y = l(h)
            if str(k) in self.adapt:
                y = y + self.adapt[str(k)](h)
            if inj is not None and k == self.inject:
                y = y + inj
            h = self.ACT[a](y)
        return h

    def save(self, path, c):
        f = lambda l: (l.weight.detach().numpy(), l.bias.detach().numpy())  # noqa: E731
        psfile.write_policy(path, [f(l) for l in self.base], c,
                            adapters={int(k): f(l) for k, l in self.adapt.items()},
                            embed=[f(l) for l in self.embed] if self.embed else None)


def main():
    torch.manual_seed(1)
    torch.set_num_threads(1)
    os.makedirs(OUT, exist_ok=True)
    k = 16
    x = torch.randn(k, 15) * 2.0
    x[0] = 0.0
    x[1, :5] = 5.0
    extra = torch.randn(k, 5)
    vec = {"base.in": x.numpy(), "adapt.in": x.numpy(), "adapt.extra": extra.numpy(),
           "acts.in": x.numpy()}

    acts = ["elu", "elu", "identity"]
    base = Net([15, 64, 64, 4], acts)
    base.save(os.path.join(OUT, "golden_base.safetensors"), contract(acts))
    with torch.no_grad():
        vec["base.out"] = base(x).numpy()

    ad = Net([15, 64, 64, 4], acts, adapt=(0, 1), embed=([5, 16, 64], ["tanh", "identity"]))
    ad.base.load_state_dict(base.base.state_dict())
    with torch.no_grad():  # adapters trained away from zero, here at random
        for p in list(ad.adapt.parameters()) + list(ad.embed.parameters()):
            p.mul_(0.5)
    ad.save(os.path.join(OUT, "golden_adapt.safetensors"),
            contract(acts, extra=5, inject=0, embed_acts=["tanh", "identity"]))
    with torch.no_grad():
        vec["adapt.out"] = ad(x, extra).numpy()

    acts2 = ["sigmoid", "tanh", "relu", "silu", "identity"]
    mixed = Net([15, 32, 32, 32, 32, 4], acts2)
    mixed.save(os.path.join(OUT, "golden_acts.safetensors"), contract(acts2))
    with torch.no_grad():
        vec["acts.out"] = mixed(x).numpy()

    psfile.write_safetensors(os.path.join(OUT, "golden_vectors.safetensors"), vec,
                             {"made_by": "policy/train/make_golden.py seed 1, torch " +
                              torch.__version__})
    onnx_path = os.path.join(OUT, "golden_onnx.onnx")
    torch.onnx.export(base, (x[:1],), onnx_path, input_names=["obs"], output_names=["action"],
                      opset_version=13)
    import onnx2policy
    onnx2policy.convert(onnx_path, contract(acts),
                        os.path.join(OUT, "golden_from_onnx.safetensors"))
    # the numpy reference agrees with torch (the C test then has two witnesses)
    for name in ("base", "adapt", "acts", "from_onnx"):
        path = os.path.join(OUT, "golden_%s.safetensors" % name)
        key = "base" if name == "from_onnx" else name
        ref = psfile.forward(path, vec[key + ".in"], vec.get(key + ".extra"))
        err = np.abs(ref - vec[key + ".out"]).max()
        print("%s: torch vs numpy max |diff| %.2e" % (name, err))
        assert err < 1e-5
    print(json.dumps({k: list(v.shape) for k, v in vec.items()}))


if __name__ == "__main__":
    main()

#!/usr/bin/python3
"""Tests of the Python policy tools (make test runs this file): the ONNX
importer (policy/train/onnx2policy.py) on graphs built with onnx.helper and
on torch's export in tests/data/policy, its refusals, and a property test
(python3-hypothesis): any supported chain imports to a policy file whose
forward pass equals the graph's. Prints cmocka's summary lines for
tools/run-tests.sh.
"""
import json
import os
import sys
import tempfile
import unittest

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import onnx2policy  # noqa: E402
import psfile  # noqa: E402

DATA = os.path.join(HERE, "..", "..", "tests", "data", "policy")


def contract(n_joints, n_act=None):
    n_act = n_joints if n_act is None else n_act
    names = ["j%d" % i for i in range(n_joints)]
    fields = ["gravity_body", "joint_pos", "joint_vel", "prev_action"]
    n_obs = psfile.obs_size(fields, n_joints, n_act)
    return {"version": 1, "robot": "t", "policy_hz": 50, "joints": names,
            "kp": [1.0] * n_joints, "kd": [0.1] * n_joints, "stance": [0.0] * n_joints,
            "observation": {"fields": fields, "mean": [0.0] * n_obs, "std": [1.0] * n_obs,
                            "clip": 5.0},
            "action": {"joints": names[:n_act], "scale": [0.3] * n_act, "clip": 5.0}}


def graph(layers, matmul=False, extra_nodes=(), name="g"):
    """layers: list of (W [out, in], b, act). Gemm (transB) or MatMul+Add."""
    nodes, inits = [], []
    cur = "x"
    for k, (w, b, act) in enumerate(layers):
        wn, bn, y = "w%d" % k, "b%d" % k, "y%d" % k
        if matmul:
            inits.append(numpy_helper.from_array(w.T.astype(np.float32), wn))
            nodes.append(helper.make_node("MatMul", [cur, wn], [y + "m"], name="mm%d" % k))
            inits.append(numpy_helper.from_array(b.astype(np.float32), bn))
            nodes.append(helper.make_node("Add", [y + "m", bn], [y], name="add%d" % k))
        else:
            inits.append(numpy_helper.from_array(w.astype(np.float32), wn))
            inits.append(numpy_helper.from_array(b.astype(np.float32), bn))
            nodes.append(helper.make_node("Gemm", [cur, wn, bn], [y], transB=1, name="g%d" % k))
        cur = y
        if act == "silu":
            nodes.append(helper.make_node("Sigmoid", [cur], [cur + "s"], name="s%d" % k))
            nodes.append(helper.make_node("Mul", [cur, cur + "s"], [cur + "a"], name="m%d" % k))
            cur = cur + "a"
        elif act != "identity":
            op = {"relu": "Relu", "tanh": "Tanh", "sigmoid": "Sigmoid", "elu": "Elu"}[act]
            nodes.append(helper.make_node(op, [cur], [cur + "a"], name="a%d" % k))
            cur = cur + "a"
    nodes.extend(extra_nodes)
    n_in, n_out = layers[0][0].shape[1], layers[-1][0].shape[0]
    g = helper.make_graph(nodes, name, [helper.make_tensor_value_info("x", TensorProto.FLOAT,
                                                                      [1, n_in])],
                          [helper.make_tensor_value_info(cur, TensorProto.FLOAT, [1, n_out])],
                          inits)
    return helper.make_model(g, opset_imports=[helper.make_opsetid("", 13)])


def save(model, d, name="m.onnx"):
    p = os.path.join(d, name)
    onnx.save(model, p)
    return p


def rand_layers(rng, sizes, acts):
    return [(rng.standard_normal((b, a)) * 0.3, rng.standard_normal(b) * 0.1, act)
            for a, b, act in zip(sizes[:-1], sizes[1:], acts)]


def direct(layers, x):
    h = x.astype(np.float64)
    for w, b, act in layers:
        h = psfile.act(act, h @ w.T.astype(np.float32).astype(np.float64) +
                       b.astype(np.float32))
    return h


class Onnx2Policy(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.d = self.tmp.name

    def tearDown(self):
        self.tmp.cleanup()

    def test_torch_export_imports_and_matches_pytorch(self):
        vec, _ = psfile.read_safetensors(os.path.join(DATA, "golden_vectors.safetensors"))
        src = os.path.join(DATA, "golden_onnx.onnx")
        out = os.path.join(self.d, "p.safetensors")
        c = contract(4)
        onnx2policy.convert(src, c, out)
        y = psfile.forward(out, vec["base.in"])
        self.assertLess(np.abs(y - vec["base.out"]).max(), 1e-5)
        _, meta = psfile.read_safetensors(out)
        self.assertEqual(json.loads(meta[psfile.CONTRACT_KEY])["activations"],
                         ["elu", "elu", "identity"])

    def test_matmul_add_and_silu_chain(self):
        rng = np.random.default_rng(3)
        layers = rand_layers(rng, [15, 8, 6, 4], ["silu", "relu", "tanh"])
        p = save(graph(layers, matmul=True), self.d)
        out = os.path.join(self.d, "p.safetensors")
        onnx2policy.convert(p, contract(4), out)
        x = rng.standard_normal((5, 15))
        self.assertLess(np.abs(psfile.forward(out, x) - direct(layers, x)).max(), 1e-5)

    def _refused(self, model, text):
        p = save(model, self.d)
        with self.assertRaises(onnx2policy.Unsupported) as cm:
            onnx2policy.convert(p, contract(4), os.path.join(self.d, "p.safetensors"))
        self.assertIn(text, str(cm.exception))

    def test_refuses_unsupported_operator(self):
        rng = np.random.default_rng(4)
        m = graph(rand_layers(rng, [15, 4], ["identity"]))
        m.graph.node[0].op_type = "Conv"
        self._refused(m, "operator Conv is not supported")

    def test_refuses_branch(self):
        rng = np.random.default_rng(5)
        layers = rand_layers(rng, [15, 4], ["relu"])
        extra = [helper.make_node("Tanh", ["y0"], ["z"], name="side")]
        self._refused(graph(layers, extra_nodes=extra), "feeds 2 nodes")

    def test_refuses_scaled_gemm_and_elu_alpha(self):
        rng = np.random.default_rng(6)
        m = graph(rand_layers(rng, [15, 4], ["identity"]))
        m.graph.node[0].attribute.append(helper.make_attribute("alpha", 2.0))
        self._refused(m, "alpha/beta other than 1")
        m = graph(rand_layers(rng, [15, 4], ["elu"]))
        m.graph.node[1].attribute.append(helper.make_attribute("alpha", 0.5))
        self._refused(m, "Elu with alpha 0.5")

    def test_refuses_contract_mismatch(self):
        rng = np.random.default_rng(7)
        p = save(graph(rand_layers(rng, [14, 4], ["identity"])), self.d)
        with self.assertRaises(ValueError) as cm:
            onnx2policy.convert(p, contract(4), os.path.join(self.d, "p.safetensors"))
        self.assertIn("first layer takes 14 inputs, the observation has 15", str(cm.exception))

    def test_cli_refusal_exit_status(self):
        rng = np.random.default_rng(8)
        m = graph(rand_layers(rng, [15, 4], ["identity"]))
        m.graph.node[0].op_type = "LSTM"
        p = save(m, self.d)
        cpath = os.path.join(self.d, "c.json")
        with open(cpath, "w") as f:
            json.dump(contract(4), f)
        import subprocess
        r = subprocess.run([sys.executable, os.path.join(HERE, "onnx2policy.py"), p,
                            "--contract", cpath, "--out", os.path.join(self.d, "o")],
                           capture_output=True, text=True)
        self.assertEqual(r.returncode, 2)
        self.assertIn("refused: node g0 (LSTM): operator LSTM is not supported", r.stderr)


class Property(unittest.TestCase):
    def test_any_supported_chain_imports_exactly(self):
        try:
            from hypothesis import given, settings, strategies as st
        except ImportError:
            self.skipTest("python3-hypothesis not installed")

        acts = st.sampled_from(["identity", "relu", "elu", "tanh", "sigmoid", "silu"])

        @settings(max_examples=25, deadline=None, database=None)
        @given(hidden=st.lists(st.integers(1, 24), min_size=0, max_size=3),
               act_list=st.lists(acts, min_size=4, max_size=4), matmul=st.booleans(),
               seed=st.integers(0, 10000))
        def prop(hidden, act_list, matmul, seed):
            rng = np.random.default_rng(seed)
            sizes = [15] + hidden + [4]
            layers = rand_layers(rng, sizes, act_list[:len(sizes) - 1])
            with tempfile.TemporaryDirectory() as d:
                p = save(graph(layers, matmul=matmul), d)
                out = os.path.join(d, "p.safetensors")
                onnx2policy.convert(p, contract(4), out)
                x = rng.standard_normal((3, 15))
                assert np.abs(psfile.forward(out, x) - direct(layers, x)).max() < 1e-5

        prop()


def main():
    res = unittest.TextTestRunner(stream=sys.stdout, verbosity=2).run(
        unittest.defaultTestLoader.loadTestsFromModule(sys.modules[__name__]))
    bad = len(res.failures) + len(res.errors)
    print("[  PASSED  ] %d test(s)." % (res.testsRun - bad))
    if bad:
        print("[  FAILED  ] %d test(s), listed below:" % bad)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/python3
"""Tests of the Python policy tools (make test runs this file): the ONNX
importer (policy/train/onnx2policy.py) on graphs built with onnx.helper and
on torch's export in tests/data/policy, its refusals, and two property
tests (python3-hypothesis): any supported chain imports to a policy file
whose forward pass equals the graph's; any one change to such a graph
(operator, node, initializer, shape, wiring, attribute, output, bytes) is
refused with a message and no file, or imports to a file that computes
what the changed graph computes. Prints cmocka's summary lines for
tools/run-tests.sh.
"""
import json
import os
import subprocess
import sys
import tempfile
import unittest

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import ensemble  # noqa: E402
import onnx2policy  # noqa: E402
import portable  # noqa: E402
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

    # Found by Malformed below (each crashed the importer or wrote a file the
    # graph does not compute); refused now with the node and the reason.
    def test_refuses_bias_not_one_per_output(self):
        rng = np.random.default_rng(9)
        layers = rand_layers(rng, [15, 4], ["identity"])
        m = graph(layers)
        m.graph.initializer[1].CopyFrom(numpy_helper.from_array(
            np.zeros(5, np.float32), m.graph.initializer[1].name))
        self._refused(m, "bias of shape (5,) for 4 outputs")
        m = graph(layers, matmul=True)
        m.graph.initializer[1].CopyFrom(numpy_helper.from_array(
            np.zeros(1, np.float32), m.graph.initializer[1].name))
        self._refused(m, "bias of shape (1,) for 4 outputs")

    def test_refuses_known_operator_with_missing_input(self):
        rng = np.random.default_rng(10)
        m = graph(rand_layers(rng, [15, 4], ["relu"]))
        m.graph.node[1].op_type = "Gemm"  # the Relu, one input
        self._refused(m, "node a0 (Gemm): 1 inputs and 1 outputs")

    def test_refuses_cycle(self):
        rng = np.random.default_rng(11)
        m = graph(rand_layers(rng, [15, 8, 4], ["relu", "identity"]))
        m.graph.node[1].output[0] = m.graph.node[1].input[0]  # Relu(y0) -> y0
        self._refused(m, "computed earlier in the chain (a cycle)")
        # a square Gemm writing its own input: the old importer looped forever
        m = graph(rand_layers(rng, [15, 15], ["identity"]))
        m.graph.node[0].output[0] = m.graph.node[0].input[0]  # Gemm(x) -> x
        self._refused(m, "node g0 (Gemm): its output x is computed earlier")

    def test_cli_not_onnx_exit_status(self):
        rng = np.random.default_rng(12)
        p = os.path.join(self.d, "cut.onnx")
        with open(p, "wb") as f:
            f.write(graph(rand_layers(rng, [15, 4], ["relu"])).SerializeToString()[:1])
        cpath = os.path.join(self.d, "c.json")
        with open(cpath, "w") as f:
            json.dump(contract(4), f)
        out = os.path.join(self.d, "o")
        status, err = run_cli(p, cpath, out)
        self.assertEqual(status, 2)
        self.assertIn("not an ONNX model", err)
        self.assertFalse(os.path.exists(out))

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
            from hypothesis import example, given, settings, strategies as st
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


# ---- malformed graphs ------------------------------------------------------

def ref_eval(model, x):
    """An independent numpy evaluation of the graph as ONNX defines it, for
    the operators an MLP uses; raises on anything else (another operator, a
    shape that does not fit, a tensor never computed)."""
    g = model.graph
    env = {i.name: numpy_helper.to_array(i).astype(np.float64) for i in g.initializer}
    inputs = [i.name for i in g.input if i.name not in env]
    if len(inputs) != 1 or len(g.output) != 1:
        raise ValueError("not one input and one output")
    env[inputs[0]] = np.asarray(x, dtype=np.float64)
    pending = list(g.node)
    while pending:  # any order the graph allows; a cycle never becomes ready
        ready = [n for n in pending if all(i in env for i in n.input)]
        if not ready:
            raise ValueError("a node never gets its inputs")
        n = ready[0]
        pending.remove(n)
        a = {t.name: helper.get_attribute_value(t) for t in n.attribute}
        v = [env[i] for i in n.input]
        if n.op_type == "Gemm":
            A = v[0].T if a.get("transA", 0) else v[0]
            B = v[1].T if a.get("transB", 0) else v[1]
            if A.ndim != 2 or B.ndim != 2:
                raise ValueError("Gemm of a non-matrix")
            y = a.get("alpha", 1.0) * (A @ B)
            if len(v) > 2:
                y = y + a.get("beta", 1.0) * v[2]
        elif n.op_type == "MatMul":
            y = v[0] @ v[1]
        elif n.op_type == "Add":
            y = v[0] + v[1]
        elif n.op_type == "Mul":
            y = v[0] * v[1]
        elif n.op_type == "Relu":
            y = np.maximum(v[0], 0)
        elif n.op_type == "Tanh":
            y = np.tanh(v[0])
        elif n.op_type == "Sigmoid":
            y = 1 / (1 + np.exp(-v[0]))
        elif n.op_type == "Identity":
            y = v[0]
        elif n.op_type == "Elu":
            al = a.get("alpha", 1.0)
            y = np.where(v[0] > 0, v[0], al * np.expm1(np.minimum(v[0], 0)))
        else:
            raise ValueError("operator %s" % n.op_type)
        if len(n.output) != 1:
            raise ValueError("%d outputs" % len(n.output))
        env[n.output[0]] = y
    return env[g.output[0].name]


MUTATIONS = ("op", "drop_node", "drop_init", "bias_len", "weight_shape", "rewire", "attr",
             "extra_output", "self_loop", "bytes")
OPS = ("Gemm", "MatMul", "Add", "Mul", "Relu", "Tanh", "Sigmoid", "Elu", "Identity", "Conv",
       "Softmax", "Sub", "Reshape", "LSTM")


def mutate(model, kind, k, r):
    """One change to a valid graph; k and r pick what and how (any ints).
    Returns the model, or the serialized bytes for "bytes"."""
    g = model.graph
    nodes, inits = g.node, g.initializer
    if kind == "op":
        nodes[k % len(nodes)].op_type = OPS[r % len(OPS)]
    elif kind == "drop_node":
        del nodes[k % len(nodes)]
    elif kind == "drop_init":
        del inits[k % len(inits)]
    elif kind in ("bias_len", "weight_shape"):
        cands = [i for i, t in enumerate(inits) if (len(t.dims) == 1) == (kind == "bias_len")]
        i = cands[k % len(cands)]
        a = numpy_helper.to_array(inits[i])
        if kind == "bias_len":
            n = (a.shape[0] + 1, max(a.shape[0] - 1, 0), 1)[r % 3]
            a = np.resize(a, n).astype(np.float32)
        else:
            a = (a.T, a[None], a[:-1] if a.shape[0] > 1 else a[:, :0])[r % 3].copy()
        inits[i].CopyFrom(numpy_helper.from_array(np.ascontiguousarray(a), inits[i].name))
    elif kind == "rewire":
        n = nodes[k % len(nodes)]
        names = ["x"] + [o for m in nodes for o in m.output] + [t.name for t in inits]
        n.input[r % len(n.input)] = names[(k + r) % len(names)]
    elif kind == "attr":
        n = nodes[k % len(nodes)]
        name = ("alpha", "beta", "transA", "transB")[r % 4]
        val = (0.5, 2.0, 0, 1)[(k + r) % 4]
        n.attribute.append(helper.make_attribute(name, float(val) if name in ("alpha", "beta")
                                                 else int(val)))
    elif kind == "extra_output":
        g.output.append(helper.make_tensor_value_info(nodes[k % len(nodes)].output[0],
                                                      TensorProto.FLOAT, None))
    elif kind == "self_loop":
        n = nodes[k % len(nodes)]
        n.output[0] = n.input[0]
    elif kind == "bytes":
        b = bytearray(model.SerializeToString())
        if r % 2:
            return bytes(b[:k % len(b)])
        b[k % len(b)] ^= 1 + r % 255
        return bytes(b)
    return model


def run_cli(src, contract_path, out):
    """onnx2policy's command line, in this process: (exit status, stderr)."""
    import contextlib
    import io
    err = io.StringIO()
    argv = sys.argv
    sys.argv = ["onnx2policy.py", src, "--contract", contract_path, "--out", out]
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            status = onnx2policy.main()
    finally:
        sys.argv = argv
    return status, err.getvalue()


class Malformed(unittest.TestCase):
    def test_malformed_graphs_refused_clearly_or_imported_exactly(self):
        """Any one change to a valid graph: the importer either refuses with
        exit status 2 and a message, writing no file, or writes a file whose
        forward pass equals the changed graph's own (ref_eval), never
        raising, hanging or writing a file the graph does not compute."""
        try:
            from hypothesis import example, given, settings, strategies as st
        except ImportError:
            self.skipTest("python3-hypothesis not installed")
        import signal

        def on_alarm(signum, frame):
            raise TimeoutError("the importer ran 10 s on a small graph")

        @settings(max_examples=60, deadline=None, database=None)
        # found by the search in a fresh-check (2026-12-03): a SiLU's Sigmoid
        # writing over its own input was imported
        @example(hidden=[1], act_list=["identity", "silu", "identity"], matmul=False,
                 kind="self_loop", k=2, r=0, seed=0)
        # and (2026-12-03, later): corrupt bytes on which protobuf warned on
        # stderr before the importer's own message
        @example(hidden=[], act_list=["identity", "identity", "identity"], matmul=False,
                 kind="bytes", k=0, r=768, seed=0)
        @given(hidden=st.lists(st.integers(1, 12), min_size=0, max_size=2),
               act_list=st.lists(st.sampled_from(["identity", "relu", "tanh", "silu"]),
                                 min_size=3, max_size=3),
               matmul=st.booleans(), kind=st.sampled_from(MUTATIONS),
               k=st.integers(0, 1000), r=st.integers(0, 1000), seed=st.integers(0, 1000))
        def prop(hidden, act_list, matmul, kind, k, r, seed):
            rng = np.random.default_rng(seed)
            sizes = [15] + hidden + [4]
            layers = rand_layers(rng, sizes, act_list[:len(sizes) - 1])
            m = mutate(graph(layers, matmul=matmul), kind, k, r)
            with tempfile.TemporaryDirectory() as d:
                src = os.path.join(d, "m.onnx")
                with open(src, "wb") as f:
                    f.write(m if isinstance(m, bytes) else m.SerializeToString())
                cpath = os.path.join(d, "c.json")
                with open(cpath, "w") as f:
                    json.dump(contract(4), f)
                out = os.path.join(d, "p.safetensors")
                old = signal.signal(signal.SIGALRM, on_alarm)
                signal.alarm(10)
                try:
                    status, err = run_cli(src, cpath, out)
                finally:
                    signal.alarm(0)
                    signal.signal(signal.SIGALRM, old)
                assert status in (0, 2), status
                if status == 2:
                    assert err.startswith("onnx2policy: ") and len(err) > 20, err
                    assert not os.path.exists(out), "a refusal left " + out
                    return
                x = rng.standard_normal((3, 15))
                model = m if not isinstance(m, bytes) else onnx.load_from_string(m)
                want = ref_eval(model, x)  # raises: accepted a graph that computes nothing
                got = psfile.forward(out, x)
                assert got.shape == want.shape and np.abs(got - want).max() < 1e-5, \
                    "imported file differs from the graph (%s)" % kind

        prop()


ROOT = os.path.join(HERE, "..", "..")
# The shipped file and its members, in make train's order: the runs
# recorded in bench/results that policy/weights/ps1_stage1.members lists
# (docs/policy.md).
SHIPPED = os.path.join(ROOT, "policy", "weights", "ps1_stage1.safetensors")


def shipped_members():
    """The recorded policy files the members list names (column 2)."""
    with open(os.path.join(ROOT, "policy", "weights", "ps1_stage1.members")) as f:
        rows = [line.split() for line in f if line.strip() and not line.lstrip().startswith("#")]
    return [os.path.join(ROOT, r[1]) for r in rows]


def member(d, name, rng, hidden, trained_by, **change):
    """A random policy file of contract(4) with its own normalisation."""
    c = contract(4)
    n_obs = len(c["observation"]["mean"])
    c["observation"]["mean"] = list(0.3 * rng.standard_normal(n_obs))
    c["observation"]["std"] = list(0.5 + rng.random(n_obs))
    c["activations"] = ["elu"] * len(hidden) + ["identity"]
    c["trained_by"] = trained_by
    c.update(change)
    sizes = [n_obs] + list(hidden) + [4]
    layers = [(w, b) for w, b, _ in rand_layers(rng, sizes, c["activations"])]
    p = os.path.join(d, name)
    psfile.write_policy(p, layers, c)
    return p


def run_policy(path, x):
    """The runtime's pass: normalise, clip, MLP (float64 reference)."""
    t, meta = psfile.read_safetensors(path)
    c = json.loads(meta[psfile.CONTRACT_KEY])
    o = c["observation"]
    z = np.clip((x - np.array(o["mean"])) / np.array(o["std"]), -o["clip"], o["clip"])
    return psfile.forward(t, z, contract=c)


class Ensemble(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.d = self.tmp.name
        self.rng = np.random.default_rng(11)

    def tearDown(self):
        self.tmp.cleanup()

    def test_computes_the_mean_of_its_members(self):
        cmd = "train.py --seed %d --envs 4"
        ps = [member(self.d, "m%d.st" % k, self.rng, h, cmd % k)
              for k, h in enumerate([(16, 16), (8, 24), (16, 16)])]
        out = os.path.join(self.d, "e.st")
        layers = ensemble.ensemble(ps, out)
        self.assertEqual([w.shape for w, _ in layers], [(40, 15), (56, 40), (4, 56)])
        t, meta = psfile.read_safetensors(out)
        c = json.loads(meta[psfile.CONTRACT_KEY])
        self.assertNotIn("groups", c)  # widths differ: dense, zeros and all
        self.assertEqual(c["observation"]["mean"], json.loads(psfile.read_safetensors(ps[0])[1][
            psfile.CONTRACT_KEY])["observation"]["mean"])
        self.assertEqual(c["trained_by"], "policy/train/ensemble.py, the mean of 3 policies: "
                         "train.py --seed 0 --envs 4; and with --seed 1; and with --seed 2")
        # observations within every member's clip: |x - mean| < 2.5, std >= 0.5, clip 5
        x = self.rng.uniform(-1.0, 1.0, (50, 15))
        want = np.mean([run_policy(p, x) for p in ps], axis=0)
        got = run_policy(out, x)
        self.assertLess(np.abs(got - want).max(), 1e-5)
        # one member alone differs from the mean by far more
        self.assertGreater(np.abs(run_policy(ps[0], x) - want).max(), 1e-2)

    def test_members_of_one_width_make_grouped_hidden_layers(self):
        ps = [member(self.d, "m%d.st" % k, self.rng, (16, 16), "a") for k in range(3)]
        out = os.path.join(self.d, "g.st")
        layers = ensemble.ensemble(ps, out)
        self.assertEqual([w.shape for w, _ in layers], [(48, 15), (48, 16), (4, 48)])
        c = json.loads(psfile.read_safetensors(out)[1][psfile.CONTRACT_KEY])
        self.assertEqual(c["groups"], [1, 3, 1])
        x = self.rng.uniform(-1.0, 1.0, (50, 15))
        want = np.mean([run_policy(p, x) for p in ps], axis=0)
        self.assertLess(np.abs(run_policy(out, x) - want).max(), 1e-5)
        # the grouped layer is the block-diagonal dense one without its zeros
        t, _ = psfile.read_safetensors(out)
        w1 = t["base.1.weight"]
        dense = np.zeros((48, 48), np.float32)
        for g in range(3):
            dense[16 * g:16 * (g + 1), 16 * g:16 * (g + 1)] = w1[16 * g:16 * (g + 1)]
        tt = dict(t)
        tt["base.1.weight"] = dense
        cd = dict(c)
        del cd["groups"]
        z = self.rng.standard_normal((20, 15))
        self.assertLess(np.abs(psfile.forward(t, z, contract=c) -
                               psfile.forward(tt, z, contract=cd)).max(), 1e-12)
        with self.assertRaisesRegex(ensemble.Refused, "g.st: has grouped layers"):
            ensemble.ensemble([out, ps[0]], os.path.join(self.d, "gg.st"))

    def test_same_members_same_bytes(self):
        ps = [member(self.d, "m%d.st" % k, self.rng, (8, 8), "a") for k in range(2)]
        a, b = os.path.join(self.d, "a.st"), os.path.join(self.d, "b.st")
        ensemble.ensemble(ps, a)
        ensemble.ensemble(ps, b)
        self.assertEqual(open(a, "rb").read(), open(b, "rb").read())

    def test_trained_by_in_full_where_more_than_options_differ(self):
        self.assertEqual(ensemble.describe(["x --seed 1", "y --seed 2"]),
                         "policy/train/ensemble.py, the mean of 2 policies: x --seed 1; "
                         "and y --seed 2")
        self.assertEqual(ensemble.describe(["x --seed 1", "x --seed 1"]),
                         "policy/train/ensemble.py, the mean of 2 policies: x --seed 1; "
                         "and the same command")
        self.assertEqual(ensemble.describe(["x --seed 1", "x --seed 1 --more"]),
                         "policy/train/ensemble.py, the mean of 2 policies: x --seed 1; "
                         "and x --seed 1 --more")

    def test_refuses_members_that_differ(self):
        base = member(self.d, "base.st", self.rng, (8, 8), "a")
        c = contract(4)
        cases = {
            "joints": {"joints": ["j1", "j0", "j2", "j3"]},
            "activations": {"activations": ["relu", "elu", "identity"]},
            "policy_hz": {"policy_hz": 100},
            "observation.clip": {"observation": dict(c["observation"], clip=3.0)},
            "action": {"action": dict(c["action"], scale=[0.2] * 4)},
        }
        for what, change in cases.items():
            other = member(self.d, "o.st", self.rng, (8, 8), "a", **change)
            out = os.path.join(self.d, "e.st")
            with self.assertRaises(ensemble.Refused) as e:
                ensemble.ensemble([base, other], out)
            self.assertIn("contract %s differs" % what, str(e.exception))
            self.assertFalse(os.path.exists(out))

    def test_refuses_adapters_one_member_and_a_non_policy(self):
        base = member(self.d, "base.st", self.rng, (8, 8), "a")
        t, meta = psfile.read_safetensors(base)
        c = json.loads(meta[psfile.CONTRACT_KEY])
        layers = [(t["base.%d.weight" % k], t["base.%d.bias" % k]) for k in range(3)]
        adapted = os.path.join(self.d, "adapted.st")
        psfile.write_policy(adapted, layers, c, adapters={1: (np.zeros((8, 8)), None)})
        with self.assertRaisesRegex(ensemble.Refused, "adapted.st: has adapt.1.weight"):
            ensemble.ensemble([base, adapted], os.path.join(self.d, "e.st"))
        with self.assertRaisesRegex(ensemble.Refused, "needs 2 or more policy files, 1 given"):
            ensemble.ensemble([base], os.path.join(self.d, "e.st"))
        junk = os.path.join(self.d, "junk.st")
        open(junk, "wb").write(b"\x08" + b"\0" * 7 + b"{}      ")
        with self.assertRaisesRegex(ensemble.Refused, "junk.st: not a policy file"):
            ensemble.ensemble([base, junk], os.path.join(self.d, "e.st"))

    def test_cli_refusal_exit_status(self):
        import subprocess
        base = member(self.d, "base.st", self.rng, (8, 8), "a")
        out = os.path.join(self.d, "e.st")
        r = subprocess.run([sys.executable, os.path.join(HERE, "ensemble.py"), "--out", out, base],
                           capture_output=True, text=True)
        self.assertEqual(r.returncode, 1)
        self.assertTrue(r.stderr.startswith("ensemble.py: refused: an ensemble needs 2"), r.stderr)
        self.assertFalse(os.path.exists(out))

    def test_shipped_file_is_make_trains_ensemble_of_its_members(self):
        out = os.path.join(self.d, "shipped.st")
        members = shipped_members()
        self.assertGreaterEqual(len(members), 2, "ps1_stage1.members lists fewer than 2 runs")
        ensemble.ensemble(members, out)
        self.assertEqual(open(out, "rb").read(), open(SHIPPED, "rb").read(),
                         "policy/weights/ps1_stage1.safetensors is not ensemble.py of its members")


PIN_PROBE = """import ctypes, hashlib, json, os, random, struct, sys
sys.path.insert(0, %r)
import portable
is_pinned, what = portable.pin()
import numpy
import torch
cap = [l.strip() for l in torch.__config__.show().splitlines() if "capability" in l]
libm = ctypes.CDLL("libm.so.6")
h = hashlib.sha256()
rng = random.Random(7)
for name in ("exp", "sin", "cos", "atan", "pow"):
    f = getattr(libm, name)
    f.restype = ctypes.c_double
    f.argtypes = [ctypes.c_double] * (2 if name == "pow" else 1)
    for _ in range(5000):
        x = rng.uniform(-20.0, 20.0)
        h.update(struct.pack("d", f(abs(x) + 1e-3, x / 7) if name == "pow" else f(x)))
print(json.dumps({"pinned": is_pinned, "refusal": portable.check_loaded(), "capability": cap,
                  "tunables": os.environ.get("GLIBC_TUNABLES"), "libm": h.hexdigest()}))
"""
PIN_VARS = ("LD_LIBRARY_PATH", "GLIBC_TUNABLES", "ATEN_CPU_CAPABILITY", "PUSHSTEP_TRAIN_NATIVE")


def cpu_flags():
    with open("/proc/cpuinfo") as f:
        for line in f:
            if line.startswith("flags"):
                return set(line.split(":", 1)[1].split())
    return set()


class Portable(unittest.TestCase):
    """train.py's float path (policy/train/portable.py)."""

    def test_pinned_env_puts_its_choices_first_and_keeps_the_users(self):
        blas, lapack = portable.reference_dirs()
        env = {"LD_LIBRARY_PATH": "/a:" + blas + ":/b", "X": "1",
               "GLIBC_TUNABLES": "glibc.malloc.check=3:glibc.cpu.hwcaps=-AVX512F,-FMA"}
        out = portable.pinned_env(env)
        self.assertEqual(out["LD_LIBRARY_PATH"], blas + ":" + lapack + ":/a:/b")
        self.assertEqual(out["ATEN_CPU_CAPABILITY"], "default")
        self.assertEqual(out["X"], "1")
        if os.uname().machine == "x86_64":
            self.assertEqual(out["GLIBC_TUNABLES"],
                             "glibc.malloc.check=3:glibc.cpu.hwcaps=-AVX512F,-FMA,-AVX2,-FMA4")
        self.assertEqual(portable.pinned_env(out), out, "pinning twice changes the environment")
        self.assertEqual(env["X"], "1")
        self.assertEqual(env["LD_LIBRARY_PATH"], "/a:" + blas + ":/b", "the caller's dict changed")

    def probe(self, **extra):
        with tempfile.TemporaryDirectory() as d:
            script = os.path.join(d, "probe.py")
            with open(script, "w") as f:
                f.write(PIN_PROBE % HERE)
            env = {k: v for k, v in os.environ.items() if k not in PIN_VARS}
            env.update(extra)
            r = subprocess.run([sys.executable, script], env=env, capture_output=True, text=True)
            self.assertEqual(r.returncode, 0, r.stderr)
            return json.loads(r.stdout)

    def test_a_script_that_pins_runs_on_the_portable_libraries(self):
        pinned = self.probe()
        self.assertTrue(pinned["pinned"], pinned)
        self.assertIsNone(pinned["refusal"])
        self.assertEqual(pinned["capability"], ["- CPU capability usage: NO AVX"])
        if os.uname().machine != "x86_64":
            return
        # libm's baseline variants: the same results as with glibc's vector
        # features masked wholesale, and, where this CPU would take the FMA
        # variants, other results than the machine's own.
        everything = "glibc.cpu.hwcaps=-AVX,-AVX2,-FMA,-FMA4,-AVX512F,-AVX512DQ,-AVX512BW,-AVX512VL"
        masked = self.probe(PUSHSTEP_TRAIN_NATIVE="1", GLIBC_TUNABLES=everything)
        self.assertEqual(pinned["libm"], masked["libm"], "libm is not on its baseline variants")
        if {"fma", "avx2"} <= cpu_flags():
            native = self.probe(PUSHSTEP_TRAIN_NATIVE="1")
            self.assertNotEqual(pinned["libm"], native["libm"], "libm kept its FMA variants")

    def test_native_keeps_the_machines_own(self):
        native = self.probe(PUSHSTEP_TRAIN_NATIVE="1")
        self.assertFalse(native["pinned"])
        self.assertIsNone(native["tunables"])
        if {"fma", "avx2"} <= cpu_flags():
            self.assertNotEqual(native["capability"], ["- CPU capability usage: NO AVX"])


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

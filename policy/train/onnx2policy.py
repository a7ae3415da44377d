#!/usr/bin/python3
"""Import an MLP policy exported to ONNX by an RL framework into a pushstep
policy file (safetensors with the contract, policy/ps_weights.h).

  onnx2policy.py MODEL.onnx --contract CONTRACT.json --out POLICY.safetensors

Supported graphs: one input, one output, a single chain of dense layers
(Gemm with alpha = beta = 1 and transA = 0, or MatMul followed by Add of a
bias) each optionally followed by one activation (Relu, Elu with alpha 1,
Tanh, Sigmoid, SiLU written as x * Sigmoid(x), Identity). Weights and
biases must be initializers. Anything else (another operator, a branch, a
weight computed at run time, a Gemm with transA or scaling, a bias that is
not one value per output, a node with the wrong number of inputs, a cycle)
is refused with the node and the reason; a file that is not ONNX, with
what the parser said. A refusal writes no file (exit status 2). CONTRACT.json gives what the graph cannot: joints,
gains, stance, policy_hz, observation layout and normalisation, action joints
and scale (policy/ps_weights.h, docs/policy.md); the activations come from
the graph. python3-onnx and numpy only.
"""
import argparse
import json
import os
import sys
import warnings

import numpy as np
import onnx
from google.protobuf.message import DecodeError
from onnx import numpy_helper

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import psfile  # noqa: E402

ACT_OPS = {"Relu": "relu", "Tanh": "tanh", "Sigmoid": "sigmoid", "Identity": "identity",
           "Elu": "elu"}


class Unsupported(Exception):
    pass


def _attrs(node):
    return {a.name: onnx.helper.get_attribute_value(a) for a in node.attribute}


def _where(node):
    return "node %s (%s)" % (node.name or "?", node.op_type)


def parse(model):
    """-> list of (W [out, in], b [out] or None, activation)."""
    g = model.graph
    inits = {i.name: numpy_helper.to_array(i) for i in g.initializer}
    inputs = [i.name for i in g.input if i.name not in inits]
    if len(inputs) != 1 or len(g.output) != 1:
        raise Unsupported("the graph has %d inputs and %d outputs; an MLP policy has one of each"
                          % (len(inputs), len(g.output)))
    consumers = {}
    for n in g.node:
        for i in n.input:
            consumers.setdefault(i, []).append(n)
    cur = inputs[0]
    layers = []
    nodes = list(g.node)
    used = set()
    seen = {cur}  # tensors computed so far on the chain

    def single_consumer(name):
        cs = consumers.get(name, [])
        if len(cs) == 1:
            return cs[0]
        if len(cs) == 2 and {c.op_type for c in cs} == {"Sigmoid", "Mul"}:
            return cs  # SiLU
        if not cs:
            return None
        raise Unsupported("tensor %s feeds %d nodes (%s): only a single chain is supported"
                          % (name, len(cs), ", ".join(_where(c) for c in cs)))

    while cur != g.output[0].name:
        nxt = single_consumer(cur)
        if nxt is None:
            raise Unsupported("tensor %s leads nowhere before the output" % cur)
        if isinstance(nxt, list):  # x * sigmoid(x)
            sig = [c for c in nxt if c.op_type == "Sigmoid"][0]
            mul = [c for c in nxt if c.op_type == "Mul"][0]
            # exactly y = x * s, s = Sigmoid(x), both new tensors: a Sigmoid that
            # writes over its own input leaves s computed by nothing
            if (list(sig.input) != [cur] or len(sig.output) != 1 or len(mul.output) != 1 or
                    sorted(mul.input) != sorted([cur, sig.output[0]]) or
                    sig.output[0] in seen or mul.output[0] in seen or
                    sig.output[0] == mul.output[0] or not layers or layers[-1][2] is not None):
                raise Unsupported("%s: not x * Sigmoid(x) after a dense layer" % _where(mul))
            seen.update([sig.output[0], mul.output[0]])
            layers[-1][2] = "silu"
            used.update([id(sig), id(mul)])
            cur = mul.output[0]
            continue
        n = nxt
        used.add(id(n))
        arity = {"Gemm": (2, 3), "MatMul": (2, 2), "Add": (2, 2)}.get(
            n.op_type, (1, 1) if n.op_type in ACT_OPS else (0, 99))
        if not arity[0] <= len(n.input) <= arity[1] or len(n.output) != 1:
            raise Unsupported("%s: %d inputs and %d outputs" % (_where(n), len(n.input),
                                                                len(n.output)))
        if n.output[0] in seen:
            raise Unsupported("%s: its output %s is computed earlier in the chain (a cycle)"
                              % (_where(n), n.output[0]))
        seen.add(n.output[0])
        if n.op_type == "Gemm":
            a = _attrs(n)
            if a.get("alpha", 1.0) != 1.0 or a.get("beta", 1.0) != 1.0 or a.get("transA", 0):
                raise Unsupported("%s: Gemm with alpha/beta other than 1 or transA" % _where(n))
            if n.input[0] != cur or n.input[1] not in inits or (
                    len(n.input) > 2 and n.input[2] not in inits):
                raise Unsupported("%s: weights must be initializers on the chain" % _where(n))
            w = inits[n.input[1]]
            if w.ndim != 2:
                raise Unsupported("%s: weight of shape %s, not a matrix" % (_where(n), w.shape))
            w = w if a.get("transB", 0) else w.T
            b = inits[n.input[2]] if len(n.input) > 2 else None
            if b is not None and b.shape != (w.shape[0],):
                raise Unsupported("%s: bias of shape %s for %d outputs (broadcast biases are "
                                  "not supported)" % (_where(n), b.shape, w.shape[0]))
            layers.append([w, b, None])
        elif n.op_type == "MatMul":
            if n.input[0] != cur or n.input[1] not in inits or inits[n.input[1]].ndim != 2:
                raise Unsupported("%s: MatMul must be x @ W with W a 2-D initializer" % _where(n))
            layers.append([inits[n.input[1]].T, None, None])
        elif n.op_type == "Add":
            other = [i for i in n.input if i != cur]
            if (not layers or layers[-1][1] is not None or layers[-1][2] is not None or
                    len(other) != 1 or other[0] not in inits or inits[other[0]].ndim != 1):
                raise Unsupported("%s: Add is only supported as the bias of a MatMul" % _where(n))
            if inits[other[0]].shape != (layers[-1][0].shape[0],):
                raise Unsupported("%s: bias of shape %s for %d outputs (broadcast biases are "
                                  "not supported)" % (_where(n), inits[other[0]].shape,
                                                      layers[-1][0].shape[0]))
            layers[-1][1] = inits[other[0]]
        elif n.op_type in ACT_OPS:
            if not layers or layers[-1][2] is not None:
                raise Unsupported("%s: an activation must follow a dense layer" % _where(n))
            if n.op_type == "Elu" and _attrs(n).get("alpha", 1.0) != 1.0:
                raise Unsupported("%s: Elu with alpha %g (only 1)" % (_where(n),
                                                                     _attrs(n)["alpha"]))
            layers[-1][2] = ACT_OPS[n.op_type]
        else:
            raise Unsupported("%s: operator %s is not supported (Gemm, MatMul+Add, Relu, Elu, "
                              "Tanh, Sigmoid, SiLU, Identity)" % (_where(n), n.op_type))
        cur = n.output[0]
    rest = [n for n in nodes if id(n) not in used]
    if rest:
        raise Unsupported("%s is not on the chain from input to output" % _where(rest[0]))
    for k in range(1, len(layers)):
        if layers[k][0].shape[1] != layers[k - 1][0].shape[0]:
            raise Unsupported("layer %d takes %d inputs, layer %d gives %d"
                              % (k, layers[k][0].shape[1], k - 1, layers[k - 1][0].shape[0]))
    if not layers:
        raise Unsupported("no dense layer")
    return [(np.asarray(w, np.float32), None if b is None else np.asarray(b, np.float32),
             a or "identity") for w, b, a in layers]


def convert(onnx_path, contract, out_path):
    # A corrupt file makes protobuf warn on stderr before it fails; the
    # failure is reported as our one clear line (hypothesis found this).
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = onnx.load(onnx_path)
    layers = parse(model)
    c = dict(contract)
    c["activations"] = [a for _, _, a in layers]
    for key in ("embed_activations", "inject_layer", "extra_size"):
        c.pop(key, None)
    psfile.write_policy(out_path, [(w, b) for w, b, _ in layers], c)
    return layers


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model")
    ap.add_argument("--contract", required=True, help="JSON file: the policy's contract")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    try:
        with open(a.contract) as f:
            contract = json.load(f)
        layers = convert(a.model, contract, a.out)
    except Unsupported as e:
        sys.stderr.write("onnx2policy: %s: refused: %s\n" % (a.model, e))
        return 2
    except (OSError, ValueError, KeyError, onnx.onnx_cpp2py_export.checker.ValidationError) as e:
        sys.stderr.write("onnx2policy: %s\n" % e)
        return 2
    except DecodeError as e:
        sys.stderr.write("onnx2policy: %s: not an ONNX model (%s)\n" % (a.model, e))
        return 2
    print("%s: %d layers (%s) -> %s" % (a.model, len(layers), ", ".join(
        "%dx%d %s" % (w.shape[1], w.shape[0], act) for w, _, act in layers), a.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())

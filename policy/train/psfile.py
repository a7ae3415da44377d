"""Policy files for pushstep: safetensors (written by hand: 8-byte header
length, JSON header, raw little-endian F32 tensors) with the contract in the
metadata key "pushstep.contract" (policy/ps_weights.h says what it holds).
numpy only, so the ONNX importer needs no torch.
"""
import json
import struct

import numpy as np

CONTRACT_KEY = "pushstep.contract"
VERSION = 1

# Sizes of the observation builder's fields (policy/ps_obs.h); "N" and "A"
# stand for the contract's joint and action counts.
OBS_FIELDS = {
    "gravity_body": 3, "gyro_body": 3, "joint_pos": "N", "joint_vel": "N",
    "prev_action": "A", "com_pos": 3, "com_vel": 3, "cop": 2, "capture_point": 2,
    "bos_margin": 1, "feet": 6, "contact": 2, "momentum": 6, "base_action": "A",
}
ACTIVATIONS = ("identity", "relu", "elu", "tanh", "sigmoid", "silu")


def obs_size(fields, n_joints, n_act):
    n = 0
    for f in fields:
        s = OBS_FIELDS[f]
        n += n_joints if s == "N" else (n_act if s == "A" else s)
    return n


def write_safetensors(path, tensors, metadata=None):
    """tensors: dict name -> numpy array (written as F32, in insertion order)."""
    header = {}
    blobs = []
    at = 0
    for name, arr in tensors.items():
        a = np.ascontiguousarray(np.asarray(arr, dtype="<f4"))
        b = a.tobytes()
        header[name] = {"dtype": "F32", "shape": list(a.shape), "data_offsets": [at, at + len(b)]}
        blobs.append(b)
        at += len(b)
    if metadata:
        header["__metadata__"] = {k: str(v) for k, v in metadata.items()}
    h = json.dumps(header, separators=(",", ":")).encode()
    h += b" " * ((8 - len(h) % 8) % 8)  # the data section starts 8-aligned
    with open(path, "wb") as f:
        f.write(struct.pack("<Q", len(h)))
        f.write(h)
        for b in blobs:
            f.write(b)


def read_safetensors(path):
    with open(path, "rb") as f:
        raw = f.read()
    (n,) = struct.unpack("<Q", raw[:8])
    header = json.loads(raw[8:8 + n])
    meta = header.pop("__metadata__", {})
    out = {}
    for name, e in header.items():
        if e["dtype"] != "F32":
            raise ValueError("%s: dtype %s" % (name, e["dtype"]))
        b, end = e["data_offsets"]
        out[name] = np.frombuffer(raw[8 + n + b:8 + n + end], dtype="<f4").reshape(e["shape"])
    return out, meta


def write_policy(path, layers, contract, adapters=None, embed=None):
    """layers: list of (W [out, in], b [out]); adapters: {k: (W, b)};
    embed: list of (W, b). contract: dict (checked for consistency here)."""
    c = dict(contract)
    c.setdefault("version", VERSION)
    groups = c.get("groups", [1] * len(layers))
    if len(groups) != len(layers):
        raise ValueError("%d groups for %d layers" % (len(groups), len(layers)))
    n_obs = obs_size(c["observation"]["fields"], len(c["joints"]), len(c["action"]["joints"]))
    if layers[0][0].shape[1] * groups[0] != n_obs:
        raise ValueError("first layer takes %d inputs, the observation has %d"
                         % (layers[0][0].shape[1] * groups[0], n_obs))
    if layers[-1][0].shape[0] != len(c["action"]["joints"]):
        raise ValueError("last layer gives %d outputs, %d actions"
                         % (layers[-1][0].shape[0], len(c["action"]["joints"])))
    if len(c["activations"]) != len(layers):
        raise ValueError("%d activations for %d layers" % (len(c["activations"]), len(layers)))
    t = {}
    for k, (w, b) in enumerate(layers):
        t["base.%d.weight" % k] = w
        if b is not None:
            t["base.%d.bias" % k] = b
    for k, (w, b) in (adapters or {}).items():
        t["adapt.%d.weight" % k] = w
        if b is not None:
            t["adapt.%d.bias" % k] = b
    for j, (w, b) in enumerate(embed or []):
        t["embed.%d.weight" % j] = w
        if b is not None:
            t["embed.%d.bias" % j] = b
    write_safetensors(path, t, {CONTRACT_KEY: json.dumps(c)})


def act(name, x):
    if name == "identity":
        return x
    if name == "relu":
        return np.maximum(x, 0)
    if name == "elu":
        return np.where(x > 0, x, np.expm1(np.minimum(x, 0)))
    if name == "tanh":
        return np.tanh(x)
    if name == "sigmoid":
        return 1 / (1 + np.exp(-x))
    if name == "silu":
        return x / (1 + np.exp(-x))
    raise ValueError(name)


def grouped(h, w, g):
    """h @ W^T for a layer in g groups (contract "groups", policy/ps_mlp.h):
    W is [out, in / g]; output block j reads input block j only."""
    if g == 1:
        return h @ w.T
    hs = np.split(h, g, axis=-1)
    ws = np.split(w, g, axis=0)
    return np.concatenate([a @ b.T for a, b in zip(hs, ws)], axis=-1)


def forward(path_or_tensors, x, extra=None, contract=None):
    """numpy reference forward pass of a policy file (float64)."""
    if isinstance(path_or_tensors, str):
        t, meta = read_safetensors(path_or_tensors)
        contract = json.loads(meta[CONTRACT_KEY])
    else:
        t = path_or_tensors
    acts = contract["activations"]
    h = np.asarray(x, dtype=np.float64)
    inj = None
    if "embed.0.weight" in t and extra is not None:
        e = np.asarray(extra, dtype=np.float64)
        j = 0
        while "embed.%d.weight" % j in t:
            e = e @ t["embed.%d.weight" % j].T.astype(np.float64) + t.get(
                "embed.%d.bias" % j, 0)
            e = act(contract["embed_activations"][j], e)
            j += 1
        inj = e
    groups = contract.get("groups", [1] * len(acts))
    for k in range(len(acts)):
        y = grouped(h, t["base.%d.weight" % k].astype(np.float64), groups[k]) + t.get(
            "base.%d.bias" % k, 0)
        if "adapt.%d.weight" % k in t:
            y = y + h @ t["adapt.%d.weight" % k].T.astype(np.float64) + t.get(
                "adapt.%d.bias" % k, 0)
        if inj is not None and k == contract.get("inject_layer", 0):
            y = y + inj
        h = act(acts[k], y)
    return h

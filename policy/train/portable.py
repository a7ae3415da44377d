"""Training's floating point, the same on every machine.

Three libraries under the trainer pick their code by the CPU they find, and
the choices round differently: ATen's vector kernels (AVX2 where the CPU has
it, portable C otherwise), the BLAS that Debian's alternatives point
libblas.so.3 at (OpenBLAS picks a kernel per CPU; the reference BLAS has
one) and glibc's libm (FMA variants of exp, sin, pow ... on CPUs with FMA and
AVX2), which the C environment's physics calls. A run of make train on one
machine therefore drifted from the same seed's run recorded on another
(2026-12-07: seed 2's learning log left the recorded one after 11 iterations
through ATen alone, after 17-24 through the BLAS or libm; docs/policy.md,
"Training").

pin() makes train.py run on the portable choice of each: ATen's default
kernels, the reference BLAS (package libblas3) ahead of any other, and
libm's baseline variants (x86-64: glibc's FMA, FMA4 and AVX2 ifuncs
masked). The loader reads the last two only when a process starts, so pin()
re-executes the script once with them set. PUSHSTEP_TRAIN_NATIVE=1 skips it:
the machine's own choices, faster where OpenBLAS is installed, but not the
recorded files.
"""
import os
import platform
import sys
import sysconfig

_MARK = "PUSHSTEP_TRAIN_PINNED"
_NATIVE = "PUSHSTEP_TRAIN_NATIVE"
_LIBM_MASK = "glibc.cpu.hwcaps=-AVX2,-FMA,-FMA4"


def reference_blas_dir():
    """Directory of Debian's reference libblas.so.3 (libblas3)."""
    multiarch = sysconfig.get_config_var("MULTIARCH") or ""
    return os.path.join("/usr/lib", multiarch, "blas")


def pinned_env(env):
    """The environment `env` with the portable choices set."""
    out = dict(env)
    out["ATEN_CPU_CAPABILITY"] = "default"
    ld = [reference_blas_dir()] + [p for p in env.get("LD_LIBRARY_PATH", "").split(":") if p]
    out["LD_LIBRARY_PATH"] = ":".join(ld)
    if platform.machine() == "x86_64":
        tunables = [t for t in env.get("GLIBC_TUNABLES", "").split(":") if t]
        out["GLIBC_TUNABLES"] = ":".join(tunables + [_LIBM_MASK])
    out[_MARK] = "1"
    return out


def pin():
    """Re-execute this Python script with the portable choices, once.

    Returns (is_pinned, description). Call before importing numpy or torch.
    Exits with a message when the reference BLAS is not installed."""
    if os.environ.get(_NATIVE) == "1":
        return False, "native (PUSHSTEP_TRAIN_NATIVE=1: this machine's BLAS, libm and ATen kernels)"
    blas = os.path.join(reference_blas_dir(), "libblas.so.3")
    if not os.path.exists(blas):
        sys.exit(f"train.py: {blas} not found: install libblas3 (make deps-train), "
                 f"or set {_NATIVE}=1 to train on this machine's own BLAS")
    if os.environ.get(_MARK) != "1":
        sys.stdout.flush()
        sys.stderr.flush()
        os.execve(sys.executable, [sys.executable] + sys.argv, pinned_env(os.environ))
    return True, f"portable (ATen default kernels, {blas}, libm baseline)"


def loaded_blas():
    """Path of the libblas.so.3 this process mapped (None before torch)."""
    with open("/proc/self/maps") as maps:
        for line in maps:
            path = line.split()[-1] if len(line.split()) >= 6 else ""
            if os.path.basename(path).startswith("libblas.so"):
                return os.path.realpath(path)
    return None


def check_loaded():
    """After torch is imported: the reference BLAS is the one mapped.

    Returns an error message, or None."""
    want = os.path.realpath(os.path.join(reference_blas_dir(), "libblas.so.3"))
    got = loaded_blas()
    if got != want:
        return f"train.py: pinned to {want}, but the process mapped {got}"
    return None

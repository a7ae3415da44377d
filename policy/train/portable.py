"""Training's floating point, the same on every x86-64 machine.

Three libraries under the trainer pick their code by the CPU they find, and
the choices round differently: ATen's vector kernels (AVX2 where the CPU has
it, portable C otherwise), the BLAS and LAPACK that Debian's alternatives
point libblas.so.3 and liblapack.so.3 at (OpenBLAS picks a kernel per CPU;
the reference libraries have one) and glibc's libm (FMA variants of exp,
sin, pow ... on CPUs with FMA and AVX2), which the C environment's physics
calls. A seeded run on one machine therefore drifted from the same seed's
run on another (2026-12-07: seed 2's learning log left the recorded one
after 11 iterations through ATen alone, after 17-24 through the BLAS or
libm; docs/policy.md, "The same floats on every x86-64 machine").

pin() makes train.py run on the portable choice of each: ATen's default
kernels, the reference BLAS and LAPACK (packages libblas3, liblapack3)
ahead of any other, and libm's baseline variants (x86-64: glibc's FMA, FMA4
and AVX2 ifuncs masked). The loader reads the last two only when a process
starts, so pin() re-executes the script once with them set.
PUSHSTEP_TRAIN_NATIVE=1 skips it: the machine's own choices, which train
other files than the recorded ones. aarch64 has its own portable paths
(ATen's default kernels and libm compiled for it): the same files on every
aarch64 machine, not the x86-64 ones.
"""
import os
import platform
import sys
import sysconfig

NATIVE = "PUSHSTEP_TRAIN_NATIVE"
HWCAPS = "glibc.cpu.hwcaps="
LIBM_MASK = ["-AVX2", "-FMA", "-FMA4"]


def reference_dirs():
    """Directories of Debian's reference libblas.so.3 and liblapack.so.3."""
    lib = os.path.join("/usr/lib", sysconfig.get_config_var("MULTIARCH") or "")
    return [os.path.join(lib, "blas"), os.path.join(lib, "lapack")]


def reference_libs():
    """(path, Debian package) of the reference libblas.so.3 and liblapack.so.3."""
    blas_dir, lapack_dir = reference_dirs()
    return [(os.path.join(blas_dir, "libblas.so.3"), "libblas3"),
            (os.path.join(lapack_dir, "liblapack.so.3"), "liblapack3")]


def _tunables_with_mask(value):
    """GLIBC_TUNABLES `value` with LIBM_MASK added to its hwcaps (one entry:
    glibc keeps the last value of a tunable, so a second would drop the
    user's own masks)."""
    entries = [t for t in value.split(":") if t]
    caps = [t for t in entries if t.startswith(HWCAPS)]
    rest = [t for t in entries if not t.startswith(HWCAPS)]
    have = [c for t in caps for c in t[len(HWCAPS):].split(",") if c]
    masks = have + [m for m in LIBM_MASK if m not in have]
    return ":".join(rest + [HWCAPS + ",".join(masks)])


def pinned_env(env):
    """The environment `env` with the portable choices set (a new dict)."""
    out = dict(env)
    out["ATEN_CPU_CAPABILITY"] = "default"
    first = reference_dirs()
    rest = [p for p in env.get("LD_LIBRARY_PATH", "").split(":") if p and p not in first]
    out["LD_LIBRARY_PATH"] = ":".join(first + rest)
    if platform.machine() == "x86_64":
        out["GLIBC_TUNABLES"] = _tunables_with_mask(env.get("GLIBC_TUNABLES", ""))
    return out


def pin():
    """Re-execute this Python script with the portable choices, once.

    Returns (is_pinned, description). Call before importing numpy or torch.
    Exits with a message when the reference libraries are not installed."""
    if os.environ.get(NATIVE) == "1":
        return False, f"native ({NATIVE}=1: this machine's BLAS, libm and ATen kernels)"
    for lib, pkg in reference_libs():
        if not os.path.exists(lib):
            sys.exit(f"train.py: {lib} not found: install {pkg} "
                     f"(make deps-train), or set {NATIVE}=1 to train on this machine's own")
    want = pinned_env(os.environ)
    keys = ("ATEN_CPU_CAPABILITY", "LD_LIBRARY_PATH", "GLIBC_TUNABLES")
    if any(os.environ.get(k) != want.get(k) for k in keys):
        sys.stdout.flush()
        sys.stderr.flush()
        # orig_argv keeps the interpreter's own flags (-u, -X ...).
        os.execve(sys.executable, [sys.executable] + sys.orig_argv[1:], want)
    return True, "portable (ATen default kernels, %s, libm baseline)" % (
        ", ".join(os.path.join(d, "") for d in reference_dirs()))


def mapped_libraries():
    """Paths of the shared objects this process has mapped."""
    paths = set()
    with open("/proc/self/maps") as maps:
        for line in maps:
            fields = line.rstrip("\n").split(None, 5)
            if len(fields) == 6 and fields[5].startswith("/"):
                paths.add(fields[5])
    return paths


def check_loaded():
    """After torch and numpy are imported: the BLAS mapped is the reference
    one, so is any LAPACK, and no other BLAS is (OpenBLAS's LAPACK brings
    its BLAS along). Returns an error message, or None."""
    mapped = mapped_libraries()
    (blas, _), (lapack, _) = reference_libs()
    want = {os.path.realpath(blas), os.path.realpath(lapack)}
    real = {p: os.path.realpath(p) for p in mapped}
    if os.path.realpath(blas) not in real.values():
        return f"train.py: pinned to {blas}, which the process did not map"
    other = sorted(p for p, r in real.items()
                   if (os.path.basename(r).startswith(("libblas", "liblapack")) and r not in want)
                   or any(k in os.path.basename(r) for k in ("openblas", "libmkl", "libblis")))
    if other:
        return "train.py: pinned to the reference BLAS and LAPACK, but the process mapped " + \
            ", ".join(other)
    return None

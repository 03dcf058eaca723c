"""Process environment for reproducible numerics: the same results on every x86-64 machine with AVX2.

OpenBLAS and numpy choose their kernels by the CPU they run on (OpenBLAS's ``DYNAMIC_ARCH``, numpy's
SIMD dispatch), and kernels for different instruction sets round differently in the last bits. The
planner's designs are nonlinear fits with several local optima, and its closed loop amplifies
last-bit differences: on an AVX-512 machine the centre designs of the rotation and the line sink
came out as other motions (the line sink's y-acceleration 25.6 against 21.5 m/s^2), and benchmark
scenes took 12.8 and 21.2 s instead of 8.8 and 12.5 s. A lab's regression replay, a benchmark
figure or a test's expected outcome must not depend on which PC runs it.

So, like MKL's ``MKL_CBWR``, the stack pins the kernels to the AVX2 (x86-64-v3) level, which
nearly every x86-64 machine of the last ten years has: ``OPENBLAS_CORETYPE=Haswell`` (only on a CPU
with AVX2 and FMA: elsewhere it would not run) and ``NPY_DISABLE_CPU_FEATURES`` for numpy's
dispatch targets above it. Both must be in the environment before numpy is imported: importing
``ppod_nodes`` does it (so ``ppod``, every node and every process they start are pinned), and so
does the test suite's ``conftest.py``. A variable already set is left as it is;
``PPOD_NATIVE_NUMERICS=1`` turns the pinning off. The numba kernels are not pinned: with these two
pins, the benchmark scenes that the tests hold (planned on an AVX-512 machine) took the times
measured on the machines of earlier sessions again. Other architectures (aarch64) run natively and
may differ in the last bits.
"""

from __future__ import annotations

import os
import platform
from collections.abc import MutableMapping

#: Set to 1 to run OpenBLAS and numpy on the kernels of this machine's own CPU.
OPT_OUT = "PPOD_NATIVE_NUMERICS"
#: OpenBLAS's kernels for the AVX2 + FMA level.
OPENBLAS_CORE = "Haswell"
#: numpy's dispatch targets above x86-64-v3 (AVX2): disabled (names this CPU lacks are ignored).
NUMPY_DISABLED = "X86_V4 AVX512_ICL AVX512_SPR"


def _cpu_flags(cpuinfo: str | None = None) -> set[str]:
    """The CPU's feature flags from ``/proc/cpuinfo`` (its text, if given), empty where unknown."""
    if cpuinfo is None:
        try:
            with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
                cpuinfo = f.read()
        except OSError:
            return set()
    for line in cpuinfo.splitlines():
        key, _, value = line.partition(":")
        if key.strip() == "flags":
            return set(value.split())
    return set()


def configure_numeric_environment(env: MutableMapping[str, str] | None = None, *, machine: str | None = None,
                                  cpuinfo: str | None = None) -> dict[str, str]:
    """Pin OpenBLAS and numpy to their AVX2 kernels in ``env`` (default ``os.environ``); returns what
    it set (nothing with ``PPOD_NATIVE_NUMERICS=1``, on another architecture, or where already set).
    ``machine`` and ``cpuinfo`` stand in for ``platform.machine()`` and ``/proc/cpuinfo`` in tests."""
    env = os.environ if env is None else env
    if env.get(OPT_OUT, "").strip() not in ("", "0"):
        return {}
    machine = platform.machine() if machine is None else machine
    if machine.lower() not in ("x86_64", "amd64"):
        return {}
    wanted = {"NPY_DISABLE_CPU_FEATURES": NUMPY_DISABLED}
    if {"avx2", "fma"} <= _cpu_flags(cpuinfo):
        wanted["OPENBLAS_CORETYPE"] = OPENBLAS_CORE
    done = {}
    for key, value in wanted.items():
        if key not in env:
            env[key] = done[key] = value
    return done


__all__ = ["NUMPY_DISABLED", "OPENBLAS_CORE", "OPT_OUT", "configure_numeric_environment"]

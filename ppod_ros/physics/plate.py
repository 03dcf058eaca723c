"""Plate motion as a compact coefficient table, evaluated inside compiled kernels.

A :class:`~ppod_ros.motion.PlateMotion` becomes a float64 table with one row per harmonic that is
present (zero-amplitude harmonics are pruned, so they cost nothing in the time stepping). With
``x = k Omega t`` each of the six axes j is

    u_j(t) = as_j sin x + ac_j cos x                  (acceleration, m/s^2 or rad/s^2)
    v_j(t) = vs_j sin x + vc_j cos x                  (zero-mean velocity)
    d_j(t) = ds_j sin x + dc_j cos x                  (zero-mean displacement)

summed over the rows. Columns: ``[k Omega, as(6), ac(6), vs(6), vc(6), ds(6), dc(6), k, Omega]``.
One ``sin``/``cos`` pair per time gives all 18 series: the pair of the fundamental, then the
angle-addition recurrence up to each present harmonic (rows ascend in k), instead of one pair per
harmonic.
"""

from __future__ import annotations

import math

import numpy as np

from ppod_ros.motion import GRAVITY_MPS2, PlateMotion
from ppod_ros.physics._jit import njit

#: Column offsets in the coefficient table.
COL_W, COL_AS, COL_AC, COL_VS, COL_VC, COL_DS, COL_DC = 0, 1, 7, 13, 19, 25, 31
COL_K, COL_OMEGA = 37, 38  # harmonic number, fundamental (rad/s): the sin/cos recurrence
TABLE_COLS = 39
G = GRAVITY_MPS2


def motion_table(motion: PlateMotion, prune: bool = True) -> np.ndarray:
    """The coefficient table of ``motion``, shape (K, 39).

    Parameters
    ----------
    motion : PlateMotion
    prune : bool
        Drop harmonics whose six amplitudes are all zero (the default). ``False`` keeps them, which
        only costs time (used by the benchmark to show what pruning saves).
    """
    rows = []
    # A frequency so low that a velocity or displacement overflows (an untrusted file's 1e-160 Hz)
    # gives inf coefficients, which the solver reports as invalid rows: no warning for it here.
    with np.errstate(over="ignore"):
        for k, amp, ph in zip(motion.k, motion.amplitude, motion.phase):
            if prune and not np.any(amp > 0):
                continue
            w = motion.omega * float(k)
            a_s = amp * np.cos(ph)
            a_c = amp * np.sin(ph)
            # v = -A/w cos(x + phi) = (A sin phi / w) sin x - (A cos phi / w) cos x
            v_s = a_c / w
            v_c = -a_s / w
            # d = -A/w^2 sin(x + phi)
            d_s = -a_s / w**2
            d_c = -a_c / w**2
            rows.append(np.concatenate([[w], a_s, a_c, v_s, v_c, d_s, d_c, [float(k), motion.omega]]))
    if not rows:
        return np.zeros((0, TABLE_COLS))
    return np.ascontiguousarray(np.array(rows, dtype=np.float64))


def table_kmax(table: np.ndarray, omega: float) -> int:
    """Highest harmonic number present in a table (at least 1)."""
    if table.shape[0] == 0:
        return 1
    return max(1, int(round(float(table[:, COL_W].max()) / omega)))


@njit(cache=True, error_model="numpy", inline="always")
def plate_eval(mc, t, W, ou, ov):
    """Write the plate acceleration into W[ou:ou+6] and its velocity into W[ov:ov+6] at time t.

    (Offsets instead of array slices: slicing in numba costs reference counting in hot loops.)
    """
    for j in range(6):
        W[ou + j] = 0.0
        W[ov + j] = 0.0
    nr = mc.shape[0]
    s1 = 0.0
    c1 = 1.0
    sk = 0.0
    ck = 1.0
    k = 0
    if nr > 1:
        x1 = mc[0, COL_OMEGA] * t
        s1 = math.sin(x1)
        c1 = math.cos(x1)
    for r in range(nr):
        if nr == 1:
            x = mc[r, 0] * t
            s = math.sin(x)
            c = math.cos(x)
        else:
            # sin/cos of k Omega t by angle addition from the fundamental (rows ascend in k).
            target = int(mc[r, COL_K])
            while k < target:
                sk, ck = sk * c1 + ck * s1, ck * c1 - sk * s1
                k += 1
            s = sk
            c = ck
        for j in range(6):
            W[ou + j] += mc[r, 1 + j] * s + mc[r, 7 + j] * c
            W[ov + j] += mc[r, 13 + j] * s + mc[r, 19 + j] * c


@njit(cache=True, error_model="numpy")
def point_velocity_scale(mc, x, y):
    """Bound on |v_h| at plate point (x, y): the natural velocity scale for tolerances (m/s)."""
    total = 0.0
    for r in range(mc.shape[0]):
        vx_s = mc[r, 13] - mc[r, 18] * y
        vx_c = mc[r, 19] - mc[r, 24] * y
        vy_s = mc[r, 14] + mc[r, 18] * x
        vy_c = mc[r, 20] + mc[r, 24] * x
        total += math.sqrt(vx_s * vx_s + vx_c * vx_c + vy_s * vy_s + vy_c * vy_c)
    return total


@njit(cache=True, error_model="numpy")
def min_normal_accel(mc, x, y, period, nscan):
    """Minimum over one period of n(t) = g + a_n(x, y, t) (m/s^2): sampled, then refined.

    The sample with the smallest value is refined by golden-section search on its two neighbouring
    intervals, so the minimum is found to ~1e-12 relative unless two minima lie within one sample
    spacing (``nscan`` should be ~32 per harmonic). A one-harmonic table's minimum is exact,
    ``g - |(S, C)|``, without sampling.
    """
    if mc.shape[0] == 0:
        return G
    if mc.shape[0] == 1:
        # One harmonic: n = g + S sin(k Omega t) + C cos(k Omega t), whose minimum is exact.
        return G - math.hypot(mc[0, 3] + mc[0, 4] * y - mc[0, 5] * x, mc[0, 9] + mc[0, 10] * y - mc[0, 11] * x)
    best = 1e300
    ibest = 0
    dt = period / nscan
    for i in range(nscan):
        val = _normal_at(mc, x, y, i * dt)
        if val < best:
            best = val
            ibest = i
    a = (ibest - 1) * dt
    b = (ibest + 1) * dt
    gr = 0.6180339887498949
    c = b - gr * (b - a)
    d = a + gr * (b - a)
    fc = _normal_at(mc, x, y, c)
    fd = _normal_at(mc, x, y, d)
    for _ in range(80):
        if fc < fd:
            b = d
            d = c
            fd = fc
            c = b - gr * (b - a)
            fc = _normal_at(mc, x, y, c)
        else:
            a = c
            c = d
            fc = fd
            d = a + gr * (b - a)
            fd = _normal_at(mc, x, y, d)
        if b - a < 1e-14 * period:
            break
    return min(best, fc, fd)


@njit(cache=True, error_model="numpy")
def _normal_at(mc, x, y, t):
    n = G
    for r in range(mc.shape[0]):
        ph = mc[r, 0] * t
        s = math.sin(ph)
        c = math.cos(ph)
        n += (mc[r, 3] + mc[r, 4] * y - mc[r, 5] * x) * s + (mc[r, 9] + mc[r, 10] * y - mc[r, 11] * x) * c
    return n


__all__ = [
    "COL_AC", "COL_AS", "COL_DC", "COL_DS", "COL_K", "COL_OMEGA", "COL_VC", "COL_VS", "COL_W", "G",
    "TABLE_COLS",
    "min_normal_accel", "motion_table", "plate_eval", "point_velocity_scale", "table_kmax",
]

"""An independent fixed-step reference for point parts (``ppod bench solver`` accuracy tables).

Written from PHYSICS.md alone and sharing no code with ``ppod_ros.physics``: a fixed grid of
``steps`` steps per period (at least 25,600), classical RK4 while the part slides clearly, and an
exact-impulse step (Moreau's time-stepping with the plate's velocity change and the integral of
the normal force over the step, both in closed form) where the relative velocity is near zero or
the part sticks: that step resolves stopping, sticking and break-away inside the step without
locating events. The period average is the trapezoid rule on the same grid; periods are iterated
until the cycle start and the average repeat to ``tol_mps``. Its own error is estimated by running
at ``steps`` and ``2 steps`` (``reference_average(..., check=True)``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

G_MPS2 = 9.81
#: Relative speeds below this many (max acceleration x step) are handled by the impulse step.
NEAR_ZERO_STEPS = 4.0
#: Substeps of the impulse step.
IMPULSE_SUBSTEPS = 256


def plate_coefficients(motion) -> np.ndarray:
    """Rows [k Omega, A cos(phi) (6), A sin(phi) (6)]: u_j(t) = A_j sin(k Omega t + phi_j)."""
    rows = []
    for k, amp, ph in zip(motion.k, np.asarray(motion.amplitude, float), np.asarray(motion.phase, float)):
        rows.append(np.concatenate([[motion.omega * float(k)], amp * np.cos(ph), amp * np.sin(ph)]))
    return np.array(rows, float)


@njit(cache=True)
def _plate(cf, x, y, t, out):
    """out = [a_hx, a_hy, n, v_hx, v_hy, N(t) - g t] at plate point (x, y), time t."""
    u = np.zeros(6)
    v = np.zeros(6)
    for r in range(cf.shape[0]):
        w = cf[r, 0]
        s = math.sin(w * t)
        c = math.cos(w * t)
        for j in range(6):
            cp = cf[r, 1 + j]
            sp = cf[r, 7 + j]
            u[j] += cp * s + sp * c            # A sin(wt + phi)
            v[j] += (-cp * c + sp * s) / w     # -A/w cos(wt + phi), its zero-mean integral
    out[0] = u[0] - u[5] * y
    out[1] = u[1] + u[5] * x
    out[2] = G_MPS2 + u[2] + u[3] * y - u[4] * x
    out[3] = v[0] - v[5] * y
    out[4] = v[1] + v[5] * x
    out[5] = v[2] + v[3] * y - v[4] * x


@njit(cache=True)
def _slide_rhs(cf, x, y, t, s0, s1, mu, k, buf):
    _plate(cf, x, y, t, buf)
    w0 = s0 - buf[3]
    w1 = s1 - buf[4]
    nw = math.hypot(w0, w1)
    k[0] = -mu * buf[2] * w0 / nw
    k[1] = -mu * buf[2] * w1 / nw


@njit(cache=True)
def _impulse_steps(cf, x, y, mu, mus, t, h, s, stuck, a, b):
    hs = h / IMPULSE_SUBSTEPS
    _plate(cf, x, y, t, a)
    for q in range(IMPULSE_SUBSTEPS):
        _plate(cf, x, y, t + (q + 1) * hs, b)
        if stuck and math.hypot(b[0], b[1]) <= mus * b[2]:
            s[0] = b[3]
            s[1] = b[4]
        else:
            w0 = 0.0 if stuck else s[0] - a[3]
            w1 = 0.0 if stuck else s[1] - a[4]
            ws0 = w0 - (b[3] - a[3])
            ws1 = w1 - (b[4] - a[4])
            imp = mu * (G_MPS2 * hs + b[5] - a[5])
            nws = math.hypot(ws0, ws1)
            if nws <= imp:
                s[0] = b[3]
                s[1] = b[4]
                stuck = True
            else:
                s[0] = b[3] + ws0 - imp * ws0 / nws
                s[1] = b[4] + ws1 - imp * ws1 / nws
                stuck = False
        for j in range(6):
            a[j] = b[j]
    return stuck


@njit(cache=True)
def one_period(cf, x, y, mu, mus, T, steps, s, stuck):
    """Advance s (2,) over one period in place; returns (average vx, vy, still stuck at the end)."""
    h = T / steps
    a = np.zeros(6)
    b = np.zeros(6)
    k1 = np.zeros(2)
    k2 = np.zeros(2)
    k3 = np.zeros(2)
    k4 = np.zeros(2)
    amax = 0.0
    for r in range(cf.shape[0]):
        for j in range(6):
            amax += math.hypot(cf[r, 1 + j], cf[r, 7 + j]) * (1.0 + 0.1)
    near = NEAR_ZERO_STEPS * (amax + mu * (G_MPS2 + amax)) * h
    sx = 0.5 * s[0]
    sy = 0.5 * s[1]
    for i in range(steps):
        t = i * h
        _plate(cf, x, y, t, a)
        _plate(cf, x, y, t + h, b)
        if stuck and math.hypot(b[0], b[1]) <= mus * b[2]:
            s[0] = b[3]
            s[1] = b[4]
        else:
            w0 = s[0] - a[3]
            w1 = s[1] - a[4]
            if not stuck and math.hypot(w0, w1) > near:
                _slide_rhs(cf, x, y, t, s[0], s[1], mu, k1, a)
                _slide_rhs(cf, x, y, t + 0.5 * h, s[0] + 0.5 * h * k1[0], s[1] + 0.5 * h * k1[1], mu, k2, a)
                _slide_rhs(cf, x, y, t + 0.5 * h, s[0] + 0.5 * h * k2[0], s[1] + 0.5 * h * k2[1], mu, k3, a)
                _slide_rhs(cf, x, y, t + h, s[0] + h * k3[0], s[1] + h * k3[1], mu, k4, a)
                s[0] += h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
                s[1] += h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
            else:
                # Exact impulses (plate velocity change, mu * integral of n) over IMPULSE_SUBSTEPS
                # substeps: stopping, sticking, reversal and break-away inside the step, each
                # substep's only error being where the friction direction turns within it.
                stuck = _impulse_steps(cf, x, y, mu, mus, t, h, s, stuck, a, b)
        if i < steps - 1:
            sx += s[0]
            sy += s[1]
    sx += 0.5 * s[0]
    sy += 0.5 * s[1]
    return sx / steps, sy / steps, stuck


@njit(cache=True)
def _min_normal(cf, x, y, T, samples):
    buf = np.zeros(6)
    lo = 1e300
    for i in range(samples):
        _plate(cf, x, y, T * i / samples, buf)
        lo = min(lo, buf[2])
    return lo


def reference_average(motion, mu: float, x: float, y: float, steps: int = 25_600, start=None,
                      tol_mps: float = 1e-12, max_periods: int = 3000, mu_static: float | None = None):
    """(average velocity (2,), periods) of the limit cycle at plate point (x, y); NaN if contact is
    lost (n <= 0 somewhere on a 4096-sample scan) or not converged."""
    if steps < 25_600:
        raise ValueError(f"steps: at least 25,600 per period, got {steps}")
    cf = plate_coefficients(motion)
    T = motion.period_s
    if _min_normal(cf, x, y, T, 4096) <= 0.0:
        return np.full(2, np.nan), 0
    mus = mu if mu_static is None else mu_static
    s = np.zeros(2) if start is None else np.array(start, float)
    stuck = False
    last = np.full(2, np.nan)
    for p in range(max_periods):
        s_begin = s.copy()
        vx, vy, stuck = one_period(cf, x, y, mu, mus, T, steps, s, stuck)
        avg = np.array([vx, vy])
        if p > 0 and np.abs(avg - last).max() <= tol_mps and np.abs(s - s_begin).max() <= tol_mps:
            return avg, p + 1
        last = avg
    return np.full(2, np.nan), max_periods


__all__ = ["plate_coefficients", "reference_average"]

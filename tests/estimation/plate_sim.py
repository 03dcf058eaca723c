"""Test oracle: an independent time-domain rigid-body simulation of the plate's accelerometers.

It shares no code with ppod_ros.estimation. The plate's pose is exact: origin at p(t) and
orientation R(t) = expm([theta(t)]x) (rotation matrices, no small-angle formulas), with p'' and the
rotation vector's theta'' having the motion's harmonics. R' and R'' come exactly from one matrix
exponential of a block-Toeplitz matrix (exp of A(t+s) = A + s A' + s^2 A''/2 truncated at s^2),
not from finite differences. A channel at l with axis e reads the specific force in the plate frame,
e . R^T (p'' + R'' l + g z), minus the static e_z g that AC coupling removes.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

G = 9.81


def skew(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def harmonic_series(
    X: np.ndarray, k: np.ndarray, omega: float, t: np.ndarray, integrals: int = 0
) -> np.ndarray:
    """sum_k Im(X_k / (i k Omega)^n e^{i k Omega t}), the n-th zero-mean integral; shape (N, cols)."""
    X = np.asarray(X, complex) / (1j * omega * np.asarray(k)[:, None]) ** integrals
    return np.imag(np.exp(1j * omega * np.outer(t, k)) @ X)


def plate_pose(U: np.ndarray, k: np.ndarray, frequency_hz: float, t: np.ndarray):
    """p'' (N, 3) and R, R', R'' (N, 3, 3) of the motion with phasors U (K, 6) at harmonics k."""
    omega = 2 * np.pi * frequency_hz
    acc = harmonic_series(U[:, :3], k, omega, t)
    theta = harmonic_series(U[:, 3:], k, omega, t, 2)
    dtheta = harmonic_series(U[:, 3:], k, omega, t, 1)
    ddtheta = harmonic_series(U[:, 3:], k, omega, t)
    N = t.size
    block = np.zeros((N, 9, 9))
    for i in range(3):
        block[:, 3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = skew(theta)
    block[:, 0:3, 3:6] = block[:, 3:6, 6:9] = skew(dtheta)
    block[:, 0:3, 6:9] = 0.5 * skew(ddtheta)
    E = expm(block)
    return acc, E[:, 0:3, 0:3], E[:, 0:3, 3:6], 2.0 * E[:, 0:3, 6:9]


def readings(
    U: np.ndarray,
    k,
    frequency_hz: float,
    t: np.ndarray,
    position_m: np.ndarray,
    axis: np.ndarray,
    gravity: float = G,
) -> np.ndarray:
    """Exact sensor readings (N, C) (static 1 g removed) of channels at position_m (C, 3), axis (C, 3)."""
    t = np.asarray(t, float)
    acc, R, _, Rdd = plate_pose(np.asarray(U, complex), np.asarray(k), frequency_hz, t)
    world = acc[:, None, :] + np.einsum("nij,cj->nci", Rdd, position_m) + np.array([0, 0, gravity])
    body = np.einsum("nji,ncj->nci", R, world)  # R^T f
    return np.einsum("nci,ci->nc", body, axis) - gravity * axis[:, 2]


def first_order_readings(U, k, frequency_hz, t, position_m, axis) -> np.ndarray:
    """The first-order model e . (p'' + alpha x l), without gravity or second-order terms (N, C)."""
    omega = 2 * np.pi * frequency_hz
    u = harmonic_series(U, np.asarray(k), omega, np.asarray(t, float))
    lin = u[:, None, :3] + np.cross(u[:, None, 3:], position_m[None])
    return np.einsum("nci,ci->nc", lin, axis)


def sample_times(frequency_hz: float, cycles: float, rate_hz: float, start_s: float = 0.0) -> np.ndarray:
    """Uniform sample times from ``start_s`` (a cycle start when 0) over ``cycles`` periods."""
    n = int(round(cycles * rate_hz / frequency_hz))
    return start_s + np.arange(n) / rate_hz

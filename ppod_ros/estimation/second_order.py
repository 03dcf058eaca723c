"""Second-order terms of an accelerometer reading on the vibrating plate.

Convention (docs/feedback.md, "Sensor model"): the plate's pose is periodic, its origin at p(t) in the
nominal plate frame and its orientation ``R(t) = exp([theta(t)]x)`` with the rotation vector theta
the zero-mean double integral of alpha; the motion's harmonics are those of (p'', theta''). A channel
at l with axis e reads the specific force in the plate frame with the static 1 g removed::

    r = e . R^T (p'' + R'' l + g z) - e_z g

Expanding R = I + [theta]x + [theta]x^2 / 2 + ... to second order in the motion:

    first order:  e . (p'' + theta'' x l - g theta x z)          (the layout's measurement matrix)
    second order: e . ( omega x (omega x l)          "centripetal"  (omega = theta')
                        - theta x p''                 "frame"        (p'' seen in the tilted frame)
                        - (theta x theta'') x l / 2   "euler"        (body vs rotation-vector alpha)
                        + g theta x (theta x z) / 2 ) "gravity"      (cosine of the tilt)

The second-order terms are products of harmonics, so they appear at 0 Hz and at sums and differences
of the plate's frequencies (twice the fundamental for a one-harmonic motion). They are evaluated here
on a time grid over one period and transformed back to phasors exactly (the grid is fine enough that
no product aliases onto a harmonic that is returned).
"""

from __future__ import annotations

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.motion import GRAVITY_MPS2

#: Every second-order term the estimator knows, in the order of the module docstring.
SECOND_ORDER_TERMS = ("centripetal", "frame", "euler", "gravity")


def check_terms(terms: tuple[str, ...] | list[str]) -> tuple[str, ...]:
    terms = tuple(terms)
    unknown = [t for t in terms if t not in SECOND_ORDER_TERMS]
    if unknown:
        raise ConfigError(
            f"second_order_terms: unknown {unknown}; expected a subset of {list(SECOND_ORDER_TERMS)}"
        )
    return terms


def _series(X: np.ndarray, omega_k: np.ndarray, phase: np.ndarray) -> np.ndarray:
    # X (K, 3) phasors, phase (M, K) = k Omega t: sum_k Im(X_k e^{i k Omega t}) -> (M, 3)
    return np.imag(np.exp(1j * phase) @ X)


def second_order_phasors(
    U: np.ndarray,
    frequency_hz: float,
    position_m: np.ndarray,
    axis: np.ndarray,
    terms: tuple[str, ...] = SECOND_ORDER_TERMS,
    gravity_mps2: float = GRAVITY_MPS2,
) -> np.ndarray:
    """Phasors of the second-order reading of each channel at harmonics 1..K.

    Parameters
    ----------
    U : complex array_like, shape (K, 6)
        Plate motion phasors of harmonics 1..K (row k-1 holds harmonic k): [p'', alpha].
    frequency_hz : float
        Fundamental f (Hz).
    position_m, axis : array_like, shape (C, 3)
        Channel positions l (m) and unit sensing axes e, plate frame.
    terms : tuple of str
        Which terms of :data:`SECOND_ORDER_TERMS` to include.

    Returns
    -------
    complex ndarray, shape (K, C)
        Second-order reading of each channel per harmonic (m/s^2).
    """
    U = np.asarray(U, dtype=complex)
    if U.ndim != 2 or U.shape[1] != 6:
        raise ConfigError(f"U: expected shape (K, 6), got {U.shape}")
    terms = check_terms(terms)
    K = U.shape[0]
    l = np.asarray(position_m, float)
    e = np.asarray(axis, float)
    if not terms or K == 0:
        return np.zeros((K, l.shape[0]), dtype=complex)
    omega = 2.0 * np.pi * frequency_hz
    k = np.arange(1, K + 1)
    wk = omega * k
    # Products reach harmonic 2K; with M > 3K samples, none of them aliases onto harmonics 1..K.
    M = 4 * K + 4
    phase = np.outer(np.arange(M) / M * 2.0 * np.pi, k)  # k Omega t over one period, (M, K)
    acc_lin = _series(U[:, :3], wk, phase)  # p''
    alpha = _series(U[:, 3:], wk, phase)  # theta''
    rate = _series(U[:, 3:] / (1j * wk[:, None]), wk, phase)  # theta'  (omega)
    tilt = _series(-U[:, 3:] / wk[:, None] ** 2, wk, phase)  # theta
    z = np.array([0.0, 0.0, 1.0])
    vec = np.zeros((M, l.shape[0], 3))
    if "centripetal" in terms:
        vec += np.cross(rate[:, None, :], np.cross(rate[:, None, :], l[None, :, :]))
    if "frame" in terms:
        vec -= np.cross(tilt, acc_lin)[:, None, :]
    if "euler" in terms:
        vec -= 0.5 * np.cross(np.cross(tilt, alpha)[:, None, :], l[None, :, :])
    if "gravity" in terms:
        vec += 0.5 * gravity_mps2 * np.cross(tilt, np.cross(tilt, z))[:, None, :]
    reading = np.einsum("mcj,cj->mc", vec, e)  # (M, C)
    # DFT coefficient c_k = (1/M) sum r e^{-i k Omega t} = X_k / (2i) for r = Im(X_k e^{i k Omega t}).
    ck = np.exp(-1j * phase).T @ reading / M  # (K, C)
    return 2j * ck


__all__ = ["SECOND_ORDER_TERMS", "second_order_phasors"]

"""Harmonic tables: synthesis, analysis over one cycle, peaks and RMS values.

Every periodic signal in the stack follows PHYSICS.md's phasor convention: harmonic k of a channel
is the complex number X_k and the signal is ``y(t) = sum_k Im(X_k exp(i k Omega t))`` with t = 0 at
a cycle start. A *table* is an array of phasors, shape (K, C): rows are harmonics (listed in a
separate ``k`` array, or dense 1..K), columns are channels (actuators, axes, legs).
"""

from __future__ import annotations

import math

import numpy as np

from ppod_ros.errors import ConfigError

#: Samples per period of the highest harmonic used to evaluate peaks: the sampled peak of a
#: sinusoid underestimates the true one by at most 1 - cos(pi / 64) = 0.12 %.
PEAK_SAMPLES_PER_PERIOD = 64


def cycle_phases(n: int) -> np.ndarray:
    """Phases Omega t_n = 2 pi n / N of N equally spaced samples starting at a cycle start, shape (N,)."""
    if n < 1:
        raise ConfigError(f"n: need at least one sample per cycle, got {n}")
    return 2.0 * math.pi * np.arange(n) / n


def dense_k(kmax: int) -> np.ndarray:
    return np.arange(1, int(kmax) + 1)


def synthesize(table: np.ndarray, k: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Evaluate ``sum_k Im(X_k exp(i k theta))``.

    Parameters
    ----------
    table : complex array, shape (K, C)
    k : int array, shape (K,)
    theta : array, shape (N,)
        Phase of the fundamental, Omega t (rad).

    Returns
    -------
    ndarray, shape (N, C)
    """
    table = np.asarray(table, dtype=complex)
    k = np.asarray(k)
    theta = np.asarray(theta, dtype=float)
    if table.ndim != 2 or k.shape != (table.shape[0],):
        raise ConfigError(f"table, k: expected shapes (K, C) and (K,), got {table.shape} and {k.shape}")
    if table.shape[0] == 0:
        return np.zeros((theta.size, table.shape[1]))
    basis = np.exp(1j * np.outer(theta, k))  # (N, K)
    return (basis @ table).imag


def analyze(samples: np.ndarray, kmax: int) -> np.ndarray:
    """Phasors of harmonics 1..kmax of samples taken at theta_n = 2 pi n / N over one cycle.

    ``X_k = (2 i / N) sum_n y_n exp(-i k theta_n)`` is exact for band-limited signals with no
    harmonic at or above N / 2 (the samples must cover exactly one period, first sample at the
    cycle start).

    Parameters
    ----------
    samples : array, shape (N, ...)
    kmax : int, < N / 2

    Returns
    -------
    complex ndarray, shape (kmax, ...)
    """
    y = np.asarray(samples, dtype=float)
    n = y.shape[0]
    if not 0 <= kmax < n / 2:
        raise ConfigError(f"kmax: must be below half the samples per cycle ({n / 2:g}), got {kmax}")
    spectrum = np.fft.rfft(y, axis=0)[1 : kmax + 1]
    return (2j / n) * spectrum


def peak_abs(
    table: np.ndarray, k: np.ndarray, samples_per_period: int = PEAK_SAMPLES_PER_PERIOD
) -> np.ndarray:
    """Peak of |y(t)| over one cycle per channel, shape (C,), sampled densely (see module note)."""
    k = np.asarray(k)
    table = np.asarray(table, dtype=complex)
    if table.shape[0] == 0:
        return np.zeros(table.shape[1])
    n = samples_per_period * max(1, int(np.max(k)))
    return np.max(np.abs(synthesize(table, k, cycle_phases(n))), axis=0)


def rms(table: np.ndarray) -> np.ndarray:
    """RMS value per channel of a zero-mean harmonic signal, sqrt(sum_k |X_k|^2 / 2), shape (C,)."""
    table = np.asarray(table, dtype=complex)
    return np.sqrt(np.sum(np.abs(table) ** 2, axis=0) / 2.0)


def to_dense(k: np.ndarray, table: np.ndarray, kmax: int) -> np.ndarray:
    """Scatter rows listed by ``k`` onto the dense harmonic axis 1..kmax, shape (kmax, C)."""
    table = np.asarray(table, dtype=complex)
    out = np.zeros((kmax, table.shape[1]), dtype=complex)
    for row, kk in enumerate(np.asarray(k)):
        if not 1 <= kk <= kmax:
            raise ConfigError(f"k: harmonic {kk} does not fit a table of harmonics 1..{kmax}")
        out[kk - 1] = table[row]
    return out


__all__ = [
    "PEAK_SAMPLES_PER_PERIOD",
    "analyze",
    "cycle_phases",
    "dense_k",
    "peak_abs",
    "rms",
    "synthesize",
    "to_dense",
]

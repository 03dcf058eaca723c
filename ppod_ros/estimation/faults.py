"""Channel faults to inject into accelerometer readings, by name (benchmarks and tests).

Each fault maps readings (N, C) m/s^2 and the faulted channels to new readings; the set is what a lab
meets in wiring and sensors: a dead channel reading 0, a sign flip (sensor mounted upside down), a
channel replaced by noise (broken cable), a stuck ADC channel, half gain (wrong sensitivity) and two
channels swapped in wiring. :data:`FAULTS` is the table; :func:`inject` applies one by name.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ppod_ros.errors import ConfigError


def _zeroed(y: np.ndarray, ch: tuple[int, ...], rng: np.random.Generator) -> None:
    y[:, ch[0]] = 0.0


def _flipped(y: np.ndarray, ch: tuple[int, ...], rng: np.random.Generator) -> None:
    y[:, ch[0]] *= -1.0


def _noise(y: np.ndarray, ch: tuple[int, ...], rng: np.random.Generator) -> None:
    y[:, ch[0]] = rng.normal(0.0, float(np.nanstd(y[:, ch[0]])), y.shape[0])


def _stuck(y: np.ndarray, ch: tuple[int, ...], rng: np.random.Generator) -> None:
    y[:, ch[0]] = y[0, ch[0]]


def _half(y: np.ndarray, ch: tuple[int, ...], rng: np.random.Generator) -> None:
    y[:, ch[0]] *= 0.5


def _swapped(y: np.ndarray, ch: tuple[int, ...], rng: np.random.Generator) -> None:
    y[:, [ch[0], ch[1]]] = y[:, [ch[1], ch[0]]]


#: Fault name -> (number of channels it takes, function(readings, channels, rng) modifying in place).
FAULTS: dict[str, tuple[int, Callable[[np.ndarray, tuple[int, ...], np.random.Generator], None]]] = {
    "zeroed": (1, _zeroed),
    "flipped": (1, _flipped),
    "noise": (1, _noise),
    "stuck": (1, _stuck),
    "half": (1, _half),
    "swapped": (2, _swapped),
}


def inject(readings_mps2: np.ndarray, fault: str, channels: tuple[int, ...], seed: int = 0) -> np.ndarray:
    """A copy of ``readings_mps2`` (N, C) with ``fault`` applied to ``channels`` (column indices)."""
    if fault not in FAULTS:
        raise ConfigError(f"fault: unknown fault {fault!r}; known: {', '.join(FAULTS)}")
    n, fn = FAULTS[fault]
    if len(channels) != n:
        raise ConfigError(f"channels: fault {fault!r} takes {n} channel(s), got {list(channels)}")
    y = np.array(readings_mps2, dtype=float, copy=True)
    fn(y, tuple(int(c) for c in channels), np.random.default_rng(seed))
    return y


def swap_matters(readings_mps2: np.ndarray, a: int, b: int, min_difference: float = 0.5) -> bool:
    """Whether swapping columns a and b changes the readings by at least ``min_difference`` of the larger.

    Two channels that read nearly the same signal (twins under a symmetric motion) swap harmlessly.
    """
    y = np.asarray(readings_mps2, float)
    diff = np.linalg.norm(y[:, a] - y[:, b])
    return bool(diff >= min_difference * max(np.linalg.norm(y[:, a]), np.linalg.norm(y[:, b])))


__all__ = ["FAULTS", "inject", "swap_matters"]

"""Dead-acquisition checks: data that no live sensor can have produced.

A live accelerometer reads noise even on a plate at rest (the PPOD2 lab's undriven record: about
0.14 m/s^2 RMS per channel), so every channel exactly 0.0, every channel exactly constant (a stuck
ADC), samples that all stopped changing part-way through a record, or per-cycle summaries that are
all exactly zero or repeat exactly from one cycle to the next, mean nothing was acquired. Estimating
from such data would report a plate at rest (or frozen in one motion) with every channel "ok", and a
learning loop would push harder on it; these checks raise :class:`EstimationError` instead. They
look at the whole array; a single dead channel is the channel checks' business (harmonic_fit,
AccelEstimator.from_summaries).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ppod_ros.estimation.six_dof import EstimationError

#: A frozen tail shorter than this many samples is not called frozen (a slow ADC may repeat a few).
MIN_FROZEN_SAMPLES = 8
#: Fraction of a record whose samples all stopped changing at its end that makes it dead.
FROZEN_TAIL_FRACTION = 0.1
#: Identical consecutive per-cycle summaries of every channel (exact equality) that mean the device
#: re-sends a stale summary: live noise never repeats a phasor to the last bit.
STALE_SUMMARIES = 2


def _dead(what: str, names: Sequence[str]) -> EstimationError:
    return EstimationError(f"dead acquisition: {what}", {n: f"dead acquisition: {what}" for n in names})


def check_samples_alive(samples_mps2: np.ndarray, names: Sequence[str]) -> None:
    """Raise EstimationError if raw samples (N, C) cannot come from live sensors (module docstring)."""
    y = np.asarray(samples_mps2, dtype=float)
    if y.ndim != 2 or y.shape[0] < 2:
        return  # shape errors are the harmonic fit's to report
    finite = np.isfinite(y)
    if not finite.any():
        return  # every sample missing: the channel checks report "missing"
    vals = np.where(finite, y, np.nan)
    if np.all(np.where(finite, y == 0.0, True)):
        raise _dead(f"all {y.shape[1]} channels read exactly 0.0 (nothing was acquired)", names)
    seen = finite.any(axis=0)
    ptp = np.nanmax(vals[:, seen], axis=0) - np.nanmin(vals[:, seen], axis=0)
    if np.all(ptp == 0.0):
        raise _dead(f"all {y.shape[1]} channels are exactly constant (stuck ADC)", names)
    changed = np.any((np.diff(y, axis=0) != 0) & finite[1:] & finite[:-1], axis=1)
    last = int(np.flatnonzero(changed)[-1]) + 1 if changed.any() else 0
    frozen = int(np.sum(finite[last + 1 :].any(axis=1)))  # a missing (NaN) tail is not a frozen one
    if frozen >= max(MIN_FROZEN_SAMPLES, FROZEN_TAIL_FRACTION * y.shape[0]):
        raise _dead(
            f"samples stopped changing at sample {last} of {y.shape[0]} "
            f"(every channel frozen for the last {frozen} samples)",
            names,
        )


def check_summaries_alive(phasors: np.ndarray, names: Sequence[str]) -> None:
    """Raise EstimationError if per-cycle summaries (cycles, K, C) cannot come from live sensors."""
    P = np.asarray(phasors, dtype=complex)
    finite = np.isfinite(P)
    if P.ndim != 3 or not finite.any():
        return
    if np.all(np.where(finite, P == 0, True)):
        raise _dead(f"every phasor of all {P.shape[2]} channels is exactly zero (nothing was acquired)", names)
    # Whole-array repeats: a frozen acquisition re-sends its last summary.
    rows = [P[i] for i in range(P.shape[0]) if np.all(np.isfinite(P[i]))]
    run = 1
    for a, b in zip(rows, rows[1:]):
        run = run + 1 if np.array_equal(a, b) else 1
        if run >= STALE_SUMMARIES:
            raise _dead(
                f"{run} consecutive cycle summaries of all {P.shape[2]} channels are identical "
                f"(the acquisition stopped)",
                names,
            )


__all__ = ["check_samples_alive", "check_summaries_alive"]

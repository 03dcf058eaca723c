"""Corrections from the feedback loop: the one entry point where they reach the current table.

The accelerometer feedback publishes corrections in the generator's command units: complex coil
current phasors (A) per harmonic and actuator (DESIGN.md: only the waveform generator validates,
limits and applies them). :func:`correct_table` adds one to a plan's feed-forward table:

1. each entry's step from the correction now applied is clipped to ``limits.correction_step_a``
   (the magnitude is cut, the phase kept), or to ``limits.start_correction_a`` for a goal's
   starting correction;
2. if the corrected table would exceed an actuator limit (peak current, I^2 R temperature,
   amplifier voltage), the step is scaled back by bisection until it does not (if the correction
   now applied no longer fits, e.g. carried over to a new goal, the whole correction is scaled);
3. the result reports the table to send, the correction applied, whether steps were clipped and
   which limit scaled them. Nothing past a limit is ever returned.

Plate-motion limits (acceleration, contact margin, stroke) belong to the goal and were checked when
it was planned: corrections steer the plate towards that goal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ppod_ros.actuation.planning import GoalPlan, GoalPlanner, TablePrediction
from ppod_ros.can.protocol import quantise_currents
from ppod_ros.errors import ConfigError, LimitError


@dataclass(frozen=True, eq=False)
class CorrectionResult:
    """A corrected table and what the limiter did to the requested correction.

    ``currents_a = plan.currents_a + applied_a`` (quantised); ``step_clipped`` is true when some
    entry's step was cut to ``limits.correction_step_a``; ``limited_by`` names the limit that
    forced the step to be scaled by ``scale`` < 1 (None when it was not).
    """

    currents_a: np.ndarray
    applied_a: np.ndarray
    requested_a: np.ndarray
    step_clipped: bool
    limited_by: str | None
    scale: float
    prediction: TablePrediction


def correct_table(
    planner: GoalPlanner,
    plan: GoalPlan,
    requested: np.ndarray,
    previous: np.ndarray | None = None,
    k: np.ndarray | None = None,
    step_cap_a: float | None = None,
) -> CorrectionResult:
    """Apply a feedback correction to a plan's table, clipped and limited (module docstring).

    Parameters
    ----------
    planner : GoalPlanner
        The planner of the device (its limits and nominal plant).
    plan : GoalPlan
    requested : complex array, shape (Kc, 6)
        The correction wanted (A), added to the feed-forward table: rows are harmonics ``k``
        (default 1..Kc); every k must be a row of the plan's table.
    previous : complex array, shape (K, 6), optional
        The correction currently applied (``applied_a`` of the last result; default zero).
    step_cap_a : float, optional
        Largest step per entry (A); default ``limits.correction_step_a``. Never above
        ``limits.start_correction_a``.
    """
    K = plan.currents_a.shape[0]
    req = np.asarray(requested, dtype=complex)
    if req.ndim != 2 or req.shape[1] != 6 or not np.all(np.isfinite(req)):
        raise ConfigError(
            f"requested: expected a finite (Kc, 6) table of current phasors (A), got {req.shape}"
        )
    kk = np.arange(1, req.shape[0] + 1) if k is None else np.asarray(k, dtype=int)
    if kk.shape != (req.shape[0],) or np.any(kk < 1) or np.any(kk > K):
        raise ConfigError(f"k: correction harmonics must lie in the table's 1..{K}, got {kk.tolist()}")
    target = np.zeros((K, 6), dtype=complex)
    target[kk - 1] = req
    prev = np.zeros((K, 6), dtype=complex) if previous is None else np.asarray(previous, dtype=complex)
    if prev.shape != (K, 6):
        raise ConfigError(f"previous: expected shape ({K}, 6), got {prev.shape}")
    step = target - prev
    lim = planner.config.limits
    cap = lim.correction_step_a if step_cap_a is None else min(float(step_cap_a), lim.start_correction_a)
    mag = np.abs(step)
    clipped = mag > cap
    step = np.where(clipped, step * cap / np.maximum(mag, 1e-300), step)

    def attempt(base: np.ndarray, s: float) -> tuple[np.ndarray, TablePrediction, LimitError | None]:
        table = quantise_currents(plan.currents_a + base + s * step)
        pred = planner.predict(plan.frequency_hz, table)
        try:
            planner.check_table(pred)
        except LimitError as exc:
            return table, pred, exc
        return table, pred, None

    table, pred, err = attempt(prev, 1.0)
    if err is None:
        return CorrectionResult(table, table - plan.currents_a, target, bool(clipped.any()), None, 1.0, pred)
    limited_by = err.limit
    base = prev
    if attempt(prev, 0.0)[2] is not None:
        # The previous correction itself no longer fits (e.g. carried over to a new goal):
        # scale the whole correction from zero instead.
        base, step = np.zeros_like(prev), prev + step
    lo, hi = 0.0, 1.0
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if attempt(base, mid)[2] is None:
            lo = mid
        else:
            hi = mid
    table, pred, err = attempt(base, lo)
    if err is not None:  # only possible if the plan's own table is over a limit
        raise err
    return CorrectionResult(table, table - plan.currents_a, target, bool(clipped.any()), limited_by, lo, pred)


__all__ = ["CorrectionResult", "correct_table"]

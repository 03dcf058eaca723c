"""Corrections from the feedback loop: the one entry point where they reach the current table.

The accelerometer feedback publishes corrections in the generator's command units: complex coil
current phasors (A) per harmonic and actuator (DESIGN.md: only the waveform generator validates,
limits and applies them). :func:`correct_table` adds one to a plan's feed-forward table:

1. rows at a forbidden frequency (outside ``limits.frequency_range_hz`` or inside an excluded band,
   possible for rows 1..3 of a goal whose fundamental is not its lowest harmonic, or rows above the
   band) get no correction at all: no current ever goes to a forbidden frequency;
2. each entry's step from the correction now applied is clipped to ``limits.correction_step_a``
   (the magnitude is cut, the phase kept), or to ``limits.start_correction_a`` for a goal's
   starting correction;
3. the corrected table must pass the whole envelope (:mod:`ppod_ros.actuation.envelope`: plate
   acceleration, angular acceleration, contact margin, leg stroke, peak current, I^2 R temperature,
   amplifier voltage, through the nominal plant) with the guard band :data:`CORRECTION_GUARD`; if it
   would not, the step is scaled back by bisection until it does (if the correction now applied no
   longer fits, e.g. carried over to a new goal, the whole correction is scaled);
   the plate-side limits (:data:`~ppod_ros.actuation.envelope.PLATE_LIMITS`) are properties of the
   plate's actual motion: given a fresh measurement of the table now playing (:class:`MeasuredTable`),
   they are judged on the best prediction of the actual plate, the measured motion plus the nominal
   plant's response to the change of table (``measured + P_nominal (T_new - T_measured)``: the
   model's error applies to the step only, not to the whole table), and, as a backstop against a
   wrong measurement, the nominal prediction may exceed them by at most
   ``limits.plant_model_allowance`` (0: the measurement is not used). Without a measurement (a
   goal's starting correction, a stale or dead estimate) they are judged through the nominal plant.
   The actuator-side limits are always judged through the nominal plant;
4. the result reports the table to send, the correction applied (learning continues from it, not
   from what was asked), whether steps were clipped, which rows were blocked and which limit
   scaled them. Nothing past a limit is ever returned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ppod_ros.actuation.envelope import LIMIT_ORDER, PLATE_LIMITS, EnvelopeReport
from ppod_ros.actuation.planning import GoalPlan, GoalPlanner, TablePrediction
from ppod_ros.can.protocol import quantise_currents
from ppod_ros.errors import ConfigError, LimitError

#: Guard band of a corrected table under every limit (fraction of the limit's ratio): a corrected
#: table uses at most 1 - CORRECTION_GUARD of each limit (or what the goal itself uses, if more), so
#: that checkers with another sampling or model error (the device's own, an independent campaign)
#: never see it over a limit.
CORRECTION_GUARD = 0.005
#: Bisection halvings when a step is scaled back (resolution 2^-10 of the step: 0.2 mA of a 0.2 A step).
SCALE_BISECTIONS = 10


@dataclass(frozen=True, eq=False)
class CorrectionResult:
    """A corrected table and what the limiter did to the requested correction.

    ``currents_a = plan.currents_a + applied_a`` (quantised); ``step_clipped`` is true when some
    entry's step was cut to ``limits.correction_step_a``; ``limited_by`` names the limit that
    forced the step to be scaled by ``scale`` < 1 (None when it was not); ``blocked_rows`` lists
    the harmonics whose requested correction was dropped because they lie at a forbidden frequency;
    ``envelope`` is the corrected table's :class:`~ppod_ros.actuation.envelope.EnvelopeReport`
    (nominal plant); ``measured_ratios`` the plate-side limits' ratios of the prediction anchored on
    the measurement (None when the table was judged through the nominal plant alone).
    """

    currents_a: np.ndarray
    applied_a: np.ndarray
    requested_a: np.ndarray
    step_clipped: bool
    limited_by: str | None
    scale: float
    prediction: TablePrediction
    blocked_rows: tuple[int, ...] = ()
    envelope: EnvelopeReport | None = None
    measured_ratios: dict[str, float] | None = None


@dataclass(frozen=True, eq=False)
class MeasuredTable:
    """The plate's measured motion under the table now playing: the anchor of the plate-side limits.

    Attributes
    ----------
    correction_a : complex ndarray, shape (K, 6)
        The correction (A) over the plan's feed-forward of the table that was measured (the table
        is ``plan.currents_a + correction_a``, exactly as sent).
    accel : complex ndarray, shape (Km, 6)
        The measured plate acceleration phasors, rows harmonics 1..Km (m/s^2, rad/s^2).
    """

    correction_a: np.ndarray
    accel: np.ndarray


def correct_table(
    planner: GoalPlanner,
    plan: GoalPlan,
    requested: np.ndarray,
    previous: np.ndarray | None = None,
    k: np.ndarray | None = None,
    step_cap_a: float | None = None,
    measured: MeasuredTable | None = None,
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
    measured : MeasuredTable, optional
        A fresh measurement of the table now playing: the plate-side limits are judged on it
        (module docstring, item 3). None: through the nominal plant alone.
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
    if prev.shape != (K, 6) or not np.all(np.isfinite(prev)):
        raise ConfigError(f"previous: expected a finite table of shape ({K}, 6), got {prev.shape}")
    envelope = planner.envelope
    allowed = envelope.allowed_rows(plan.frequency_hz, K)
    blocked = tuple(int(r) + 1 for r in np.flatnonzero(~allowed & np.any(target != 0, axis=1)))
    target[~allowed] = 0.0
    prev = np.where(allowed[:, None], prev, 0.0)
    step = target - prev
    lim = planner.config.limits
    cap = lim.correction_step_a if step_cap_a is None else min(float(step_cap_a), lim.start_correction_a)
    mag = np.abs(step)
    clipped = mag > cap
    step = np.where(clipped, step * cap / np.maximum(mag, 1e-300), step)
    # Each limit may be used up to 1 - guard, or as far as the goal itself uses it (never beyond 1).
    base_ratios = planner.plan_envelope(plan).ratios
    allowed_ratio = {
        name: min(1.0, max(1.0 - CORRECTION_GUARD, base_ratios.get(name, 0.0))) for name in LIMIT_ORDER
    }

    # The plate-side limits on the measured plate plus the nominal response to the change of table.
    anchor = None
    if measured is not None and lim.plant_model_allowance > 0:
        anchor = _MeasuredAnchor(planner, plan, measured)

    def attempt(base: np.ndarray, s: float):
        table = quantise_currents(plan.currents_a + base + s * step)
        report = envelope.check_table(plan.frequency_hz, table)
        plate = None if anchor is None else anchor.ratios(table)
        allowance = lim.plant_model_allowance
        over = [n for n in LIMIT_ORDER if limit_over(n, report.ratios, plate, allowed_ratio[n], allowance)]
        return table, report, over, plate

    def result(table, report, limited_by, scale, plate) -> CorrectionResult:
        pred = planner.predict(plan.frequency_hz, table)
        return CorrectionResult(
            table, table - plan.currents_a, target, bool(clipped.any()), limited_by, scale, pred, blocked, report,
            plate,
        )

    table, report, over, plate = attempt(prev, 1.0)
    if not over:
        return result(table, report, None, 1.0, plate)
    limited_by = over[0]
    base = prev
    if attempt(prev, 0.0)[2]:
        # The previous correction itself no longer fits (e.g. carried over to a new goal, or the
        # measured plate is over a limit): scale the whole correction from zero instead.
        base, step = np.zeros_like(prev), prev + step
    lo, hi = 0.0, 1.0
    for _ in range(SCALE_BISECTIONS):
        mid = 0.5 * (lo + hi)
        if attempt(base, mid)[2]:
            hi = mid
        else:
            lo = mid
    table, report, over, plate = attempt(base, lo)
    if over and anchor is not None and not [n for n in LIMIT_ORDER if report.ratios.get(n, 0.0) > allowed_ratio[n]]:
        # Only the measured plate is over, even under the goal's own table (accepted on the nominal
        # plant; this is where the bisection ends then): no correction is added to it.
        return result(table, report, limited_by, 0.0, plate)
    if over:  # only possible if the plan's own table is over a limit
        raise report.error(1.0) or LimitError(
            f"the goal's own table is over {over[0]}", limit=over[0], limit_value=math.nan, requested=math.nan
        )
    return result(table, report, limited_by, lo, plate)


def limit_over(name: str, nominal: dict[str, float], plate: dict[str, float] | None, allowed: float,
          allowance: float) -> bool:
    """Whether limit ``name`` is over: on the nominal plant, or for a plate-side limit with a
    measurement, on the measured plate (and on the nominal plant beyond the allowance)."""
    ratio = nominal.get(name, 0.0)
    if plate is None or name not in PLATE_LIMITS:
        return ratio > allowed
    return plate[name] > allowed or ratio > allowed + allowance


class _MeasuredAnchor:
    """Prediction of the actual plate under a table: ``measured + P_nominal (T - T_measured)`` on the
    measured harmonics, the nominal plant's ``P_nominal T`` on table rows above them."""

    def __init__(self, planner: GoalPlanner, plan: GoalPlan, measured: MeasuredTable):
        K = plan.currents_a.shape[0]
        corr = np.asarray(measured.correction_a, dtype=complex)
        accel = np.asarray(measured.accel, dtype=complex)
        if corr.shape != (K, 6) or not np.all(np.isfinite(corr)):
            raise ConfigError(f"measured.correction_a: expected a finite table of shape ({K}, 6) (A), got {corr.shape}")
        if accel.ndim != 2 or accel.shape[1] != 6 or accel.shape[0] < 1 or not np.all(np.isfinite(accel)):
            raise ConfigError(
                f"measured.accel: expected a finite (Km, 6) table of plate acceleration phasors, got {accel.shape}"
            )
        self.planner, self.frequency_hz = planner, plan.frequency_hz
        self.rows = max(K, accel.shape[0])
        self.accel = np.zeros((self.rows, 6), dtype=complex)
        self.accel[: accel.shape[0]] = accel
        rows = min(K, accel.shape[0])
        self.accel[:rows] -= planner.plant.predict(plan.frequency_hz, plan.currents_a + corr, "accel")[:rows]

    def ratios(self, table: np.ndarray) -> dict[str, float]:
        accel = self.accel.copy()
        accel[: table.shape[0]] += self.planner.plant.predict(self.frequency_hz, table, "accel")
        return self.planner.envelope.check_plate(self.frequency_hz, accel)[1]


__all__ = ["CORRECTION_GUARD", "CorrectionResult", "MeasuredTable", "correct_table", "limit_over"]

"""Goal planning: plate motion -> validated coil-current table, with every device limit checked.

:meth:`GoalPlanner.plan` turns a :class:`~ppod_ros.motion.PlateMotion` into the current table the
device will play (feed-forward from the nominal plant, quantised exactly as the CAN protocol sends
it), with predicted peaks, and rejects the goal whole with a :class:`~ppod_ros.errors.LimitError`
naming the first limit it would exceed (DESIGN.md, device safety). Checks, in order:

1. ``limits.max_harmonic``: the goal's highest harmonic;
2. ``limits.frequency_range_hz`` and ``limits.excluded_bands_hz``: every harmonic's frequency;
3. ``limits.plate_accel_mps2`` / ``limits.plate_angular_accel_radps2``: peaks over the cycle;
4. ``limits.contact_margin_mps2``: min over the working disc and the cycle of g + a_n;
5. ``limits.leg_stroke_m``: peak leg displacement from the exact inverse kinematics;
6. ``limits.coil_current_a``, ``limits.coil_temperature_c`` (steady-state I^2 R heating) and
   ``limits.amplifier_voltage_v``: from the table through the nominal plant;
7. the drive limits (:data:`~ppod_ros.actuation.envelope.DRIVE_LIMITS`: leg stroke, peak coil
   current, amplifier voltage) for every plant within ``limits.plant_uncertainty``: a goal's table
   plays on a plant the feedback has not measured for it yet (its starting correction may come late,
   be lost or be scaled back), and a plant stronger than the model would take a goal planned near a
   limit past it on the first ramp-up (the checker's bound, ``Envelope.check_table`` with an
   allowance). The rejection names the limit and the allowance.

Invalid goals (NaN, frequency <= 0, harmonic numbers outside 1..10) never become a PlateMotion:
its constructor raises :class:`~ppod_ros.errors.ConfigError` naming the field.

:meth:`GoalPlanner.correct` is the entry point for the feedback loop's corrections (complex, per
harmonic and actuator, in amperes), implemented in :mod:`ppod_ros.actuation.corrections`: steps
clipped, scaled back before any actuator limit, and reported.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ppod_ros.actuation.envelope import Envelope, EnvelopeReport, PlantTolerance, motion_extremes, table_peak
from ppod_ros.actuation.harmonics import rms
from ppod_ros.actuation.plant import NominalPlant
from ppod_ros.can.protocol import MAX_RAMP_S, quantise_currents, quantise_frequency
from ppod_ros.device.config import DeviceConfig
from ppod_ros.errors import ConfigError, LimitError
from ppod_ros.kinematics.stewart import LegTrajectory, leg_trajectory
from ppod_ros.motion import GRAVITY_MPS2, PlateMotion

if TYPE_CHECKING:
    from ppod_ros.actuation.corrections import CorrectionResult, MeasuredTable

#: The table always has room for harmonics 1..3 (DESIGN.md), so that feedback can cancel distortion.
MIN_TABLE_HARMONICS = 3


def table_size(top_harmonic: int, max_harmonic: int, frequency_hz: float | None = None, limits=None) -> int:
    """Rows of the current table for a goal whose highest harmonic is ``top_harmonic``.

    At least 1..3 (DESIGN.md) and the goal's harmonics; with ``frequency_hz`` and the device
    ``limits``, also up to the third-order distortion products ``3 top`` (a voice coil's odd
    nonlinearity puts them there, and the feedback cancels them), as far as ``limits.max_table_harmonic``,
    ``limits.frequency_range_hz`` and ``limits.excluded_bands_hz`` allow.
    """
    rows = max(int(top_harmonic), min(MIN_TABLE_HARMONICS, int(max_harmonic)))
    if frequency_hz is None or limits is None:
        return rows
    for h in range(rows + 1, min(3 * int(top_harmonic), int(limits.max_table_harmonic)) + 1):
        fh = h * frequency_hz
        if fh > limits.frequency_range_hz[1] or any(lo <= fh <= hi for lo, hi in limits.excluded_bands_hz):
            break
        rows = h
    return rows


def plate_peaks(motion: PlateMotion) -> tuple[float, float]:
    """Peak |p''| (m/s^2) and peak |alpha| (rad/s^2) over one cycle (refined extrema, envelope module)."""
    if motion.is_zero():
        return 0.0, 0.0
    acc, ang, _ = motion_extremes(motion.phasors(), motion.k, 0.0)
    return acc, ang


def contact_margin(motion: PlateMotion, radius_m: float) -> float:
    """min over the disc |r| <= radius and over the cycle of g + a_n(r, t) (m/s^2).

    With a_n = p''z + alpha_x y - alpha_y x the minimum over the disc is
    p''z - radius |(alpha_x, alpha_y)|.
    """
    if motion.is_zero():
        return GRAVITY_MPS2
    return motion_extremes(motion.phasors(), motion.k, radius_m)[2]


@dataclass(frozen=True, eq=False)
class TablePrediction:
    """What the nominal plant predicts for a current table played at ``frequency_hz``.

    Arrays over actuators have shape (6,); ``currents_a`` and ``accel`` are dense (K, 6) phasor
    tables (row k-1 = harmonic k).
    """

    frequency_hz: float
    currents_a: np.ndarray
    current_peak_a: np.ndarray
    current_rms_a: np.ndarray
    coil_temperature_c: np.ndarray
    voltage_peak_v: np.ndarray
    stroke_peak_m: np.ndarray
    accel: np.ndarray


@dataclass(frozen=True, eq=False)
class GoalPlan:
    """A validated goal: the current table to send and what it will do.

    Attributes
    ----------
    motion : PlateMotion
    frequency_hz : float
        The fundamental as the device will play it (quantised to 1 uHz).
    ramp_s : float
        Ramp time sent with the table (the goal's, or the device default; at least timing.min_goal_ramp_s).
    currents_a : complex ndarray, shape (K, 6)
        The table: row k-1 holds harmonic k's coil-current phasors (A), quantised as sent.
    prediction : TablePrediction
    legs : LegTrajectory
        Exact inverse kinematics of the goal (leg displacement harmonics and peaks).
    plate_accel_peak_mps2, plate_angular_accel_peak_radps2, contact_margin_mps2 : float
        From the goal itself.
    """

    motion: PlateMotion
    frequency_hz: float
    ramp_s: float
    currents_a: np.ndarray
    prediction: TablePrediction
    legs: LegTrajectory
    plate_accel_peak_mps2: float
    plate_angular_accel_peak_radps2: float
    contact_margin_mps2: float

    @property
    def k(self) -> np.ndarray:
        return np.arange(1, self.currents_a.shape[0] + 1)

    @property
    def stroke_peak_m(self) -> np.ndarray:
        return self.legs.peak_m


def _limit(name: str, limit_value: float, requested: float, what: str, unit: str) -> LimitError:
    return LimitError(
        f"{what} {requested:.4g} {unit} exceeds {name} = {limit_value:g} {unit}",
        limit=name,
        limit_value=limit_value,
        requested=requested,
    )


class GoalPlanner:
    """Plans goals and corrections for one device (see the module docstring).

    Parameters
    ----------
    config : DeviceConfig
    plant : NominalPlant, optional
        Shared model instance (built from ``config`` when omitted).
    """

    def __init__(self, config: DeviceConfig, plant: NominalPlant | None = None):
        self.config = config
        self.plant = plant if plant is not None else NominalPlant(config)
        self.kinematics = self.plant.kinematics
        #: The one envelope checker (ppod_ros.actuation.envelope) every corrected table passes.
        self.envelope = Envelope(config, self.plant)
        #: The plants a goal's table must be safe on before the feedback has measured the plant
        #: (``limits.plant_uncertainty``; None when it is zero: the nominal plant alone).
        tolerance = PlantTolerance.from_limits(config.limits)
        self.allowance: PlantTolerance | None = None if tolerance.is_zero() else tolerance
        self._plan_envelope: tuple[GoalPlan, EnvelopeReport] | None = None

    # ------------------------------------------------------------------ goals
    def plan_arrays(
        self,
        frequency_hz: float,
        k,
        amplitude,
        phase,
        *,
        name: str = "",
        ramp_time_s: float | None = None,
    ) -> GoalPlan:
        """Plan a goal given as raw fields (e.g. from a message), rejecting bad ones with the reason.

        Non-finite numbers raise :class:`ConfigError` naming the field; a frequency outside
        ``limits.frequency_range_hz`` (including <= 0) and harmonic numbers above
        ``limits.max_harmonic`` raise :class:`LimitError`; then as :meth:`plan`.
        """
        lim = self.config.limits
        try:
            f = float(frequency_hz)
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"frequency_hz: expected a number in Hz, got {frequency_hz!r}") from exc
        if not np.isfinite(f):
            raise ConfigError(f"frequency_hz: must be finite, got {frequency_hz!r}")
        lo, hi = lim.frequency_range_hz
        if not lo <= f <= hi:
            raise LimitError(
                f"frequency {f:g} Hz is outside limits.frequency_range_hz = [{lo:g}, {hi:g}] Hz",
                limit="limits.frequency_range_hz",
                limit_value=lo if f < lo else hi,
                requested=f,
            )
        for field_name, values in (("amplitude", amplitude), ("phase", phase)):
            arr = np.asarray(values, dtype=float)
            if not np.all(np.isfinite(arr)):
                raise ConfigError(f"harmonics.{field_name}: all values must be finite, got {arr.tolist()}")
        kk = np.asarray(k)
        if kk.size and np.all(np.isfinite(kk.astype(float))) and np.max(kk) > lim.max_harmonic:
            top = float(np.max(kk))
            raise LimitError(
                f"harmonic {top:g} is above limits.max_harmonic = {lim.max_harmonic}",
                limit="limits.max_harmonic",
                limit_value=lim.max_harmonic,
                requested=top,
            )
        motion = PlateMotion(f, kk, amplitude, phase, name=name, ramp_time_s=ramp_time_s)
        return self.plan(motion)

    def plan(self, motion: PlateMotion) -> GoalPlan:
        """Validate ``motion`` against every limit and compute its current table.

        Raises
        ------
        LimitError
            Naming the first limit exceeded (nothing may be sent for this goal).
        ConfigError
            When ``motion`` is not a PlateMotion.
        """
        if not isinstance(motion, PlateMotion):
            raise ConfigError(f"motion: expected a PlateMotion, got {type(motion).__name__}")
        lim = self.config.limits
        active = motion.pruned()
        top = int(active.k.max()) if active.num_harmonics else 0
        if top > lim.max_harmonic:
            raise LimitError(
                f"harmonic {top} is above limits.max_harmonic = {lim.max_harmonic}",
                limit="limits.max_harmonic",
                limit_value=lim.max_harmonic,
                requested=top,
            )
        self._check_frequencies(motion.frequency_hz, active.k)
        if active.is_zero():
            acc_peak, ang_peak, margin = 0.0, 0.0, GRAVITY_MPS2
        else:
            acc_peak, ang_peak, margin = motion_extremes(active.phasors(), active.k, lim.working_radius_m)
        if acc_peak > lim.plate_accel_mps2:
            raise _limit(
                "limits.plate_accel_mps2", lim.plate_accel_mps2, acc_peak, "peak plate acceleration", "m/s^2"
            )
        if ang_peak > lim.plate_angular_accel_radps2:
            raise _limit(
                "limits.plate_angular_accel_radps2",
                lim.plate_angular_accel_radps2,
                ang_peak,
                "peak angular acceleration",
                "rad/s^2",
            )
        if margin < lim.contact_margin_mps2:
            raise LimitError(
                f"contact margin min(g + a_n) = {margin:.4g} m/s^2 over the working disc (r = "
                f"{lim.working_radius_m:g} m) is below limits.contact_margin_mps2 = "
                f"{lim.contact_margin_mps2:g} m/s^2",
                limit="limits.contact_margin_mps2",
                limit_value=lim.contact_margin_mps2,
                requested=margin,
            )
        kt = table_size(top, lim.max_harmonic, motion.frequency_hz, lim)
        legs = leg_trajectory(self.kinematics, active, kmax=2 * max(top, 1))
        stroke = float(np.max(self.envelope.exact_stroke(active, legs))) if top else 0.0
        if stroke > lim.leg_stroke_m:
            raise _limit("limits.leg_stroke_m", lim.leg_stroke_m, stroke, "peak leg displacement", "m")
        freq = quantise_frequency(motion.frequency_hz)
        currents = quantise_currents(
            self.plant.feedforward(active, kt) if top else np.zeros((kt, 6), complex)
        )
        prediction = self.predict(freq, currents)
        # The nominal plant's linear legs can exceed the exact inverse kinematics by the second-order
        # terms: the envelope takes the larger, for goals as for corrected tables.
        linear = float(np.max(prediction.stroke_peak_m))
        if linear > lim.leg_stroke_m:
            raise _limit("limits.leg_stroke_m", lim.leg_stroke_m, linear, "peak leg displacement (linear model)", "m")
        self.check_table(prediction)
        if top and self.allowance is not None:
            # The drive limits on every plant within the allowance (item 7 of the module docstring).
            error = self.envelope.check_table(freq, currents, self.allowance).error()
            if error is not None:
                raise error
        ramp = motion.ramp_time_s if motion.ramp_time_s is not None else self.config.timing.default_ramp_s
        # A change of motion faster than min_goal_ramp_s rings the flexures: the legs overshoot their
        # steady stroke (simulated device, a spin at 61 % of the stroke: +37 % from rest and +80 %
        # reversed in 50 ms, +1 % and +2 % in 0.2 s), so a goal is never crossfaded faster.
        ramp = max(float(ramp), self.config.timing.min_ramp_s, self.config.timing.min_goal_ramp_s)
        if ramp > MAX_RAMP_S:
            raise LimitError(
                f"ramp_time_s {ramp:g} s does not fit the CAN protocol's ramp field (at most {MAX_RAMP_S:g} s)",
                limit="protocol.max_ramp_s",
                limit_value=MAX_RAMP_S,
                requested=ramp,
            )
        return GoalPlan(motion, freq, ramp, currents, prediction, legs, acc_peak, ang_peak, margin)

    def _check_frequencies(self, frequency_hz: float, k: np.ndarray) -> None:
        lim = self.config.limits
        lo, hi = lim.frequency_range_hz
        for kk in np.asarray(k, dtype=int):
            fk = kk * frequency_hz
            if fk < lo:
                raise LimitError(
                    f"harmonic {kk} at {fk:g} Hz is below limits.frequency_range_hz = [{lo:g}, {hi:g}] Hz",
                    limit="limits.frequency_range_hz",
                    limit_value=lo,
                    requested=fk,
                )
            if fk > hi:
                raise LimitError(
                    f"harmonic {kk} at {fk:g} Hz is above limits.frequency_range_hz = [{lo:g}, {hi:g}] Hz",
                    limit="limits.frequency_range_hz",
                    limit_value=hi,
                    requested=fk,
                )
            for b_lo, b_hi in lim.excluded_bands_hz:
                if b_lo <= fk <= b_hi:
                    edge = b_lo if fk - b_lo < b_hi - fk else b_hi
                    raise LimitError(
                        f"harmonic {kk} at {fk:g} Hz lies in the excluded band [{b_lo:g}, {b_hi:g}] Hz "
                        f"(flexure resonances, limits.excluded_bands_hz)",
                        limit="limits.excluded_bands_hz",
                        limit_value=edge,
                        requested=fk,
                    )

    # ------------------------------------------------------------------ tables
    def predict(self, frequency_hz: float, currents: np.ndarray) -> TablePrediction:
        """Nominal-plant prediction for a dense current table (K, 6) at ``frequency_hz``."""
        currents = np.asarray(currents, dtype=complex)
        if currents.ndim != 2 or currents.shape[1] != 6 or not np.all(np.isfinite(currents)):
            raise ConfigError(
                f"currents: expected a finite (K, 6) table of coil-current phasors (A), got shape "
                f"{currents.shape}"
            )
        k = np.arange(1, currents.shape[0] + 1)
        a = self.config.actuators
        i_rms = rms(currents)
        temp = a.ambient_temperature_c + a.thermal_resistance_k_per_w * a.resistance_ohm * i_rms**2
        if currents.shape[0] == 0 or not np.any(currents):
            zeros = np.zeros(6)
            return TablePrediction(
                frequency_hz, currents, zeros, zeros, temp, zeros, zeros, np.zeros_like(currents)
            )
        out = self.plant.predict_all(frequency_hz, currents, ("voltage", "leg", "accel"))
        volts, legs, accel = out["voltage"], out["leg"], out["accel"]
        return TablePrediction(
            frequency_hz,
            currents,
            table_peak(currents, k),
            i_rms,
            temp,
            table_peak(volts, k),
            table_peak(legs, k),
            accel,
        )

    def check_table(self, p: TablePrediction) -> None:
        """Raise LimitError if a table exceeds an actuator limit (current, thermal, voltage)."""
        lim = self.config.limits
        worst = int(np.argmax(p.current_peak_a))
        if p.current_peak_a[worst] > lim.coil_current_a:
            raise _limit(
                "limits.coil_current_a",
                lim.coil_current_a,
                float(p.current_peak_a[worst]),
                f"peak current of coil {worst}",
                "A",
            )
        worst = int(np.argmax(p.coil_temperature_c))
        if p.coil_temperature_c[worst] > lim.coil_temperature_c:
            raise _limit(
                "limits.coil_temperature_c",
                lim.coil_temperature_c,
                float(p.coil_temperature_c[worst]),
                f"steady-state temperature of coil {worst} (I^2 R heating at "
                f"{p.current_rms_a[worst]:.3g} A rms)",
                "degC",
            )
        worst = int(np.argmax(p.voltage_peak_v))
        if p.voltage_peak_v[worst] > lim.amplifier_voltage_v:
            raise _limit(
                "limits.amplifier_voltage_v",
                lim.amplifier_voltage_v,
                float(p.voltage_peak_v[worst]),
                f"peak voltage of amplifier {worst}",
                "V",
            )

    def plan_envelope(self, plan: GoalPlan) -> EnvelopeReport:
        """The envelope report of a plan's own table (kept for the plan last asked about)."""
        cached = self._plan_envelope
        if cached is not None and cached[0] is plan:
            return cached[1]
        report = self.envelope.check_table(plan.frequency_hz, plan.currents_a)
        self._plan_envelope = (plan, report)
        return report

    # ------------------------------------------------------------------ corrections
    def correct(
        self,
        plan: GoalPlan,
        requested: np.ndarray,
        previous: np.ndarray | None = None,
        k: np.ndarray | None = None,
        step_cap_a: float | None = None,
        measured: MeasuredTable | None = None,
    ) -> CorrectionResult:
        """Apply a feedback correction to a plan's table (see ppod_ros.actuation.corrections)."""
        # Imported here: the corrections module builds on this one.
        from ppod_ros.actuation.corrections import correct_table

        return correct_table(self, plan, requested, previous, k, step_cap_a, measured)


__all__ = [
    "GoalPlan",
    "GoalPlanner",
    "MIN_TABLE_HARMONICS",
    "TablePrediction",
    "contact_margin",
    "plate_peaks",
    "table_size",
]

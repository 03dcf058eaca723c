"""The live feedback loop on the device's accelerometer summaries (what ``accel_feedback`` runs).

:class:`FeedbackLoop` turns a stream of per-channel harmonic summaries into 6-DoF estimates and,
while a goal is active, learning-control corrections:

1. ``set_goal(motion, now_s)``: a new controller for the goal (plant from the nominal model or a
   stored identification, refined by the plant learned online, :mod:`~ppod_ros.control.learned_plant`;
   feed-forward exactly as the waveform generator plans it). It starts from the correction learned
   for this goal before (:class:`~ppod_ros.control.store.CorrectionStore`), else from the one the
   learned plant predicts (``G^-1 goal - feedforward``), else from zero. Measurements start after
   ``settle_s``.
2. ``on_summary(k, phasors, frequency_hz, samples_per_cycle, now_s, table_seq, cycle)``: skips
   summaries of the table a step was measured on and those before a table has settled (in the
   device's cycles), compensates each channel's AC coupling (a
   known sensor response), collects ``summaries_per_estimate`` summaries, estimates, and, if the
   loop controls, teaches the plant learner (the applied currents and what they gave) and updates
   the correction; then waits ``settle_s`` (the plate's suspension
   transients after a table change) before measuring again.

No bus access: the caller sends the corrections to the generator, which limits and applies them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ppod_ros.actuation.corrections import MeasuredTable
from ppod_ros.actuation.planning import GoalPlan, GoalPlanner
from ppod_ros.config.fields import Fields
from ppod_ros.control.learned_plant import PlantLearner, PlantLearningSettings
from ppod_ros.control.learning import DIVERGED, LearningController, LearningSettings
from ppod_ros.control.limits import DeviceLimits, LimitEvent, LimitFunction, LimitReport
from ppod_ros.control.plant import PlantModel
from ppod_ros.control.store import CorrectionStore
from ppod_ros.device.config import CYCLE_MODULUS
from ppod_ros.device.schema import DeviceConfig
from ppod_ros.errors import ConfigError, LimitError
from ppod_ros.estimation import AccelCalibration, AccelEstimator, PlateEstimate
from ppod_ros.estimation.channel_set import ChannelSet, ChannelSetChange, ChannelSetSettings
from ppod_ros.estimation.misfit import MisfitHistory
from ppod_ros.motion import PlateMotion


def high_pass_response(freq_hz: np.ndarray, corner_hz: float, dt_s: float) -> np.ndarray:
    """Response of the discrete first-order AC coupling ``y_n = a (y_{n-1} + x_n - x_{n-1})``.

    ``H(f) = a (1 - z^-1) / (1 - a z^-1)``, ``a = exp(-2 pi f_c dt)``, ``z = exp(i 2 pi f dt)``
    (docs/device.md): the sensor property the summaries are divided by.
    """
    f = np.asarray(freq_hz, dtype=float)
    if corner_hz <= 0:
        return np.ones_like(f, dtype=complex)
    a = math.exp(-2 * math.pi * corner_hz * dt_s)
    zi = np.exp(-1j * 2 * math.pi * f * dt_s)
    return a * (1 - zi) / (1 - a * zi)


@dataclass(frozen=True)
class OnlineSettings:
    """How the live loop samples: summaries per estimate, settling time, whether it controls."""

    summaries_per_estimate: int = 3
    settle_s: float = 0.6
    control: bool = True
    estimator_harmonics: int = 6
    #: After a correction the loop measures only the device's next table (the summaries name the
    #: table they were computed on): summaries of the table it was sent from are not the
    #: correction's effect, however late the generator applies it. If no new table arrives within
    #: this time (s, device) after the step (a correction refused), the loop measures what plays.
    table_wait_s: float = 2.0
    #: The device (docs/device.md) defines the plate's motion as the acceleration and angular
    #: acceleration of the plate frame expressed in that frame: only the centripetal and the
    #: tilted-gravity terms separate a reading from it. The estimator's "frame" and "euler" terms
    #: convert to the rotation-vector convention of docs/feedback.md, which this device does not use
    #: (against the simulator's truth: 0.02-0.09 % with these two terms, 0.1-0.29 % with all four).
    second_order_terms: tuple[str, ...] = ("centripetal", "gravity")

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str = "feedback") -> OnlineSettings:
        f = Fields(data, where)
        out = cls(
            summaries_per_estimate=f.integer("summaries_per_estimate", cls.summaries_per_estimate, min_value=1,
                                             max_value=64),
            settle_s=f.number("settle_s", cls.settle_s, min_value=0.0, unit="s"),
            control=f.boolean("control", cls.control),
            estimator_harmonics=f.integer("estimator_harmonics", cls.estimator_harmonics, min_value=1,
                                          max_value=10),
            table_wait_s=f.number("table_wait_s", cls.table_wait_s, min_value=0.0, unit="s"),
        )
        f.finish()
        return out


@dataclass
class LoopOutput:
    """One estimate, and the control step taken on it (None when not controlling)."""

    estimate: PlateEstimate
    step: Any = None
    goal: PlateMotion | None = None
    stored: bool = False
    #: The feedback's channel set changed with this estimate (learning restarted), else None.
    channel_change: ChannelSetChange | None = None
    #: The device table the estimate's summaries were computed on (None when not known).
    table_seq: int | None = None
    #: The measured plate acceleration (Km, 6) to send with the step's correction, with ``table_seq``
    #: (``WaveformGenerator.apply_correction``'s ``measured_accel``); None when the table is not known.
    measured_accel: np.ndarray | None = None


@dataclass
class _Collect:
    k: np.ndarray | None = None
    table_seq: int | None = None
    phasors: list[np.ndarray] = field(default_factory=list)


class FeedbackLoop:
    """See the module docstring.

    Parameters
    ----------
    config : DeviceConfig
        The device (accelerometer layout, AC coupling, limits, the plant for the nominal model).
    settings : OnlineSettings
    learning : LearningSettings
    plant_for : callable(motion, k) -> PlantModel, optional
        The prior plant (default: the nominal model at the goal's frequency); the plant learned
        online refines it where goals have excited it.
    store : CorrectionStore, optional
        Learned corrections per goal (kept on convergence, reused for the same goal).
    plant_learning : PlantLearningSettings, optional
        How the plant is learned online (default: on).
    calibration : AccelCalibration, optional
        The device's stored array calibration (``ppod calibrate accel``), used by the estimator.
    channel_set : ChannelSetSettings, optional
        Hysteresis of the channel set the loop uses (:mod:`~ppod_ros.estimation.channel_set`).
    misfit : MisfitHistory, optional
        The device's misfit learned from operation (:mod:`~ppod_ros.estimation.misfit`): every
        healthy estimate adds to it; without a calibration, once it is ready its per-channel
        allowance replaces the default (the calibration's, measured on chosen motions, wins).
    """

    def __init__(self, config: DeviceConfig, settings: OnlineSettings | None = None,
                 learning: LearningSettings | None = None,
                 plant_for: Callable[[PlateMotion, np.ndarray], PlantModel] | None = None,
                 store: CorrectionStore | None = None,
                 plant_learning: PlantLearningSettings | None = None,
                 calibration: AccelCalibration | None = None,
                 channel_set: ChannelSetSettings | None = None,
                 misfit: MisfitHistory | None = None):
        self.config = config
        self.settings = settings or OnlineSettings()
        self.learning = learning or LearningSettings()
        self.planner = GoalPlanner(config)
        self.calibration = calibration
        self.misfit = misfit
        self._learned_allowance = False
        self.estimator = self._make_estimator()
        self.channels = ChannelSet(self.estimator.layout.names, channel_set)
        self.limits = DeviceLimits(max_current_a=config.limits.coil_current_a,
                                   max_step_a=config.limits.correction_step_a)
        # A goal's starting correction is bounded as the generator bounds it (limits.start_correction_a).
        self.start_limits = DeviceLimits(max_current_a=config.limits.coil_current_a,
                                         max_step_a=config.limits.start_correction_a)
        self.plant_for = plant_for or self._nominal_plant
        self.store = store
        self.learner = PlantLearner(plant_learning)
        self.goal: PlateMotion | None = None
        self.controller: LearningController | None = None
        #: Where the current controller's starting correction came from: "stored", "predicted" or "".
        self.initial_source = ""
        self._resume_s = math.inf
        self._collect = _Collect()
        # The table the last control step was measured on, while the loop waits for the next one
        # (None: not waiting), and the device time of that step.
        self._sent_from: int | None = None
        self._step_s = -math.inf
        self._table: int | None = None  # the device table the summaries showed last
        self._table_cycle: int | None = None  # the device cycle it first showed in
        self._resume_cycle: int | None = None  # the device cycle from which it has settled
        self._ramp_s = 0.0  # the goal's ramp, while its own and its starting tables ramp in
        # The measurement a control step is taken on, while it is taken (the generator judges the
        # plate-side limits of the corrected table on it, and so does the loop's copy of its limits).
        self._measured: MeasuredTable | None = None

    def _make_estimator(self) -> AccelEstimator:
        """The estimator: the calibration's allowance, else the learned one once ready, else the default."""
        allowance = None
        if self.calibration is None and self.misfit is not None and self.misfit.ready:
            allowance = self.misfit.allowance()
            self._learned_allowance = True
        return AccelEstimator(self.config.accelerometers.layout, harmonics=self.settings.estimator_harmonics,
                              second_order_terms=self.settings.second_order_terms, calibration=self.calibration,
                              misfit_allowance=allowance)

    def _nominal_plant(self, motion: PlateMotion, k: np.ndarray) -> PlantModel:
        return PlantModel.from_response(self.planner.plant.frequency_response, motion.frequency_hz, k)

    # ------------------------------------------------------------------ goals
    def set_goal(self, motion: PlateMotion | None, now_s: float, ramp_left_fraction: float = 0.0) -> None:
        """Start learning ``motion`` (None: no goal; summaries are then only estimated).

        ``ramp_left_fraction`` (0..1) of the goal's ramp is still to come (a goal taken up as it starts
        ramping in: 1); measuring resumes ``settle_s`` after the ramp ends.
        """
        self.goal = motion
        self._collect = _Collect()
        self._sent_from = None
        self._resume_s = now_s + self.settings.settle_s
        self.controller = None
        self.initial_source = ""
        if motion is None or motion.is_zero() or not self.settings.control:
            return
        plan = self.planner.plan(motion)
        limits = self.config.limits
        self._resume_s += min(max(ramp_left_fraction, 0.0), 1.0) * plan.ramp_s
        self._ramp_s = plan.ramp_s
        self._resume_cycle = self._settled_cycle(motion.frequency_hz)
        # Every row of the generator's table is controlled: the goal's harmonics, 1..3 and the
        # third-order distortion products (GoalPlanner's table_size).
        kc = plan.currents_a.shape[0]
        k = np.arange(1, kc + 1)
        ff = plan.currents_a.copy()
        plant = self.learner.model(self.plant_for(motion, k))
        initial = None if self.store is None else self.store.initial_for(self.config.name, motion, k)
        if initial is not None:
            self.initial_source = "stored"
        elif plant.source == "learned":
            initial = self._predicted_correction(motion, plant, k, ff)
            self.initial_source = "predicted" if initial is not None else ""
        if initial is not None:
            initial = self._as_generator(plan, self.start_limits, limits.start_correction_a)(
                np.zeros_like(initial), initial, ff)[0]
            if not np.any(initial):
                initial = None
        self.controller = LearningController(motion, plant, self._as_generator(plan, self.limits), self.learning,
                                             feedforward_a=ff, initial_correction_a=initial, harmonics=kc)

    def _as_generator(self, plan: GoalPlan, own: DeviceLimits, step_cap_a: float | None = None) -> LimitFunction:
        """The controller's limits: its own, then exactly what the generator will do with the result.

        The generator holds every corrected table to the device envelope (the plate-side limits on
        the measurement the step is taken on, when the table it was measured on is known)
        and scales a step back when it would not fit (:mod:`ppod_ros.actuation.corrections`). The
        same function on the same plan gives the loop the correction the plate will really play, so
        the controller continues from it and the plant learner pairs each measurement with the
        currents that made it (pairing it with the currents asked for taught the learner a plant
        that predicted the next goals' starting corrections 10-20 % off).
        """
        def limit(previous: np.ndarray, proposed: np.ndarray, feedforward: np.ndarray):
            correction, report = own.apply(previous, proposed, feedforward)
            try:
                result = self.planner.correct(plan, correction, previous=previous, step_cap_a=step_cap_a,
                                          measured=self._measured)
            except (ConfigError, LimitError) as exc:
                event = LimitEvent(f"generator: {exc}", -1, 0.0, 1.0)
                return previous.copy(), LimitReport(report.events + (event,))
            if result.limited_by is not None:
                event = LimitEvent(f"envelope {result.limited_by}", -1, result.scale, 1.0)
                report = LimitReport(report.events + (event,))
            return result.applied_a, report

        return limit

    def _predicted_correction(self, motion: PlateMotion, plant: PlantModel, k: np.ndarray, ff: np.ndarray
                              ) -> np.ndarray | None:
        """``G^-1 goal - feedforward`` on the goal's harmonics (None if zero); the caller limits it."""
        goal = motion.phasor_table(int(k.max()))
        want = plant.solve(goal[k - 1], k) - ff
        present = np.abs(goal[k - 1]).sum(axis=1) > 0
        want[~present] = 0.0  # distortion at the other harmonics is not linear in the current there
        return want if np.any(want) else None

    @property
    def initial_correction_a(self) -> np.ndarray | None:
        """A stored correction the new controller started from (to send to the generator at once)."""
        c = self.controller
        return None if c is None or not np.any(c.correction_a) else c.correction_a.copy()

    # ------------------------------------------------------------------ measurements
    def compensate(self, k: np.ndarray, phasors: np.ndarray, frequency_hz: float, samples_per_cycle: int
                   ) -> np.ndarray:
        """Undo the channels' AC coupling on summary phasors (K, C)."""
        acc = self.config.accelerometers
        dt = 1.0 / (frequency_hz * samples_per_cycle)
        return phasors / high_pass_response(np.asarray(k) * frequency_hz, acc.ac_coupling_hz, dt)[:, None]

    def on_summary(self, k: np.ndarray, phasors: np.ndarray, frequency_hz: float, samples_per_cycle: int,
                   now_s: float, table_seq: int | None = None, cycle: int | None = None) -> LoopOutput | None:
        """Feed one summary (harmonics ``k``, phasors (K, C)); returns an output when one is ready.

        ``table_seq`` is the device table the summary was computed on (``AccelSummary.table_seq``):
        when given, a control step's next estimate uses only summaries of a later table, from
        ``settle_s`` after it first shows (a correction the generator applies late is never
        measured before it plays), and an estimate never mixes two tables. ``cycle`` is the device
        cycle index of the summary's first cycle (``AccelSummary.first_cycle``): with both, the
        settling time after a table first shows is also counted in the device's own cycles, so
        summaries that reach the loop late (a backlog on the bridge, a busy node) are never taken
        for the settled plate.
        """
        if table_seq is not None and not self._new_table(int(table_seq), now_s, cycle, frequency_hz):
            return None
        if now_s < self._resume_s:
            return None
        if cycle is not None and self._resume_cycle is not None and \
                (int(cycle) - self._resume_cycle) % CYCLE_MODULUS >= CYCLE_MODULUS // 2:
            return None  # computed before the device's own settling time (summaries arriving late)
        k = np.asarray(k, dtype=int)
        if frequency_hz <= 0 or not math.isfinite(frequency_hz):
            raise ConfigError(f"frequency_hz: must be a positive frequency, got {frequency_hz}")
        if (self._collect.k is not None and not np.array_equal(self._collect.k, k)) or \
                self._collect.table_seq != table_seq:
            self._collect = _Collect()
        self._collect.k = k
        self._collect.table_seq = table_seq
        self._collect.phasors.append(self.compensate(k, np.asarray(phasors, complex), frequency_hz,
                                                     samples_per_cycle))
        if len(self._collect.phasors) < self.settings.summaries_per_estimate:
            return None
        stack = np.stack(self._collect.phasors)
        self._collect = _Collect()
        # Every estimate judges all channels (a gross fault is out of it at once); the set the loop
        # uses changes only on persistent evidence, and a change restarts learning (ChannelSet).
        estimate = self.estimator.from_summaries(k, stack, frequency_hz)
        learned = self.misfit is not None and self.misfit.add(estimate)
        if learned and not self._learned_allowance and self.calibration is None and self.misfit.ready:
            self.estimator = self._make_estimator()
        change = self.channels.observe(dict(zip(estimate.channels, estimate.status)))
        if self.channels.removed:
            active = list(self.channels.active)
            cols = self.estimator.layout.index(active)
            estimate = self.estimator.from_summaries(k, stack[..., cols], frequency_hz, channels=active)
        out = LoopOutput(estimate, goal=self.goal, channel_change=change, table_seq=table_seq)
        if change is not None and self.controller is not None:
            # Learning restarts from the correction applied now (the plate keeps its table): the
            # history and states were measured with another channel set.
            self.controller.reset(self.controller.correction_a)
            self._resume_s = now_s
            return out
        if self.controller is not None and self.controller.state != DIVERGED:
            ctrl = self.controller
            km = int(estimate.k.max())
            self.learner.observe(self.goal.frequency_hz, self.goal.phasor_table(km), ctrl.k, ctrl.command_a,
                                 estimate.table(km))
            # Measured on a known device table (the one the last correction made): the generator
            # is sent the measurement too and judges the plate-side limits on it.
            if table_seq is not None:
                self._measured = MeasuredTable(ctrl.correction_a.copy(), estimate.table(km))
            try:
                out.step = ctrl.update(estimate)
            finally:
                self._measured = None
            out.measured_accel = None if table_seq is None else estimate.table(km)
            if out.step.converged and self.store is not None:
                self.store.save(self.config.name, self.goal, out.step.k, self.controller.correction_a)
                out.stored = True
            # The next measurement must see the new table, after its crossfade and the plate's transient.
            self._resume_s = now_s + self.settings.settle_s
            self._sent_from, self._step_s = table_seq, now_s
            self._ramp_s = 0.0  # learning steps crossfade over the device's minimum ramp (in settle_s)
        return out

    def _new_table(self, table_seq: int, now_s: float, cycle: int | None, frequency_hz: float) -> bool:
        """False while the summaries still show the table the last step was measured on.

        Every change of table restarts the settling time from now (device time): a correction
        reaches the plate when its table first shows, not when the step was taken; and a table the
        loop did not cause (the next goal, sent before its status reached the loop) is never
        measured as the effect of this goal's command. After ``table_wait_s`` without a new table
        (the generator refused the correction) the loop measures what plays.
        """
        if self._sent_from is not None and table_seq == self._sent_from:
            if now_s - self._step_s < self.settings.table_wait_s:
                return False
            self._sent_from = None
        if table_seq != self._table:
            if self._table is not None:
                self._resume_s = max(self._resume_s, now_s + self.settings.settle_s)
                self._collect = _Collect()
            self._table = table_seq
            self._sent_from = None
            self._table_cycle = None if cycle is None else int(cycle)
            self._resume_cycle = self._settled_cycle(frequency_hz)
        return True

    def _settled_cycle(self, frequency_hz: float) -> int | None:
        """The device cycle from which the current table has settled: its first cycle plus ``settle_s``
        (and the goal's ramp while the goal's own and starting tables ramp in), in cycles."""
        if self._table_cycle is None or not (frequency_hz > 0 and math.isfinite(frequency_hz)):
            return None
        wait_s = self.settings.settle_s + self._ramp_s
        return (self._table_cycle + math.ceil(wait_s * frequency_hz)) % CYCLE_MODULUS

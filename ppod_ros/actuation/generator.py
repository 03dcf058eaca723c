"""The waveform generator's logic, without ROS: goals and corrections in, CAN tables out.

:class:`WaveformGenerator` sits between whoever asks for plate motions (the ``waveform_generator``
node, scripts, tests) and a :class:`~ppod_ros.can.host.DeviceLink`:

* :meth:`submit` validates a goal with the :class:`~ppod_ros.actuation.planning.GoalPlanner` (every
  device limit) and sends its current table, ramped, only if it passes; a rejection names the limit
  and nothing reaches the bus. ``dry_run`` validates and predicts without sending.
* :meth:`apply_correction` adds a feedback correction (per actuator and harmonic, amperes) to the
  active goal's feed-forward table, clipped in step size and scaled back before any actuator
  limit by the planner, and crossfades it in (never a step on the coils). A correction (or a table
  sent again) never shortens a ramp under way: it is crossfaded over at least what is left of it
  (:meth:`_ramp_for`; a goal reversing a large motion cut from 0.5 s to 0.05 s by its first
  correction overshot the legs' stroke by 26 % and faulted the device).
* :meth:`stop`, :meth:`estop`, :meth:`reset_estop`, :meth:`ramp_down_and_disable`: the ways down.
* :meth:`state` derives the generator's state from what the device reports (its STATUS frames),
  not from what was asked: ACTIVE only once the device plays the goal at full amplitude.

Acknowledgements are used: a table the device answers INCOMPLETE, CHECKSUM or BAD_STATE (or does
not answer within :data:`ACK_TIMEOUT_S`) is sent again, at most :data:`MAX_TABLE_RETRIES` times;
then, and at once for OVER_LIMIT, the goal is reported REJECTED with the device's reason (a
correction is dropped and the correction known to play is restored), never an endless RAMPING.
Bus and protocol errors (:class:`~ppod_ros.errors.DeviceError`) never escape: a goal, correction or
stop that cannot be sent is a not-accepted outcome naming the error.
"""

from __future__ import annotations

import contextlib
import math
import threading
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from ppod_ros.actuation.corrections import CorrectionResult, MeasuredTable
from ppod_ros.actuation.planning import GoalPlan, GoalPlanner
from ppod_ros.can.codec import TableAck
from ppod_ros.can.host import DeviceLink
from ppod_ros.can.protocol import AckResult, DeviceState
from ppod_ros.errors import ConfigError, DeviceError, LimitError
from ppod_ros.motion import PlateMotion


class GeneratorState(IntEnum):
    """Same numbering as ppod_msgs/PlateMotionStatus."""

    IDLE = 0
    RAMPING = 1
    ACTIVE = 2
    STOPPING = 3
    REJECTED = 4
    FAULT = 5


@dataclass(frozen=True)
class GoalOutcome:
    """The answer to a goal: accepted (with its plan) or rejected with the reason and the limit."""

    accepted: bool
    reason: str = ""
    limit: str = ""
    limit_value: float = math.nan
    requested: float = math.nan
    plan: GoalPlan | None = None
    seq: int | None = None
    dry_run: bool = False

    @classmethod
    def rejected(cls, exc: Exception) -> GoalOutcome:
        if isinstance(exc, LimitError):
            return cls(False, str(exc), exc.limit, exc.limit_value, exc.requested)
        return cls(False, str(exc))


@dataclass(frozen=True)
class CorrectionOutcome:
    applied: bool
    reason: str = ""
    result: CorrectionResult | None = None
    seq: int | None = None


#: Sends of one table after the first when the device answers INCOMPLETE, CHECKSUM or BAD_STATE
#: or does not answer (frames lost or corrupted on the bus): bounded, then the goal is rejected.
MAX_TABLE_RETRIES = 2
#: A committed table not acknowledged within this long (host clock, s) counts as lost. The device
#: answers a commit within one firmware period (5 ms) when the frames arrive.
ACK_TIMEOUT_S = 0.5
#: Acknowledgements worth a retry (lost or corrupted frames, or the device was not enabled).
RETRY_RESULTS = frozenset({AckResult.INCOMPLETE, AckResult.CHECKSUM, AckResult.BAD_STATE})


@dataclass
class _Pending:
    """A table sent and not yet acknowledged: what it was, to send it again."""

    currents_a: np.ndarray
    frequency_hz: float
    ramp_s: float
    sent_at: float
    correction_a: np.ndarray | None  # the correction this table carries (None: the goal table)
    previous_a: np.ndarray | None  # the correction playing before it
    attempts: int = 1


@dataclass
class _Active:
    plan: GoalPlan
    seqs: set[int] = field(default_factory=set)
    correction_a: np.ndarray | None = None  # applied correction (K, 6), A
    reached: bool = False  # the device has played it at full amplitude
    last_seq: int | None = None  # the newest table sent for it: only that one is ever sent again
    accepted: bool = False  # the device accepted one of its tables
    ramp_end_s: float = -math.inf  # link clock when the newest table's ramp ends at the latest


class WaveformGenerator:
    """See the module docstring. Thread-safe: goals, corrections and status may come from threads.

    Parameters
    ----------
    link : DeviceLink
        An open, handshaken link (its receive side polled by a thread or by the caller).
    planner : GoalPlanner
    """

    def __init__(self, link: DeviceLink, planner: GoalPlanner):
        self.link = link
        self.planner = planner
        self.config = planner.config
        self._lock = threading.RLock()
        self._active: _Active | None = None
        self._stop_seq: int | None = None
        self._pending: dict[int, _Pending] = {}
        self._failed: GoalOutcome | None = None
        self.last_rejection: GoalOutcome | None = None
        #: Counts of what the acknowledgements led to (retries, rejections, by reason).
        self.ack_counters: dict[str, int] = {}
        self.last_correction_note = ""
        link.on_ack.append(self._on_ack)

    # ------------------------------------------------------------------ goals
    def submit(self, motion: PlateMotion, dry_run: bool = False) -> GoalOutcome:
        """Validate ``motion`` against every device limit; unless ``dry_run``, send it ramped."""
        try:
            plan = self.planner.plan(motion)
        except (LimitError, ConfigError) as exc:
            outcome = GoalOutcome.rejected(exc)
            self.last_rejection = outcome
            return outcome
        if dry_run:
            return GoalOutcome(True, plan=plan, dry_run=True)
        with self._lock:
            state = self.link.status.state
            if state in (DeviceState.ESTOP, DeviceState.FAULT):
                outcome = GoalOutcome(False, f"device is in {state.name}: reset it before sending goals "
                                             f"({', '.join(self.link.status.fault_names) or 'no fault flags'})")
                self.last_rejection = outcome
                return outcome
            try:
                if state not in (DeviceState.ENABLED, DeviceState.RAMPING):
                    self.link.enable()  # disabled, after a watchdog trip, or not reported yet
                seq = self.link.send_plan(plan)
            except DeviceError as exc:  # bus-off, a refused frame: nothing (more) is played
                outcome = GoalOutcome(False, f"goal not sent: {exc}")
                self.last_rejection = outcome
                return outcome
            self._active = _Active(plan, {seq}, np.zeros_like(plan.currents_a), last_seq=seq)
            self._ramp_started(self._active, plan.ramp_s)
            self._pending = {seq: _Pending(plan.currents_a, plan.frequency_hz, plan.ramp_s, self.link.clock(),
                                           None, None)}
            self._failed = None
            self._stop_seq = None
        return GoalOutcome(True, plan=plan, seq=seq)

    @property
    def active_plan(self) -> GoalPlan | None:
        with self._lock:
            return None if self._active is None else self._active.plan

    @property
    def applied_correction_a(self) -> np.ndarray | None:
        with self._lock:
            return None if self._active is None else self._active.correction_a.copy()

    # ------------------------------------------------------------------ corrections
    def apply_correction(self, goal_key: bytes | None, k: np.ndarray, table_a: np.ndarray,
                         absolute: bool = True, start: bool = False, measured_accel: np.ndarray | None = None,
                         measured_seq: int | None = None) -> CorrectionOutcome:
        """Apply a correction (harmonics ``k``, (len(k), 6) complex amperes) to the active goal.

        ``goal_key`` (a ``PlateMotion.key``) must name the active goal (None: whatever is active), so a
        correction learned for another goal is never applied. ``absolute`` replaces the correction
        table; otherwise ``table_a`` is added to it. ``start`` marks the goal's starting correction
        (learned for it before, or predicted by the feedback's learned plant): as the goal's first
        correction its entries may reach ``limits.start_correction_a`` instead of one learning step
        (``limits.correction_step_a``), and it is crossfaded over the goal's own ramp. Every current,
        voltage and thermal limit applies as always.

        ``measured_accel`` (Km, 6) is the plate's acceleration (phasors of harmonics 1..Km) measured
        on the device table ``measured_seq`` (``AccelSummary.table_seq``). When that table is the
        newest one sent for the goal, the one playing, the corrected table's plate-side limits are
        judged on this measurement (:class:`~ppod_ros.actuation.corrections.MeasuredTable`);
        otherwise (none, stale, or a starting correction) through the nominal plant.
        """
        with self._lock:
            act = self._active
            if act is None:
                return CorrectionOutcome(False, "no active goal")
            if goal_key is not None and goal_key != act.plan.motion.key:
                return CorrectionOutcome(False, "correction is for another goal")
            k = np.asarray(k, dtype=int)
            table = np.asarray(table_a, dtype=complex)
            K = act.plan.currents_a.shape[0]
            if table.shape != (k.size, 6) or np.any(k < 1) or np.any(k > K):
                return CorrectionOutcome(False, f"correction must be (len(k), 6) with k in 1..{K}; got "
                                                f"{table.shape} for k = {k.tolist()}")
            target = table if absolute else act.correction_a[k - 1] + table
            first = start and not np.any(act.correction_a)
            cap = self.config.limits.start_correction_a if first else None
            if not np.all(np.isfinite(table)):
                return CorrectionOutcome(False, "correction must be finite")
            measured = None
            if measured_accel is not None and not first and measured_seq is not None and measured_seq == act.last_seq:
                measured = MeasuredTable(act.correction_a.copy(), np.asarray(measured_accel, dtype=complex))
            try:
                result = self.planner.correct(act.plan, target, previous=act.correction_a, k=k, step_cap_a=cap,
                                              measured=measured)
            except (ConfigError, LimitError) as exc:
                return CorrectionOutcome(False, str(exc))
            ramp = self._ramp_for(act, max(act.plan.ramp_s, self.config.timing.min_ramp_s) if first
                                  else self.config.timing.min_ramp_s)
            try:
                seq = self.link.send_correction(act.plan, result, ramp_s=ramp)
            except DeviceError as exc:
                return CorrectionOutcome(False, f"correction not sent: {exc}", result)
            self._pending[seq] = _Pending(result.currents_a, act.plan.frequency_hz, ramp, self.link.clock(),
                                          result.applied_a, act.correction_a)
            act.seqs.add(seq)
            act.last_seq = seq
            act.correction_a = result.applied_a
            self._ramp_started(act, ramp)
            notes = []
            if result.blocked_rows:
                notes.append(f"no correction at harmonics {list(result.blocked_rows)} (forbidden frequencies)")
            if result.step_clipped:
                name = "start_correction_a" if first else "correction_step_a"
                notes.append(f"step clipped to limits.{name} = {getattr(self.config.limits, name):g} A")
            if result.limited_by:
                notes.append(f"scaled by {result.scale:.3f} to stay within {result.limited_by}")
            self.last_correction_note = "; ".join(notes)
            return CorrectionOutcome(True, self.last_correction_note, result, seq)

    def _ramp_for(self, act: _Active, ramp_s: float) -> float:
        """The ramp for a table of ``act`` sent now: ``ramp_s``, or longer if the ramp under way ends
        later. A new table's crossfade starts from the mix playing (docs/can_protocol.md), so a short
        one would finish the goal's crossfade in its place: a reversal of a large motion in 0.05 s
        instead of 0.5 s."""
        return max(float(ramp_s), act.ramp_end_s - self.link.clock())

    def _ramp_started(self, act: _Active, ramp_s: float) -> None:
        """A table of ``act`` was sent with ``ramp_s``: its ramp is the one under way from now (the
        device starts it at the next cycle start at the latest: one period of margin)."""
        act.ramp_end_s = self.link.clock() + ramp_s + 1.0 / act.plan.frequency_hz

    # ------------------------------------------------------------------ the ways down
    def stop(self, ramp_s: float | None = None) -> int:
        """Ramp the plate to rest (device stays enabled); returns the stop table's sequence number."""
        with self._lock:
            freq = None if self._active is None else self._active.plan.frequency_hz
            self._active = None
            self._pending.clear()
            self._failed = None
            ramp = self.config.timing.default_ramp_s if ramp_s is None else ramp_s
            self._stop_seq = self.link.stop_motion(ramp, freq)
            self._pending[self._stop_seq] = _Pending(np.zeros((1, 6), complex), freq or
                                                     self.config.sim.idle_frequency_hz, ramp,
                                                     self.link.clock(), None, None)
            return self._stop_seq

    def estop(self) -> None:
        """Emergency stop: the top-priority frame; the device latches ESTOP."""
        with self._lock:
            self._active = None
            self._pending.clear()
            self.link.estop()

    def reset_estop(self) -> None:
        with self._lock:
            self.link.reset_estop()
            self.link.clear_faults()

    def at_rest(self) -> bool:
        """True when the device plays nothing: disabled, tripped, or the stop table fully ramped."""
        s = self.link.status
        if s.state in (DeviceState.DISABLED, DeviceState.WATCHDOG, DeviceState.ESTOP, DeviceState.FAULT):
            return True
        return self._stop_seq is not None and s.active_seq == self._stop_seq and s.amplitude_scale >= 1.0

    def ramp_down_and_disable(self, timeout_s: float, heartbeat: bool = True) -> bool:
        """Stop, wait (sending heartbeats) until the device reports rest, then disable and wait for it.

        Returns True if the device reported rest and then DISABLED within ``timeout_s``. A device
        that does not answer ramps itself down on its watchdog when the heartbeats stop.
        """
        period = self.config.can.heartbeat_period_s
        deadline = self.link.clock() + timeout_s

        def wait(predicate) -> bool:
            while self.link.clock() < deadline:
                if heartbeat:
                    self.link.heartbeat()
                if self.link.wait_for(predicate, period):
                    return True
            return False

        try:
            self.stop()
            rested = wait(self.at_rest)
            # Already at rest: the disable needs no more than the device's minimum ramp.
            self.link.disable(self.config.timing.min_ramp_s if rested else None)
            return wait(lambda: self.link.status.state == DeviceState.DISABLED) and rested
        except DeviceError:
            return False

    # ------------------------------------------------------------------ acknowledgements
    def _count(self, key: str) -> None:
        self.ack_counters[key] = self.ack_counters.get(key, 0) + 1

    def _on_ack(self, ack: TableAck) -> None:
        """The device's answer to a commit (called by the link's receiving thread)."""
        with self._lock:
            pending = self._pending.get(ack.seq)
            if pending is None:
                return
            if ack.result in (AckResult.ACCEPTED, AckResult.ACTIVE, AckResult.SUPERSEDED):
                del self._pending[ack.seq]
                if self._active is not None and ack.seq in self._active.seqs and ack.result != AckResult.SUPERSEDED:
                    self._active.accepted = True
                return
            self._count(f"ack_{ack.result.name.lower()}")
            self._retry_or_reject(ack.seq, pending, f"device answered {ack.result.name}",
                                  retry=ack.result in RETRY_RESULTS)

    def check_acks(self) -> None:
        """Treat tables unacknowledged for ACK_TIMEOUT_S as lost (call periodically; state() does)."""
        now = self.link.clock()
        with self._lock:
            for seq, pending in list(self._pending.items()):
                if now - pending.sent_at > ACK_TIMEOUT_S:
                    self._count("ack_timeout")
                    self._retry_or_reject(seq, pending, f"no acknowledgement within {ACK_TIMEOUT_S:g} s",
                                          retry=True)

    def _retry_or_reject(self, seq: int, pending: _Pending, why: str, retry: bool) -> None:
        del self._pending[seq]
        act = self._active
        stopping = act is None and seq == self._stop_seq
        if not stopping and (act is None or seq not in act.seqs):
            return
        if not stopping and seq != act.last_seq:
            # A newer table of this goal was sent since (it carries the goal and the newer
            # correction): sending this one again would undo it.
            self._count("superseded_by_newer")
            return
        if retry and pending.attempts <= MAX_TABLE_RETRIES:
            try:
                if self.link.status.state not in (DeviceState.ENABLED, DeviceState.RAMPING):
                    self.link.enable()
                ramp = pending.ramp_s if stopping else self._ramp_for(act, pending.ramp_s)
                new = self.link.send_table(pending.currents_a, pending.frequency_hz, ramp)
            except DeviceError as exc:
                why = f"{why}; resend failed: {exc}"
            else:
                self._count("retries")
                pending.attempts += 1
                pending.sent_at = self.link.clock()
                self._pending[new] = pending
                if stopping:
                    self._stop_seq = new
                else:
                    act.seqs.add(new)
                    act.last_seq = new
                    pending.ramp_s = ramp
                    self._ramp_started(act, ramp)
                return
        if stopping:
            # The stop table did not get through: disabling ramps the plate down as well.
            self._count("stops_disabled")
            # If even that cannot be sent, the device's watchdog ramps it down when heartbeats stop.
            with contextlib.suppress(DeviceError):
                self.link.disable()
            return
        if pending.correction_a is not None and act.accepted:
            # A correction that did not reach the device: what plays is the one before it.
            self._count("corrections_dropped")
            if np.array_equal(act.correction_a, pending.correction_a):
                act.correction_a = pending.previous_a
            self.last_correction_note = f"correction table {seq} not played: {why}"
            return
        self._count("goals_rejected")
        self._failed = GoalOutcome(False, f"goal '{act.plan.motion.name}' not played: {why} "
                                          f"(after {pending.attempts} send(s) of its table)")
        self.last_rejection = self._failed
        self._active = None

    # ------------------------------------------------------------------ state
    def state(self) -> tuple[GeneratorState, str, float]:
        """(state, reason, ramp progress 0..1) from the device's last STATUS."""
        self.check_acks()
        s = self.link.status
        with self._lock:
            if s.state in (DeviceState.ESTOP, DeviceState.FAULT, DeviceState.WATCHDOG):
                faults = ", ".join(s.fault_names)
                return GeneratorState.FAULT, f"device {s.state.name}{': ' + faults if faults else ''}", 0.0
            act = self._active
            if act is None and self._failed is not None:
                return GeneratorState.REJECTED, self._failed.reason, 0.0
            if act is None:
                if self._stop_seq is not None and not self.at_rest():
                    return GeneratorState.STOPPING, "ramping down", float(s.amplitude_scale)
                return GeneratorState.IDLE, "", 1.0
            playing = s.active_seq in act.seqs
            if playing and s.amplitude_scale >= 1.0:
                act.reached = True
            if act.reached:
                return GeneratorState.ACTIVE, "", 1.0
            return GeneratorState.RAMPING, "", float(s.amplitude_scale) if playing else 0.0

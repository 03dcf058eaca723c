"""The simulated PPOD device: firmware state machine, actuator controllers, plant and sensors.

:class:`SimDevice` plays the device side of the CAN protocol (docs/can_protocol.md) on a
``can.BusABC`` and keeps its own clock. It advances in *chunks* of at most ``timing.watchdog_check_s``
of device time; at the start of each chunk it reads the bus, checks the watchdog and its faults,
then plays the chunk on the plant. Nothing here depends on wall time: :meth:`SimDevice.advance`
runs as fast as it can, and :mod:`ppod_sim.clock` paces it to real time or a rate factor.

Cycle timing: the device locks N accelerometer samples (and ``sim.control_steps_per_sample`` x N
control steps) to each cycle of the fundamental, N >= 32 and near ``sample_rate_hz / f``; phases
are referenced to the cycle start (t = 0 at the first sample of each cycle).

State machine (DeviceState): DISABLED -ENABLE-> ENABLED (RAMPING while a ramp runs); DISABLE ramps to
zero then DISABLED; no heartbeat for ``watchdog_timeout_s`` -> WATCHDOG (ramp to zero within
``watchdog_ramp_s``; ENABLE resumes); ESTOP from any state -> ramp to zero within ``estop_ramp_s``,
latched until RESET_ESTOP (then DISABLED, or FAULT when a stopping fault was raised meanwhile); a
stopping fault (thermal, voltage, stroke, over-current) -> FAULT, ramped to zero within
``watchdog_ramp_s``, until CLEAR_FAULTS. After any stop the active table is zero.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import can
import numpy as np

from ppod_ros.actuation.harmonics import analyze
from ppod_ros.can.codec import (
    CoilRms,
    CoilTemps,
    Control,
    DeviceLimit,
    Estop,
    FaultEvent,
    FrameCounters,
    Heartbeat,
    RawRequest,
    Status,
    StatusExt,
    TableAck,
    TableCommit,
    TableCrc,
    TableEntry,
    TableHeader,
    Version,
    VersionRequest,
)
from ppod_ros.can.protocol import (
    PROTOCOL_VERSION,
    STOPPING_FAULTS,
    AckResult,
    Command,
    DeviceState,
    Fault,
    LimitItem,
)
from ppod_ros.device.config import DeviceConfig
from ppod_ros.motion import MAX_HARMONIC, PlateMotion
from ppod_sim.drive import ActuatorDrive
from ppod_sim.plant import ChunkResult, PlantSimulator
from ppod_sim.player import TablePlayer
from ppod_sim.sensors import AccelerometerArray, SensorErrors
from ppod_sim.tables import TableReceiver
from ppod_sim.telemetry import Telemetry
from ppod_sim.truth import CycleTruth

log = logging.getLogger(__name__)

MIN_SAMPLES_PER_CYCLE = 32
COIL_REPORT_PERIOD_S = 1.0


@dataclass
class _Ahead:
    """The plant computed ahead for the rest of a cycle, released period by period."""

    res: ChunkResult
    chunks: int
    rows_per_chunk: int
    version: int
    next_chunk: int = 0


def device_limits(config: DeviceConfig) -> list[float]:
    """The values the device reports in DEVICE_LIMIT frames, indexed by LimitItem (its own limits)."""
    lim = config.limits
    out = [0.0] * LimitItem.EXCLUDED_BAND
    out[LimitItem.LEG_STROKE_M] = lim.leg_stroke_m
    out[LimitItem.COIL_CURRENT_A] = lim.coil_current_a
    out[LimitItem.AMPLIFIER_VOLTAGE_V] = lim.amplifier_voltage_v
    out[LimitItem.COIL_TEMPERATURE_C] = lim.coil_temperature_c
    out[LimitItem.PLATE_ACCEL_MPS2] = lim.plate_accel_mps2
    out[LimitItem.PLATE_ANGULAR_ACCEL_RADPS2] = lim.plate_angular_accel_radps2
    out[LimitItem.FREQUENCY_MIN_HZ], out[LimitItem.FREQUENCY_MAX_HZ] = lim.frequency_range_hz
    for lo, hi in lim.excluded_bands_hz:
        out += [float(lo), float(hi)]
    return out


class SimDevice:
    """The simulated device on a bus (see the module docstring).

    Parameters
    ----------
    config : DeviceConfig
    bus : can.BusABC
        The device's side of the bus (a python-can virtual bus in the simulator process).
    seed : int, optional
        Seed of the mismatch draws and the sensor noise (default ``config.sim.seed``).
    sensor_errors : SensorErrors, optional
        The accelerometers' gain, axis and bending errors (default: the lab-like
        ``SensorErrors.default``; ``SensorErrors.none()`` for ideal sensors).
    """

    def __init__(self, config: DeviceConfig, bus: can.BusABC, seed: int | None = None,
                 sensor_errors: SensorErrors | None = None):
        self.config = config
        self.bus = bus
        self.node = config.can.device_node_id
        seed = config.sim.seed if seed is None else int(seed)
        rng = np.random.default_rng(seed)
        self.drive = ActuatorDrive(config.sim.mismatch, np.random.default_rng(rng.integers(2**63)))
        self.sensors = AccelerometerArray(config.accelerometers, np.random.default_rng(rng.integers(2**63)),
                                          sensor_errors)
        self.plant = PlantSimulator(config)
        self.player = TablePlayer(self.drive, config.sim.idle_frequency_hz)
        self.counters = FrameCounters(self.node, "to_device")
        self.telemetry = Telemetry(
            config.accelerometers.num_channels,
            self.node,
            config.can.summary_max_rate_hz,
            config.can.summary_harmonics,
            config.can.raw_frame_rate_hz,
            self._send,
        )
        self.time_s = 0.0
        self.state = DeviceState.DISABLED
        self.faults = Fault(0)
        self._disabling = False
        self.last_heartbeat_s: float | None = None
        #: Wall-clock time (``time.time()``) at which that heartbeat reached the device's bus (the
        #: virtual bus stamps each frame as the bridge delivers it): with :attr:`last_heartbeat_s`
        #: it tells a host that stopped sending from a simulator that stopped reading (see
        #: ``ppod_sim.ros_node``'s WATCHDOG log line).
        self.last_heartbeat_wall_s: float | None = None
        #: The longest device time between two heartbeats while the watchdog was armed (enabled or
        #: ramping): the margin the watchdog had, whatever the host or the simulator's pacing did.
        self.longest_heartbeat_gap_s = 0.0
        self._rx_wall_s: float | None = None
        self.cycle_index = 0
        self.tables = TableReceiver.for_device(config)
        self.frames_tx = 0
        self.bytes_tx = 0
        self._next_status_s = 0.0
        self._next_coil_s = 0.0
        self._reported = (self.state, int(self.faults))
        self._rejected_reported = 0
        self.coil_temperature_c = np.full(6, config.actuators.ambient_temperature_c)
        self._sq_sum = np.zeros(6)
        self._sq_time = 0.0
        self.coil_rms_a = np.zeros(6)
        self.truth: deque[CycleTruth] = deque(maxlen=256)
        #: Every stopping fault as it is raised (not while it stays latched): (device time, flag, the
        #: state it met), the first 256 kept; ``stopping_fault_count`` counts them all.
        self.stopping_faults: list[tuple[float, Fault, DeviceState]] = []
        self.stopping_fault_count = 0
        self.cycle_callbacks: list[Callable[[CycleTruth], None]] = []
        self._start_cycle()

    # ------------------------------------------------------------------ cycle timing
    def _start_cycle(self) -> None:
        activated = self.player.on_cycle_boundary(self.time_s)
        if activated is not None:
            self._send(TableAck(activated.seq, AckResult.ACTIVE, self.cycle_index).encode(self.node))
        f = self.player.frequency_hz
        period = 1.0 / f
        check = self.config.timing.watchdog_check_s
        self.n_chunks = max(1, math.ceil(period / check - 1e-9))
        n = max(MIN_SAMPLES_PER_CYCLE, round(self.config.accelerometers.sample_rate_hz / f))
        self.samples_per_cycle = self.n_chunks * math.ceil(n / self.n_chunks)
        self.steps_per_sample = self.config.sim.control_steps_per_sample
        self.steps_per_cycle = self.samples_per_cycle * self.steps_per_sample
        self.steps_per_chunk = self.steps_per_cycle // self.n_chunks
        self.dt_s = period / self.steps_per_cycle
        self.plant.discretisation(self.dt_s, self.steps_per_sample, self.samples_per_cycle)
        self.cycle_start_s = self.time_s
        self.cycle_frequency_hz = f
        self.step_in_cycle = 0
        self._ahead: _Ahead | None = None
        self._cycle_samples: list[np.ndarray] = []
        self._cycle_truth: list[np.ndarray] = []
        self._cycle_peaks = np.zeros((3, 6))
        self.telemetry.start_of_cycle(self.cycle_index, self.samples_per_cycle)

    @property
    def chunk_s(self) -> float:
        return self.steps_per_chunk * self.dt_s

    # ------------------------------------------------------------------ bus
    def _send(self, msg: can.Message) -> None:
        try:
            self.bus.send(msg)
        except can.CanError as exc:  # a real device keeps running when its bus fails
            log.warning("device: send failed: %s", exc)
            return
        self.frames_tx += 1
        self.bytes_tx += len(msg.data)

    def _receive(self) -> None:
        while True:
            try:
                msg = self.bus.recv(0.0)
            except can.CanError as exc:
                log.warning("device: receive failed: %s", exc)
                return
            if msg is None:
                return
            self._rx_wall_s = msg.timestamp
            rec = self.counters.decode(msg)
            if rec is not None:
                self._handle(rec)

    def _handle(self, rec) -> None:
        now = self.time_s
        if isinstance(rec, Estop):
            self.emergency_stop()
        elif isinstance(rec, Heartbeat):
            if self.last_heartbeat_s is not None and self.watchdog_armed:
                self.longest_heartbeat_gap_s = max(self.longest_heartbeat_gap_s, now - self.last_heartbeat_s)
            self.last_heartbeat_s = now
            self.last_heartbeat_wall_s = self._rx_wall_s
        elif isinstance(rec, Control):
            self._control(rec)
        elif isinstance(rec, TableHeader):
            self.tables.header(rec)
        elif isinstance(rec, TableEntry):
            self.tables.entry(rec)
            self.counters.rejected["table entry without header"] = self.tables.orphans
        elif isinstance(rec, TableCrc):
            self.tables.crc(rec)
            self.counters.rejected["table entry without header"] = self.tables.orphans
        elif isinstance(rec, TableCommit):
            self._commit(rec)
        elif isinstance(rec, VersionRequest):
            c = self.config
            self._send(
                Version(
                    *PROTOCOL_VERSION,
                    6,
                    c.accelerometers.num_channels,
                    c.limits.max_harmonic,
                    self.node,
                    True,
                ).encode(self.node)
            )
            limits = device_limits(c)
            for item, value in enumerate(limits):
                self._send(DeviceLimit(item, len(limits), value).encode(self.node))
        elif isinstance(rec, RawRequest):
            self.telemetry.request_raw(rec.capture_id, rec.channel_mask, rec.n_cycles)

    def _control(self, rec: Control) -> None:
        now, t = self.time_s, self.config.timing
        if rec.command == Command.ENABLE:
            if self.state in (DeviceState.DISABLED, DeviceState.WATCHDOG):
                self.state = DeviceState.ENABLED
                self.faults &= ~Fault.WATCHDOG
                self._disabling = False
                self.last_heartbeat_s = now  # the enable itself proves the host is alive
                self.last_heartbeat_wall_s = self._rx_wall_s
        elif rec.command == Command.DISABLE:
            if self.state in (DeviceState.ENABLED, DeviceState.RAMPING):
                self._disabling = True
                self.player.stop(max(rec.ramp_s, t.min_ramp_s), now)
        elif rec.command == Command.RESET_ESTOP:
            if self.state == DeviceState.ESTOP:
                # A stopping fault raised during the stop stays latched: FAULT until CLEAR_FAULTS.
                self.state = DeviceState.FAULT if self.faults & STOPPING_FAULTS else DeviceState.DISABLED
                self.faults &= ~Fault.ESTOP
        elif rec.command == Command.SUMMARY_HARMONICS:
            self.telemetry.requested_harmonics = rec.harmonics
        elif rec.command == Command.CLEAR_FAULTS and self.state == DeviceState.FAULT:
            self.state = DeviceState.DISABLED
            self.faults &= ~(STOPPING_FAULTS | Fault.TABLE_REJECTED)

    def _commit(self, rec: TableCommit) -> None:
        table, ack = self.tables.commit(rec)
        if self.state not in (DeviceState.ENABLED, DeviceState.RAMPING) or self._disabling:
            table, ack = None, AckResult.BAD_STATE
        if table is None:
            self.faults |= Fault.TABLE_REJECTED
            self._send(TableAck(rec.seq, ack, self.cycle_index).encode(self.node))
            return
        self.faults &= ~Fault.TABLE_REJECTED
        old = self.player.commit(table)
        if old is not None:
            self._send(TableAck(old.seq, AckResult.SUPERSEDED, self.cycle_index).encode(self.node))
        self._send(TableAck(rec.seq, AckResult.ACCEPTED, self.cycle_index).encode(self.node))

    # ------------------------------------------------------------------ safety
    def emergency_stop(self) -> None:
        """Latch the emergency stop and ramp to zero within timing.estop_ramp_s (any state)."""
        if self.state != DeviceState.ESTOP:
            self.player.stop(self.config.timing.estop_ramp_s, self.time_s)
        self.state = DeviceState.ESTOP
        self.faults |= Fault.ESTOP
        self._disabling = False

    def _check_watchdog(self) -> None:
        if not self.watchdog_armed:
            return
        if self.heartbeat_age_s() > self.config.timing.watchdog_timeout_s:
            self.state = DeviceState.WATCHDOG
            self.faults |= Fault.WATCHDOG
            self._disabling = False
            self.player.stop(self.config.timing.watchdog_ramp_s, self.time_s)

    def _fault(self, flag: Fault, at_s: float | None = None) -> None:
        """Latch a fault; a stopping one ramps to zero from ``at_s`` (default now): the end of the
        period in which it was detected, where what was played so far ends (no step on the coils)."""
        at_s = self.time_s if at_s is None else at_s
        if flag & STOPPING_FAULTS and not flag & self.faults:
            self.stopping_fault_count += 1
            if len(self.stopping_faults) < 256:
                self.stopping_faults.append((at_s, Fault(flag), self.state))
        self.faults |= flag
        if self.state in (
            DeviceState.ENABLED,
            DeviceState.RAMPING,
            DeviceState.WATCHDOG,
            DeviceState.DISABLED,
        ):
            if self.state != DeviceState.FAULT:
                self.player.stop(self.config.timing.watchdog_ramp_s, at_s)
            self.state = DeviceState.FAULT

    @property
    def watchdog_armed(self) -> bool:
        """The watchdog acts in these states only (enabled, or ramping to a goal or to zero)."""
        return self.state in (DeviceState.ENABLED, DeviceState.RAMPING)

    def heartbeat_age_s(self) -> float:
        return math.inf if self.last_heartbeat_s is None else self.time_s - self.last_heartbeat_s

    # ------------------------------------------------------------------ stepping
    def advance(self, duration_s: float, max_chunks: int = 1) -> None:
        """Run the device for at least ``duration_s`` of device time (whole chunks; see :meth:`step`)."""
        end = self.time_s + duration_s - 1e-12
        while self.time_s < end:
            self.step(max_chunks)

    def run_until(
        self, predicate: Callable[[SimDevice], bool], timeout_s: float, max_chunks: int = 1
    ) -> bool:
        """Step until ``predicate(self)`` holds or ``timeout_s`` of device time passed; returns it."""
        end = self.time_s + timeout_s
        while self.time_s < end:
            if predicate(self):
                return True
            self.step(max_chunks)
        return bool(predicate(self))

    def step(self, max_chunks: int = 1) -> None:
        """Read the bus, check safety, then play up to ``max_chunks`` firmware periods.

        One firmware period (chunk) is at most ``timing.watchdog_check_s``. The plant is computed
        ahead, in one vectorised call, from the current period to the cycle end (or to the period
        where the watchdog would expire); each step then only releases the next periods (sensor
        readings, truth, faults, thermal state). When anything changes the drive on the way (an
        e-stop, disable, the watchdog, a fault), the precomputed rest is discarded and the plant
        resumes from the current period, so every period plays exactly what the firmware decided at
        its start. With ``max_chunks`` > 1 (faster than real time) several periods are released per
        step and frames are read at the step's start only.
        """
        self._receive()
        self._check_watchdog()
        if self._disabling and self.player.silent(self.time_s):
            self.state, self._disabling = DeviceState.DISABLED, False
        if self.state == DeviceState.ENABLED and (self.player.ramping(self.time_s) or self.player.pending):
            self.state = DeviceState.RAMPING
        elif (
            self.state == DeviceState.RAMPING
            and not self._disabling
            and not (self.player.ramping(self.time_s) or self.player.pending)
        ):
            self.state = DeviceState.ENABLED
        self._report_status()
        a = self._ahead
        if a is None or a.next_chunk >= a.chunks or a.version != self.player.version:
            if a is not None and a.next_chunk < a.chunks:
                row = a.next_chunk * a.rows_per_chunk  # resume from the current period
                self.plant.set_state(a.res.x_grid[row], a.res.u_grid[row])
            a = self._ahead = self._compute_ahead()
        chunks = min(max(1, int(max_chunks)), a.chunks - a.next_chunk)
        first = a.next_chunk * a.rows_per_chunk
        last = first + chunks * a.rows_per_chunk  # exclusive for samples; the period end for states
        res, dt_sample = a.res, self.steps_per_sample * self.dt_s
        samples = slice(first, last)
        self._cycle_samples.append(
            self.sensors.read(
                res.accel_plate[samples], res.omega_plate[samples], res.gravity_plate[samples], dt_sample
            )
        )
        self._cycle_truth.append(res.accel_plate[samples])
        states = slice(first, last + 1)
        current, voltage, leg = res.current[states], res.voltage[states], res.leg[samples]
        self._cycle_peaks = np.maximum(
            self._cycle_peaks,
            np.stack([np.max(np.abs(current), 0), np.max(np.abs(voltage), 0), np.max(np.abs(leg), 0)]),
        )
        self._current_end = current[-1]
        L = chunks * self.steps_per_chunk
        self._update_thermal(current, L * self.dt_s)
        # The period has been played: a fault found in it ramps down from its end, not its start.
        self._check_faults(current, voltage, leg, self.cycle_start_s + (self.step_in_cycle + L) * self.dt_s)
        self.telemetry.pump(L * self.dt_s)
        a.next_chunk += chunks
        self.step_in_cycle += L
        self.time_s = self.cycle_start_s + self.step_in_cycle * self.dt_s
        if self.step_in_cycle >= self.steps_per_cycle:
            self._end_cycle()

    def _compute_ahead(self) -> _Ahead:
        """Simulate from the current period to the cycle end, or to the watchdog's deadline."""
        n0 = self.step_in_cycle
        chunks = (self.steps_per_cycle - n0) // self.steps_per_chunk
        if self.watchdog_armed:
            # End at the first period boundary where the heartbeat would be too old.
            age = self.heartbeat_age_s()
            j = math.floor((self.config.timing.watchdog_timeout_s - age) / self.chunk_s) + 1
            chunks = max(1, min(chunks, j))
        L, m = chunks * self.steps_per_chunk, self.steps_per_sample
        steps = np.arange(n0, n0 + L + 1)
        t = self.cycle_start_s + steps * self.dt_s
        theta = 2 * math.pi * steps / self.steps_per_cycle
        res = self.plant.simulate(self.player.reference(t, theta), self.dt_s, every=m)
        return _Ahead(res, chunks, self.steps_per_chunk // m, self.player.version)

    def _check_faults(self, current: np.ndarray, voltage: np.ndarray, leg: np.ndarray, end_s: float) -> None:
        lim = self.config.limits
        if np.max(np.abs(voltage)) > lim.amplifier_voltage_v:
            self._fault(Fault.VOLTAGE, end_s)
        if np.max(np.abs(leg)) > lim.leg_stroke_m:
            self._fault(Fault.STROKE, end_s)
        if np.max(np.abs(current)) > lim.coil_current_a:
            self._fault(Fault.OVER_CURRENT, end_s)
        if np.max(self.coil_temperature_c) > lim.coil_temperature_c:
            self._fault(Fault.THERMAL, end_s)

    def _update_thermal(self, current: np.ndarray, dt_s: float) -> None:
        a = self.config.actuators
        mean_sq = np.mean(current[1:] ** 2, axis=0)
        target = a.ambient_temperature_c + a.thermal_resistance_k_per_w * a.resistance_ohm * mean_sq
        self.coil_temperature_c += (target - self.coil_temperature_c) * (
            1 - math.exp(-dt_s / a.thermal_time_constant_s)
        )
        self._sq_sum += mean_sq * dt_s
        self._sq_time += dt_s

    def _end_cycle(self) -> None:
        samples = np.concatenate(self._cycle_samples)
        truth = np.concatenate(self._cycle_truth)
        active = self.player.active
        self.telemetry.end_of_cycle(
            self.cycle_index, samples, self.cycle_frequency_hz, active.seq, active.top_harmonic
        )
        H = min(MAX_HARMONIC, self.samples_per_cycle // 2 - 1)
        record = CycleTruth(
            self.cycle_index,
            self.cycle_start_s,
            self.cycle_frequency_hz,
            active.seq,
            self.player.progress(self.time_s),
            analyze(truth, H),
            truth,
            *self._cycle_peaks,
            self._current_end.copy(),
        )
        self.truth.append(record)
        for callback in self.cycle_callbacks:
            callback(record)
        self.cycle_index += 1
        self._start_cycle()

    # ------------------------------------------------------------------ status
    def _report_status(self) -> None:
        now = self.time_s
        if self.counters.rejected_total > self._rejected_reported:
            self.faults |= Fault.FRAME_ERRORS
        key = (self.state, int(self.faults & ~Fault.FRAME_ERRORS))
        if key != self._reported:
            self._reported = key
            self._send(FaultEvent(int(self.faults), self.state, now).encode(self.node))
        if now >= self._next_status_s - 1e-12:
            self._next_status_s = now + 1.0 / self.config.can.status_rate_hz
            self._send(Status(self.state, int(self.faults), self.player.active.seq, now).encode(self.node))
            self._send(
                StatusExt(
                    self.cycle_index,
                    self.player.progress(now),
                    self.heartbeat_age_s(),
                    self.counters.rejected_total,
                ).encode(self.node)
            )
            self._rejected_reported = self.counters.rejected_total
            self.faults &= ~Fault.FRAME_ERRORS
        if now >= self._next_coil_s - 1e-12:
            self._next_coil_s = now + COIL_REPORT_PERIOD_S
            if self._sq_time > 0:
                self.coil_rms_a = np.sqrt(self._sq_sum / self._sq_time)
            self._sq_sum[:], self._sq_time = 0.0, 0.0
            self._send(CoilTemps(tuple(self.coil_temperature_c)).encode(self.node))
            self._send(CoilRms(tuple(self.coil_rms_a)).encode(self.node))

    # ------------------------------------------------------------------ ground truth
    def last_truth(self) -> CycleTruth | None:
        return self.truth[-1] if self.truth else None

    def current_motion(self) -> PlateMotion | None:
        """The plate's actual motion over the last completed cycle (for the parts simulation)."""
        rec = self.last_truth()
        return None if rec is None else rec.motion()


def watchdog_story(device: SimDevice, lag_s: float, wall_now_s: float) -> str:
    """Where a watchdog trip's heartbeats went, for the log line that reports it.

    The device measures the heartbeat's age in device time, at the periods where it reads its bus.
    Set beside it: how long ago (wall clock, ``wall_now_s`` from ``time.time()``) the last heartbeat
    reached the device's bus through the bridge, and how far the device clock ran behind real time
    (``lag_s``, :attr:`ppod_sim.clock.Pacer.lag_s`). A wall age about as long as the device age
    means the host stopped sending (or the bridge stopped delivering); a short wall age with a large
    lag means the simulator read its bus late.
    """
    if device.last_heartbeat_wall_s is None:
        return f"no heartbeat ever reached the bridge; device clock {1e3 * lag_s:.0f} ms behind real time"
    age_ms = 1e3 * (wall_now_s - device.last_heartbeat_wall_s)
    return (f"the last heartbeat reached the bridge {age_ms:.0f} ms ago (wall clock); device clock "
            f"{1e3 * lag_s:.0f} ms behind real time")


__all__ = ["CycleTruth", "SimDevice", "device_limits", "watchdog_story"]

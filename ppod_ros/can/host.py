"""The host side of the PPOD CAN protocol: :class:`DeviceLink`, a ROS-free handle on one device.

A ``DeviceLink`` owns a ``can.BusABC`` (from :func:`ppod_ros.can.bus.open_bus`) and does what the
waveform generator, scripts and ``ppod estop`` need: the protocol-version handshake; tables,
commits, ramps, enable/disable, heartbeats and the emergency stop; and decoding of the device's
frames into :class:`DeviceSnapshot` (status), ``AccelSummary`` (harmonic summaries, complete ones
only) and ``RawCapture`` records (:mod:`ppod_ros.can.assembly`). Malformed frames and incomplete
summaries are counted, never raised.

Threading: :meth:`DeviceLink.poll` processes received frames in the caller's thread (deterministic,
for tests and single-threaded programs); :meth:`DeviceLink.start` runs it in a background thread
instead, and can also send heartbeats on the wall clock. Callbacks run in whichever thread polls.
Sends are serialised by a lock.

Example
-------
>>> link = DeviceLink(open_bus(config.can), config)          # doctest: +SKIP
>>> link.handshake()                                          # doctest: +SKIP
>>> link.enable(); link.start(heartbeat=True)                 # doctest: +SKIP
>>> seq = link.send_plan(GoalPlanner(config).plan(motion))     # doctest: +SKIP
>>> link.wait_for_ack(seq, AckResult.ACTIVE)                  # doctest: +SKIP
"""

from __future__ import annotations

import atexit
import faulthandler
import logging
import math
import threading
import time
import weakref
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TextIO

import can
import numpy as np

from ppod_ros.can.assembly import AccelSummary, RawAssembler, RawCapture, SummaryAssembler
from ppod_ros.can.codec import (
    CoilRms,
    CoilTemps,
    Control,
    DeviceLimit,
    Estop,
    FaultEvent,
    FrameCounters,
    Heartbeat,
    RawData,
    RawHeader,
    RawRequest,
    Record,
    Status,
    StatusExt,
    SummaryData,
    SummaryHeader,
    TableAck,
    Version,
    VersionRequest,
    encode_table,
)
from ppod_ros.can.protocol import (
    LIMIT_LSB,
    PROTOCOL_VERSION,
    AckResult,
    Command,
    DeviceState,
    Fault,
    LimitItem,
    quantise_frequency,
)
from ppod_ros.device.config import DeviceConfig, Limits
from ppod_ros.errors import ConfigError, DeviceError

log = logging.getLogger(__name__)

#: Links whose wall-clock heartbeat thread runs (see :func:`_stop_heartbeats_at_exit`).
_HEARTBEATING: weakref.WeakSet = weakref.WeakSet()


@atexit.register
def _stop_heartbeats_at_exit() -> None:
    """A process on its way out stops its heartbeats first: the device's watchdog then ramps the plate
    down, and the threads do not run on through the interpreter's teardown (which starves them for
    hundreds of milliseconds and would have them report it)."""
    for link in list(_HEARTBEATING):
        link._hb_stop.set()


def send_estop(bus: can.BusABC, node_id: int, reason: int = 0) -> None:
    """Write the emergency-stop frame straight to the bus (no handshake, no state): ``ppod estop``."""
    bus.send(Estop(reason).encode(node_id))


_SCALAR_LIMITS = {
    LimitItem.LEG_STROKE_M: ("leg_stroke_m", "m"),
    LimitItem.COIL_CURRENT_A: ("coil_current_a", "A"),
    LimitItem.AMPLIFIER_VOLTAGE_V: ("amplifier_voltage_v", "V"),
    LimitItem.COIL_TEMPERATURE_C: ("coil_temperature_c", "degC"),
    LimitItem.PLATE_ACCEL_MPS2: ("plate_accel_mps2", "m/s^2"),
    LimitItem.PLATE_ANGULAR_ACCEL_RADPS2: ("plate_angular_accel_radps2", "rad/s^2"),
}


def limits_beyond_device(limits: Limits, reported: list[float]) -> list[str]:
    """Where the host's ``limits`` exceed the device's own (DEVICE_LIMIT values by LimitItem).

    Returns one message per violation (empty: the description fits the device). A host limit may
    be tighter than the device's, never looser; the host's excluded bands must cover the device's.
    """
    tol = LIMIT_LSB  # the values are rounded to 1e-6 on the wire
    out = []
    if len(reported) < LimitItem.EXCLUDED_BAND or (len(reported) - LimitItem.EXCLUDED_BAND) % 2:
        return [f"the device reported {len(reported)} limits, not a whole set"]
    for item, (name, unit) in _SCALAR_LIMITS.items():
        mine, theirs = getattr(limits, name), reported[item]
        if mine > theirs + tol:
            out.append(f"limits.{name} = {mine:g} {unit} exceeds the device's own {theirs:g} {unit}")
    lo, hi = limits.frequency_range_hz
    d_lo, d_hi = reported[LimitItem.FREQUENCY_MIN_HZ], reported[LimitItem.FREQUENCY_MAX_HZ]
    if lo < d_lo - tol or hi > d_hi + tol:
        out.append(f"limits.frequency_range_hz = [{lo:g}, {hi:g}] Hz exceeds the device's own [{d_lo:g}, {d_hi:g}] Hz")
    bands = reported[LimitItem.EXCLUDED_BAND:]
    for b_lo, b_hi in zip(bands[0::2], bands[1::2], strict=True):
        covered = any(h_lo <= b_lo + tol and h_hi >= b_hi - tol for h_lo, h_hi in limits.excluded_bands_hz)
        if not covered and b_hi >= lo and b_lo <= hi:
            out.append(f"limits.excluded_bands_hz does not cover the device's excluded band [{b_lo:g}, {b_hi:g}] Hz")
    return out


def fault_names(flags: int) -> list[str]:
    return [f.name.lower() for f in Fault if flags & f]


@dataclass
class DeviceSnapshot:
    """The device's last reported status (None / NaN until reported)."""

    state: DeviceState | None = None
    faults: int = 0
    active_seq: int = 0
    device_time_s: float = math.nan
    cycle_count: int = 0
    amplitude_scale: float = 0.0
    heartbeat_age_s: float = math.inf
    rx_rejected: int = 0
    coil_temperature_c: tuple[float, ...] = ()
    coil_rms_a: tuple[float, ...] = ()
    received_at: float = math.nan  # host monotonic clock

    @property
    def fault_names(self) -> list[str]:
        return fault_names(self.faults)


@dataclass
class LinkCounters:
    """Host-side counters (frames received are in ``frames``: a FrameCounters)."""

    frames: FrameCounters
    sent: int = 0
    send_errors: int = 0
    summaries: int = 0
    summaries_incomplete: int = 0
    raw_incomplete: int = 0
    unexpected: int = 0
    #: Heartbeats of the wall-clock thread sent more than two periods after the one before (this
    #: process starved: the device's watchdog allows three), and the longest interval seen (s).
    heartbeats_late: int = 0
    heartbeat_max_interval_s: float = 0.0
    #: ... of them, those no keeper process covered (its lease ran out, or none beat): heartbeats the
    #: device missed.
    heartbeats_lost: int = 0
    #: Lease renewals sent to the heartbeat keeper process, and its summary line ("" without one).
    keeper_renewals: int = 0
    keeper: str = ""
    extra: dict = field(default_factory=dict)


class DeviceLink:
    """Host-side protocol endpoint for one device (see the module docstring).

    Parameters
    ----------
    bus : can.BusABC
    config : DeviceConfig
        Node ids, channel count and timing come from it.
    clock : callable, optional
        Monotonic clock for ``received_at`` and timeouts (default ``time.monotonic``).
    """

    def __init__(self, bus: can.BusABC, config: DeviceConfig, clock: Callable[[], float] = time.monotonic):
        self.bus = bus
        self.config = config
        self.node = config.can.device_node_id
        self.host_node = config.can.host_node_id
        self.n_channels = config.accelerometers.num_channels
        self.clock = clock
        self.counters = LinkCounters(FrameCounters(self.node, "to_host"))
        self.status = DeviceSnapshot()
        self.version: Version | None = None
        #: The device's own limits from its DEVICE_LIMIT frames, by LimitItem number (handshake).
        self.device_limits: dict[int, float] = {}
        self._device_limit_count = 0
        self.summaries: deque[AccelSummary] = deque(maxlen=64)
        self.captures: deque[RawCapture] = deque(maxlen=4)
        self.acks: dict[int, list[TableAck]] = {}
        self.fault_events: deque[FaultEvent] = deque(maxlen=64)
        self.table_frequencies: dict[int, float] = {}
        self.on_summary: list[Callable[[AccelSummary], None]] = []
        self.on_status: list[Callable[[DeviceSnapshot], None]] = []
        self.on_ack: list[Callable[[TableAck], None]] = []
        self.on_fault: list[Callable[[FaultEvent], None]] = []
        self.on_raw: list[Callable[[RawCapture], None]] = []
        self._seq = 0
        self._hb_counter = 0
        self._stall_dump: TextIO | None = None
        self._summaries = SummaryAssembler(
            self.n_channels, lambda seq: self.table_frequencies.get(seq, math.nan)
        )
        self._raws = RawAssembler()
        self._send_lock = threading.Lock()
        self._poll_lock = threading.Lock()
        self._cv = threading.Condition()
        self._thread: threading.Thread | None = None
        self._hb_thread: threading.Thread | None = None
        self._keeper = None   # HeartbeatKeeper while the heartbeats have one
        self._stop = threading.Event()
        self._hb_stop = threading.Event()

    # ------------------------------------------------------------------ sending
    def _send(self, msg: can.Message) -> None:
        with self._send_lock:
            try:
                self.bus.send(msg)
            except can.CanError as exc:
                self.counters.send_errors += 1
                raise DeviceError(f"CAN send failed ({type(exc).__name__}): {exc}") from exc
            self.counters.sent += 1

    def estop(self, reason: int = 0) -> None:
        """Emergency stop (highest-priority frame). Raises DeviceError if the bus refuses it."""
        self._send(Estop(reason).encode(self.node))

    def enable(self) -> None:
        self._send(Control(Command.ENABLE).encode(self.node))

    def disable(self, ramp_s: float | None = None) -> None:
        """Ramp to zero (at least the device minimum ramp) and disable."""
        ramp = self.config.timing.default_ramp_s if ramp_s is None else ramp_s
        self._send(Control(Command.DISABLE, ramp).encode(self.node))

    def reset_estop(self) -> None:
        self._send(Control(Command.RESET_ESTOP).encode(self.node))

    def clear_faults(self) -> None:
        self._send(Control(Command.CLEAR_FAULTS).encode(self.node))

    def heartbeat(self) -> None:
        self._hb_counter = (self._hb_counter + 1) % 256
        self._send(Heartbeat(self._hb_counter, self.host_node).encode(self.node))

    def next_seq(self) -> int:
        """Table sequence numbers run 1..255 (0 means 'no table' in the device status)."""
        self._seq = self._seq % 255 + 1
        return self._seq

    def send_table(self, currents: np.ndarray, frequency_hz: float, ramp_s: float) -> int:
        """Send a current table (K, 6) (A, row k-1 = harmonic k) and commit it; returns its sequence number.

        The frames are encoded completely before the first is sent, so an encoding error sends nothing.
        """
        seq = self.next_seq()
        frames = encode_table(seq, frequency_hz, ramp_s, currents, self.node)
        self.table_frequencies[seq] = quantise_frequency(frequency_hz)
        self.acks.pop(seq, None)
        for msg in frames:
            self._send(msg)
        return seq

    def request_summary_harmonics(self, harmonics: int) -> None:
        """Ask the device to summarise harmonics 1..``harmonics`` (at least; within its frame budget)."""
        self._send(Control(Command.SUMMARY_HARMONICS, harmonics=int(harmonics)).encode(self.node))

    def send_plan(self, plan) -> int:
        """Send a :class:`~ppod_ros.actuation.planning.GoalPlan`'s table with its ramp; returns its seq.

        The device is first asked to summarise every harmonic of the table (its rows include the
        third-order distortion products of the goal's harmonics), so the feedback can measure them.
        """
        self.request_summary_harmonics(plan.currents_a.shape[0])
        return self.send_table(plan.currents_a, plan.frequency_hz, plan.ramp_s)

    def send_correction(self, plan, result, ramp_s: float | None = None) -> int:
        """Send a corrected table (a ``CorrectionResult`` of ``plan``), crossfaded over ``ramp_s``.

        The default ramp is the device minimum (``timing.min_ramp_s``): corrections are small
        steps, clipped by the planner, and still never applied as a step on the coils.
        """
        ramp = self.config.timing.min_ramp_s if ramp_s is None else ramp_s
        return self.send_table(result.currents_a, plan.frequency_hz, ramp)

    def send_goal(self, planner, motion):
        """Validate ``motion`` with ``planner`` (a GoalPlanner) and send it only if it passes every limit.

        Returns ``(seq, plan)``. A goal over a limit raises :class:`~ppod_ros.errors.LimitError` and
        sends nothing.
        """
        plan = planner.plan(motion)
        return self.send_plan(plan), plan

    def stop_motion(self, ramp_s: float | None = None, frequency_hz: float | None = None) -> int:
        """Commit an all-zero table: ramp the plate to rest and stay enabled."""
        ramp = self.config.timing.default_ramp_s if ramp_s is None else ramp_s
        freq = frequency_hz or self.config.sim.idle_frequency_hz
        return self.send_table(np.zeros((1, 6), complex), freq, ramp)

    def request_raw(self, channel_mask: int, n_cycles: int, capture_id: int = 0) -> None:
        self._send(RawRequest(capture_id, channel_mask, n_cycles).encode(self.node))

    def _limits_complete(self) -> bool:
        n = self._device_limit_count
        return n > 0 and all(i in self.device_limits for i in range(n))

    def handshake(self, timeout_s: float = 1.0) -> Version:
        """Exchange protocol versions and check the configuration against the device's own limits.

        Raises DeviceError on timeout or an incompatible major version, ConfigError when the device
        description's limits exceed the limits the device reports (DEVICE_LIMIT frames).
        """
        self.version = None
        self.device_limits, self._device_limit_count = {}, 0
        self._send(VersionRequest(*PROTOCOL_VERSION, self.host_node).encode(self.node))
        if not self.wait_for(lambda: self.version is not None and (
                self.version.major != PROTOCOL_VERSION[0] or self._limits_complete()), timeout_s):
            if self.version is None:
                raise DeviceError(f"no VERSION reply from device node {self.node} within {timeout_s:g} s")
            raise DeviceError(f"device node {self.node} did not report all its limits within {timeout_s:g} s")
        v = self.version
        if v.major != PROTOCOL_VERSION[0]:
            raise DeviceError(
                f"device speaks protocol {v.major}.{v.minor}, this host {PROTOCOL_VERSION[0]}."
                f"{PROTOCOL_VERSION[1]}: incompatible major version"
            )
        if v.n_channels != self.n_channels:
            raise DeviceError(
                f"device reports {v.n_channels} accelerometer channels, the configuration has "
                f"{self.n_channels}"
            )
        reported = [self.device_limits[i] for i in range(self._device_limit_count)]
        problems = limits_beyond_device(self.config.limits, reported)
        if problems:
            raise ConfigError(
                f"device description {self.config.source or self.config.name!r} is not safe for device node "
                f"{self.node}: " + "; ".join(problems)
            )
        return v

    # ------------------------------------------------------------------ receiving
    def poll(self, timeout_s: float = 0.0) -> int:
        """Process received frames until the bus is empty (waiting up to ``timeout_s`` for the first)."""
        n = 0
        with self._poll_lock:
            wait = timeout_s
            while True:
                try:
                    msg = self.bus.recv(wait)
                except can.CanError as exc:
                    self.counters.extra["recv_errors"] = self.counters.extra.get("recv_errors", 0) + 1
                    log.warning("CAN receive failed: %s", exc)
                    break
                if msg is None:
                    break
                wait = 0.0
                n += 1
                rec = self.counters.frames.decode(msg)
                if rec is not None:
                    self._dispatch(rec)
        if n:
            with self._cv:
                self._cv.notify_all()
        return n

    def _dispatch(self, rec: Record) -> None:
        now = self.clock()
        if isinstance(rec, Status):
            s = self.status
            s.state, s.faults, s.active_seq, s.device_time_s, s.received_at = (
                rec.state,
                rec.faults,
                rec.active_seq,
                rec.device_time_s,
                now,
            )
            for cb in self.on_status:
                cb(s)
        elif isinstance(rec, StatusExt):
            s = self.status
            s.cycle_count, s.amplitude_scale, s.heartbeat_age_s, s.rx_rejected = (
                rec.cycle_count,
                rec.amplitude_scale,
                rec.heartbeat_age_s,
                rec.rx_rejected,
            )
        elif isinstance(rec, CoilTemps):
            self.status.coil_temperature_c = rec.temperature_c
        elif isinstance(rec, CoilRms):
            self.status.coil_rms_a = rec.current_rms_a
        elif isinstance(rec, FaultEvent):
            self.status.faults, self.status.state = rec.faults, rec.state
            self.fault_events.append(rec)
            for cb in self.on_fault:
                cb(rec)
        elif isinstance(rec, TableAck):
            self.acks.setdefault(rec.seq, []).append(rec)
            for cb in self.on_ack:
                cb(rec)
        elif isinstance(rec, Version):
            self.version = rec
        elif isinstance(rec, DeviceLimit):
            self.device_limits[rec.item] = rec.value
            self._device_limit_count = rec.count
        elif isinstance(rec, SummaryHeader):
            self._summary_header(rec)
        elif isinstance(rec, SummaryData):
            self._summary_data(rec, now)
        elif isinstance(rec, RawHeader):
            self._raw_header(rec)
        elif isinstance(rec, RawData):
            self._raw_data(rec)
        else:
            self.counters.unexpected += 1

    def _summary_header(self, rec: SummaryHeader) -> None:
        self._summaries.header(rec)
        self.counters.summaries_incomplete = self._summaries.incomplete

    def _summary_data(self, rec: SummaryData, now: float) -> None:
        summary = self._summaries.data(rec, now)
        self.counters.frames.rejected["summary data without header"] = self._summaries.orphans
        if summary is not None:
            self.counters.summaries = self._summaries.completed
            self.summaries.append(summary)
            for cb in self.on_summary:
                cb(summary)

    def _raw_header(self, rec: RawHeader) -> None:
        self._raws.header(rec)
        self.counters.raw_incomplete = self._raws.incomplete

    def _raw_data(self, rec: RawData) -> None:
        cap = self._raws.data(rec)
        self.counters.frames.rejected["raw data without header"] = self._raws.orphans
        if cap is not None:
            self.captures.append(cap)
            for cb in self.on_raw:
                cb(cap)

    # ------------------------------------------------------------------ health
    def status_age_s(self) -> float:
        """Seconds since the device's last STATUS frame (inf before the first): its heartbeat."""
        received = self.status.received_at
        return math.inf if math.isnan(received) else self.clock() - received

    def health(self, stale_after_s: float | None = None) -> dict:
        """A flat summary for diagnostics: link state, device state and every error counter.

        ``stale`` is true when no STATUS arrived for ``stale_after_s`` (default: three status periods):
        a lost device, a cut bus or bus-off.
        """
        stale_after = 3.0 / self.config.can.status_rate_hz if stale_after_s is None else stale_after_s
        c, s = self.counters, self.status
        age = self.status_age_s()
        return {
            "stale": age > stale_after,
            "status_age_s": age,
            "state": s.state.name if s.state is not None else "UNKNOWN",
            "faults": ", ".join(s.fault_names),
            "device_rx_rejected": s.rx_rejected,
            "frames_accepted": c.frames.accepted,
            "frames_rejected": c.frames.rejected_total,
            "frames_foreign": c.frames.foreign,
            "frames_sent": c.sent,
            "send_errors": c.send_errors,
            "summaries": c.summaries,
            "summaries_incomplete": c.summaries_incomplete,
            "raw_incomplete": c.raw_incomplete,
        }

    # ------------------------------------------------------------------ waiting
    def wait_for(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Poll (or, with a running receive thread, wait) until ``predicate()`` or the timeout."""
        deadline = self.clock() + timeout_s
        while True:
            if predicate():
                return True
            remaining = deadline - self.clock()
            if remaining <= 0:
                return bool(predicate())
            if self._thread is not None:
                with self._cv:
                    self._cv.wait(min(remaining, 0.05))
            else:
                self.poll(min(remaining, 0.01))

    def wait_for_ack(
        self, seq: int, result: AckResult = AckResult.ACCEPTED, timeout_s: float = 1.0
    ) -> TableAck:
        """Wait for the device's acknowledgement of table ``seq``.

        Raises DeviceError when the device rejects the table or nothing arrives within ``timeout_s``.
        """
        final = (AckResult.ACCEPTED, AckResult.ACTIVE) if result == AckResult.ACCEPTED else (result,)

        def match() -> TableAck | None:
            for ack in self.acks.get(seq, []):
                if ack.result in final or ack.result not in (AckResult.ACCEPTED, AckResult.ACTIVE):
                    return ack
            return None

        if not self.wait_for(lambda: match() is not None, timeout_s):
            raise DeviceError(f"no {result.name} acknowledgement for table {seq} within {timeout_s:g} s")
        ack = match()
        if ack.result not in final:
            raise DeviceError(f"device rejected table {seq}: {ack.result.name}")
        return ack

    # ------------------------------------------------------------------ threads
    def start(self, heartbeat: bool = False) -> None:
        """Receive in a background thread; with ``heartbeat`` also send heartbeats on the wall clock."""
        if self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._rx_loop, name="ppod-can-rx", daemon=True)
        self._thread.start()
        if heartbeat:
            self.start_heartbeat()

    def start_heartbeat(self, stall_dump: TextIO | None = None, keeper_lease_s: float | None = None) -> None:
        """Send heartbeats every ``can.heartbeat_period_s`` of wall-clock time from a thread of their own.

        ``stall_dump``: a file (with a file descriptor, e.g. ``sys.stderr``) to which every thread's
        Python stack is written, from outside the interpreter, when the heartbeat thread has not run
        for two heartbeat periods: what held the process (the GIL) when a heartbeat was late
        (``faulthandler.dump_traceback_later``, which is process-wide: for a process with one link,
        the waveform generator's). None: no dump.

        ``keeper_lease_s``: the heartbeats are sent by a keeper process
        (:class:`~ppod_ros.can.keeper.HeartbeatKeeper`) whose lease the thread renews every period
        for this long, so that a thread held off the GIL for less than the lease does not stop them.
        Until the keeper is ready, and once it is gone, the thread sends them itself. None: the thread
        alone (and for a backend a second process cannot open, ``keeper_supported``)."""
        if self._hb_thread is not None:
            return
        self._keeper = None
        if keeper_lease_s is not None:
            from ppod_ros.can.keeper import HeartbeatKeeper, keeper_supported

            if not keeper_supported(self.config.can.interface):
                log.info("heartbeats from this process's thread: the %s backend cannot be opened by a keeper "
                         "process", self.config.can.interface)
            else:
                try:
                    self._keeper = HeartbeatKeeper(self.config.can, keeper_lease_s)
                except (ConfigError, DeviceError) as exc:
                    log.warning("heartbeats from this process's thread: %s", exc)
        if stall_dump is not None:
            try:
                stall_dump.fileno()
            except (AttributeError, OSError, ValueError) as exc:   # io.UnsupportedOperation is an OSError
                log.warning("heartbeat stalls: no stack dump (%s has no file descriptor: %s)", stall_dump, exc)
                stall_dump = None
        self._stall_dump = stall_dump
        self._hb_stop.clear()
        self._hb_thread = threading.Thread(target=self._hb_loop, name="ppod-can-heartbeat", daemon=True)
        self._hb_thread.start()
        _HEARTBEATING.add(self)

    def stop_heartbeat(self) -> None:
        self._hb_stop.set()
        _HEARTBEATING.discard(self)
        if self._hb_thread is not None:
            self._hb_thread.join(timeout=2.0)
        self._hb_thread = None
        keeper, self._keeper = self._keeper, None
        if keeper is not None:
            self.counters.keeper = keeper.close()
            log.info("heartbeat keeper (pid %d): %s", keeper.pid, self.counters.keeper)
        if self._stall_dump is not None:
            faulthandler.cancel_dump_traceback_later()
            self._stall_dump = None

    def _rx_loop(self) -> None:
        while not self._stop.is_set():
            self.poll(0.02)

    def _hb_loop(self) -> None:
        period = self.config.can.heartbeat_period_s
        next_t = time.monotonic()
        last_sent = None
        while not (self._stop.is_set() or self._hb_stop.is_set()):
            woke = time.monotonic()
            keeper = self._keeper
            if keeper is not None and keeper.ready() and keeper.renew():
                self.counters.keeper_renewals += 1
            else:
                if keeper is not None and not keeper.alive():
                    log.warning("the heartbeat keeper (pid %d) is gone (exit code %s): heartbeats from this "
                                "process's thread", keeper.pid, keeper.process.returncode)
                    self._keeper = None
                    self.counters.keeper = f"gone (exit code {keeper.process.returncode})"
                try:
                    self.heartbeat()
                except DeviceError as exc:
                    log.warning("heartbeat not sent: %s", exc)
            sent = time.monotonic()
            if last_sent is not None:
                self._heartbeat_interval(sent - last_sent, woke - next_t, sent - woke, period)
            last_sent = sent
            # After a stall, beat on from now rather than send the missed heartbeats in a burst.
            next_t = max(next_t + period, sent)
            wait = max(0.0, next_t - time.monotonic())
            if self._stall_dump is not None:
                # Armed for the wait and two periods more (with a keeper: its lease, the stall that
                # stops the heartbeats): only a thread that cannot run disarms late.
                keeper = self._keeper
                grace = keeper.lease_s if keeper is not None and keeper.ready() else 2 * period
                faulthandler.dump_traceback_later(wait + grace, file=self._stall_dump)
            self._hb_stop.wait(wait)
            if self._stall_dump is not None:
                faulthandler.cancel_dump_traceback_later()

    def _heartbeat_interval(self, interval_s: float, woke_late_s: float, send_s: float, period_s: float) -> None:
        c = self.counters
        c.heartbeat_max_interval_s = max(c.heartbeat_max_interval_s, interval_s)
        if interval_s > 2 * period_s:
            # Said where it happens: a watchdog trip after it is this host's, not the device's.
            c.heartbeats_late += 1
            keeper = self._keeper
            keeping = keeper is not None and keeper.ready()
            covered = keeping and interval_s < keeper.lease_s
            c.heartbeats_lost += not covered
            after = ""
            if keeping:
                after = (f"; the heartbeat keeper beat on (lease {1e3 * keeper.lease_s:.0f} ms)" if covered
                         else "; the keeper's lease ran out: it stopped beating")
            (log.info if covered else log.warning)(
                "%s %.0f ms after the one before (period %.0f ms): the thread woke %.0f ms late and the send "
                "took %.0f ms; this process is starved%s", "lease renewed" if keeping else "heartbeat sent",
                1e3 * interval_s, 1e3 * period_s, 1e3 * max(woke_late_s, 0.0), 1e3 * send_s, after)

    def stop(self) -> None:
        """Stop the background threads (the bus stays open: the caller owns it)."""
        self._stop.set()
        self.stop_heartbeat()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self._thread = None


__all__ = ["DeviceLink", "DeviceSnapshot", "LinkCounters", "fault_names", "limits_beyond_device", "send_estop"]

"""Encoding and decoding of every PPOD CAN frame (docs/can_protocol.md), with error counting.

Each frame type is a frozen record with ``encode(node) -> can.Message``; :func:`decode` turns a
received ``can.Message`` back into its record or raises :class:`~ppod_ros.errors.ProtocolError`
whose ``reason`` says why (``unknown id``, ``wrong direction``, ``wrong length``, ``out of range``,
``not a data frame``). :class:`FrameCounters` wraps it so that a receiver never crashes on a bad
frame: it counts and drops it. Values that do not fit their field are rejected when encoding too:
nothing is silently clipped.
"""

from __future__ import annotations

import binascii
import math
import struct
from collections import Counter
from dataclasses import dataclass, field
from typing import ClassVar

import can
import numpy as np

from ppod_ros.can.protocol import (
    BROADCAST_NODE,
    COIL_RMS_LSB_A,
    CURRENT_LSB_A,
    CYCLE_MODULUS,
    DEVICE_TO_HOST,
    FREQUENCY_LSB_HZ,
    HEARTBEAT_AGE_LSB_S,
    HOST_TO_DEVICE,
    INT24_MAX,
    MAX_CHANNELS,
    MAX_RAW_CYCLES,
    MAX_RAW_SAMPLES,
    MAX_SUMMARY_CYCLES,
    MAX_TABLE_HARMONIC,
    NUM_ACTUATORS,
    RAMP_LSB_S,
    RAW_LSB_MPS2,
    SUMMARY_LSB_MPS2,
    TIME_LSB_S,
    AckResult,
    Command,
    DeviceState,
    Fn,
    can_id,
    split_id,
)
from ppod_ros.errors import ProtocolError


def _err(reason: str, detail: str) -> ProtocolError:
    exc = ProtocolError(f"{reason}: {detail}")
    exc.reason = reason  # type: ignore[attr-defined]
    return exc


def _int(value: float, lo: int, hi: int, name: str) -> int:
    if not (isinstance(value, (int, np.integer)) or (isinstance(value, float) and math.isfinite(value))):
        raise _err("out of range", f"{name}: expected a finite number, got {value!r}")
    v = int(round(value))
    if not lo <= v <= hi:
        raise _err("out of range", f"{name}: {value!r} does not fit {lo}..{hi}")
    return v


def _scaled(value: float, lsb: float, lo: int, hi: int, name: str) -> int:
    if not math.isfinite(value):
        raise _err("out of range", f"{name}: must be finite, got {value!r}")
    return _int(round(value / lsb), lo, hi, name)


def _i24(v: int) -> bytes:
    return (v & 0xFFFFFF).to_bytes(3, "little")


def _from_i24(b: bytes) -> int:
    v = int.from_bytes(b, "little")
    return v - (1 << 24) if v & 0x800000 else v


def _u24(v: int) -> bytes:
    return v.to_bytes(3, "little")


def _complex24(value: complex, lsb: float, name: str) -> bytes:
    return _i24(_scaled(value.real, lsb, -INT24_MAX, INT24_MAX, f"{name}.real")) + _i24(
        _scaled(value.imag, lsb, -INT24_MAX, INT24_MAX, f"{name}.imag")
    )


def _from_complex24(b: bytes, lsb: float) -> complex:
    return complex(_from_i24(b[0:3]) * lsb, _from_i24(b[3:6]) * lsb)


@dataclass(frozen=True)
class Record:
    """Base of all frame records; subclasses define FN, LENGTH and _payload/_parse."""

    FN: ClassVar[Fn]
    LENGTH: ClassVar[int]

    def _payload(self) -> bytes:
        raise NotImplementedError

    def encode(self, node: int) -> can.Message:
        data = self._payload()
        if len(data) != self.LENGTH:
            raise _err(
                "wrong length", f"{type(self).__name__} payload has {len(data)} bytes, expected {self.LENGTH}"
            )
        return can.Message(arbitration_id=can_id(self.FN, node), data=data, is_extended_id=False)


# --------------------------------------------------------------------------- host -> device
@dataclass(frozen=True)
class Estop(Record):
    FN: ClassVar[Fn] = Fn.ESTOP
    LENGTH: ClassVar[int] = 1
    reason: int = 0

    def _payload(self) -> bytes:
        return bytes([_int(self.reason, 0, 255, "reason")])

    @classmethod
    def _parse(cls, d: bytes) -> Estop:
        # Any payload stops the device: the identifier alone is the command (fail safe).
        return cls(d[0] if d else 0)


@dataclass(frozen=True)
class Control(Record):
    FN: ClassVar[Fn] = Fn.CONTROL
    LENGTH: ClassVar[int] = 3
    command: Command
    ramp_s: float = 0.0

    def _payload(self) -> bytes:
        return struct.pack(
            "<BH",
            _int(int(self.command), 1, 255, "command"),
            _scaled(self.ramp_s, RAMP_LSB_S, 0, 0xFFFF, "ramp_s"),
        )

    @classmethod
    def _parse(cls, d: bytes) -> Control:
        cmd, ramp = struct.unpack("<BH", d)
        if cmd not in Command._value2member_map_:
            raise _err("out of range", f"control command {cmd} is unknown")
        return cls(Command(cmd), ramp * RAMP_LSB_S)


@dataclass(frozen=True)
class Heartbeat(Record):
    FN: ClassVar[Fn] = Fn.HEARTBEAT
    LENGTH: ClassVar[int] = 2
    counter: int
    host_node: int = 0

    def _payload(self) -> bytes:
        return bytes([self.counter & 0xFF, _int(self.host_node, 0, 15, "host_node")])

    @classmethod
    def _parse(cls, d: bytes) -> Heartbeat:
        if d[1] > 15:
            raise _err("out of range", f"heartbeat host node {d[1]} > 15")
        return cls(d[0], d[1])


@dataclass(frozen=True)
class TableHeader(Record):
    FN: ClassVar[Fn] = Fn.TABLE_HEADER
    LENGTH: ClassVar[int] = 8
    seq: int
    n_entries: int
    frequency_hz: float
    ramp_s: float

    def _payload(self) -> bytes:
        return struct.pack(
            "<BBIH",
            _int(self.seq, 0, 255, "seq"),
            _int(self.n_entries, 0, NUM_ACTUATORS * MAX_TABLE_HARMONIC, "n_entries"),
            _scaled(self.frequency_hz, FREQUENCY_LSB_HZ, 1, 0xFFFFFFFF, "frequency_hz"),
            _scaled(self.ramp_s, RAMP_LSB_S, 0, 0xFFFF, "ramp_s"),
        )

    @classmethod
    def _parse(cls, d: bytes) -> TableHeader:
        seq, n, f, ramp = struct.unpack("<BBIH", d)
        if n > NUM_ACTUATORS * MAX_TABLE_HARMONIC or f == 0:
            raise _err("out of range", f"table header n_entries {n} or frequency {f} uHz")
        return cls(seq, n, f * FREQUENCY_LSB_HZ, ramp * RAMP_LSB_S)


@dataclass(frozen=True)
class TableEntry(Record):
    FN: ClassVar[Fn] = Fn.TABLE_ENTRY
    LENGTH: ClassVar[int] = 8
    seq: int
    actuator: int
    k: int
    current_a: complex

    def _payload(self) -> bytes:
        a = _int(self.actuator, 0, NUM_ACTUATORS - 1, "actuator")
        k = _int(self.k, 1, MAX_TABLE_HARMONIC, "k")
        return bytes([_int(self.seq, 0, 255, "seq"), a << 4 | k]) + _complex24(
            complex(self.current_a), CURRENT_LSB_A, "current_a"
        )

    @classmethod
    def _parse(cls, d: bytes) -> TableEntry:
        a, k = d[1] >> 4, d[1] & 0xF
        if a >= NUM_ACTUATORS or not 1 <= k <= MAX_TABLE_HARMONIC:
            raise _err("out of range", f"table entry actuator {a} / harmonic {k}")
        return cls(d[0], a, k, _from_complex24(d[2:8], CURRENT_LSB_A))

    def checksum_bytes(self) -> bytes:
        return self._payload()[1:]


@dataclass(frozen=True)
class TableCommit(Record):
    FN: ClassVar[Fn] = Fn.TABLE_COMMIT
    LENGTH: ClassVar[int] = 4
    seq: int
    n_entries: int
    checksum: int

    def _payload(self) -> bytes:
        return struct.pack(
            "<BBH",
            _int(self.seq, 0, 255, "seq"),
            _int(self.n_entries, 0, NUM_ACTUATORS * MAX_TABLE_HARMONIC, "n_entries"),
            _int(self.checksum, 0, 0xFFFF, "checksum"),
        )

    @classmethod
    def _parse(cls, d: bytes) -> TableCommit:
        seq, n, crc = struct.unpack("<BBH", d)
        if n > NUM_ACTUATORS * MAX_TABLE_HARMONIC:
            raise _err("out of range", f"table commit n_entries {n}")
        return cls(seq, n, crc)


@dataclass(frozen=True)
class VersionRequest(Record):
    FN: ClassVar[Fn] = Fn.VERSION_REQUEST
    LENGTH: ClassVar[int] = 3
    major: int
    minor: int
    host_node: int = 0

    def _payload(self) -> bytes:
        return bytes(
            [
                _int(self.major, 0, 255, "major"),
                _int(self.minor, 0, 255, "minor"),
                _int(self.host_node, 0, 15, "host_node"),
            ]
        )

    @classmethod
    def _parse(cls, d: bytes) -> VersionRequest:
        if d[2] > 15:
            raise _err("out of range", f"version request host node {d[2]}")
        return cls(d[0], d[1], d[2])


@dataclass(frozen=True)
class RawRequest(Record):
    FN: ClassVar[Fn] = Fn.RAW_REQUEST
    LENGTH: ClassVar[int] = 4
    capture_id: int
    channel_mask: int
    n_cycles: int

    def _payload(self) -> bytes:
        return struct.pack(
            "<BHB",
            _int(self.capture_id, 0, 15, "capture_id"),
            _int(self.channel_mask, 1, 0xFFFF, "channel_mask"),
            _int(self.n_cycles, 1, MAX_RAW_CYCLES, "n_cycles"),
        )

    @classmethod
    def _parse(cls, d: bytes) -> RawRequest:
        cid, mask, n = struct.unpack("<BHB", d)
        if cid > 15 or mask == 0 or not 1 <= n <= MAX_RAW_CYCLES:
            raise _err("out of range", f"raw request id {cid}, mask {mask:#x}, cycles {n}")
        return cls(cid, mask, n)


# --------------------------------------------------------------------------- device -> host
@dataclass(frozen=True)
class FaultEvent(Record):
    FN: ClassVar[Fn] = Fn.FAULT
    LENGTH: ClassVar[int] = 7
    faults: int
    state: DeviceState
    device_time_s: float

    def _payload(self) -> bytes:
        return struct.pack(
            "<HBI",
            _int(self.faults, 0, 0xFFFF, "faults"),
            int(self.state),
            _scaled(self.device_time_s, TIME_LSB_S, 0, 0xFFFFFFFF, "device_time_s"),
        )

    @classmethod
    def _parse(cls, d: bytes) -> FaultEvent:
        faults, state, t = struct.unpack("<HBI", d)
        return cls(faults, _state(state), t * TIME_LSB_S)


@dataclass(frozen=True)
class TableAck(Record):
    FN: ClassVar[Fn] = Fn.TABLE_ACK
    LENGTH: ClassVar[int] = 5
    seq: int
    result: AckResult
    cycle_index: int = 0

    def _payload(self) -> bytes:
        return bytes([_int(self.seq, 0, 255, "seq"), int(self.result)]) + _u24(
            self.cycle_index % CYCLE_MODULUS
        )

    @classmethod
    def _parse(cls, d: bytes) -> TableAck:
        if d[1] not in AckResult._value2member_map_:
            raise _err("out of range", f"table ack result {d[1]}")
        return cls(d[0], AckResult(d[1]), int.from_bytes(d[2:5], "little"))


def _state(value: int) -> DeviceState:
    if value not in DeviceState._value2member_map_:
        raise _err("out of range", f"device state {value}")
    return DeviceState(value)


@dataclass(frozen=True)
class Status(Record):
    FN: ClassVar[Fn] = Fn.STATUS
    LENGTH: ClassVar[int] = 8
    state: DeviceState
    faults: int
    active_seq: int
    device_time_s: float

    def _payload(self) -> bytes:
        return struct.pack(
            "<BHBI",
            int(self.state),
            _int(self.faults, 0, 0xFFFF, "faults"),
            _int(self.active_seq, 0, 255, "active_seq"),
            _scaled(self.device_time_s, TIME_LSB_S, 0, 0xFFFFFFFF, "device_time_s"),
        )

    @classmethod
    def _parse(cls, d: bytes) -> Status:
        state, faults, seq, t = struct.unpack("<BHBI", d)
        return cls(_state(state), faults, seq, t * TIME_LSB_S)


@dataclass(frozen=True)
class StatusExt(Record):
    FN: ClassVar[Fn] = Fn.STATUS_EXT
    LENGTH: ClassVar[int] = 8
    cycle_count: int
    amplitude_scale: float
    heartbeat_age_s: float
    rx_rejected: int

    def _payload(self) -> bytes:
        age = self.heartbeat_age_s
        age_code = (
            255 if not math.isfinite(age) else min(255, _int(age / HEARTBEAT_AGE_LSB_S, 0, 1 << 30, "age"))
        )
        return struct.pack(
            "<IBBH",
            self.cycle_count & 0xFFFFFFFF,
            _int(self.amplitude_scale * 255, 0, 255, "amplitude_scale"),
            age_code,
            self.rx_rejected & 0xFFFF,
        )

    @classmethod
    def _parse(cls, d: bytes) -> StatusExt:
        cycles, scale, age, rej = struct.unpack("<IBBH", d)
        return cls(cycles, scale / 255, math.inf if age == 255 else age * HEARTBEAT_AGE_LSB_S, rej)


@dataclass(frozen=True)
class CoilTemps(Record):
    FN: ClassVar[Fn] = Fn.COIL_TEMP
    LENGTH: ClassVar[int] = 6
    temperature_c: tuple[float, ...]

    def _payload(self) -> bytes:
        return bytes(_int(min(255.0, max(0.0, t)), 0, 255, "temperature_c") for t in self.temperature_c)

    @classmethod
    def _parse(cls, d: bytes) -> CoilTemps:
        return cls(tuple(float(b) for b in d))


@dataclass(frozen=True)
class CoilRms(Record):
    FN: ClassVar[Fn] = Fn.COIL_RMS
    LENGTH: ClassVar[int] = 6
    current_rms_a: tuple[float, ...]

    def _payload(self) -> bytes:
        return bytes(
            min(255, _int(i / COIL_RMS_LSB_A, 0, 1 << 30, "current_rms_a")) for i in self.current_rms_a
        )

    @classmethod
    def _parse(cls, d: bytes) -> CoilRms:
        return cls(tuple(b * COIL_RMS_LSB_A for b in d))


@dataclass(frozen=True)
class Version(Record):
    FN: ClassVar[Fn] = Fn.VERSION
    LENGTH: ClassVar[int] = 7
    major: int
    minor: int
    n_actuators: int
    n_channels: int
    max_harmonic: int
    node_id: int
    simulated: bool

    def _payload(self) -> bytes:
        return bytes(
            [
                _int(self.major, 0, 255, "major"),
                _int(self.minor, 0, 255, "minor"),
                _int(self.n_actuators, 1, NUM_ACTUATORS, "n_actuators"),
                _int(self.n_channels, 1, MAX_CHANNELS, "n_channels"),
                _int(self.max_harmonic, 1, MAX_TABLE_HARMONIC, "max_harmonic"),
                _int(self.node_id, 1, 15, "node_id"),
                int(bool(self.simulated)),
            ]
        )

    @classmethod
    def _parse(cls, d: bytes) -> Version:
        if not (
            1 <= d[2] <= NUM_ACTUATORS
            and 1 <= d[3] <= MAX_CHANNELS
            and 1 <= d[4] <= MAX_TABLE_HARMONIC
            and 1 <= d[5] <= 15
            and d[6] <= 1
        ):
            raise _err("out of range", f"version fields {list(d)}")
        return cls(d[0], d[1], d[2], d[3], d[4], d[5], bool(d[6]))


@dataclass(frozen=True)
class SummaryHeader(Record):
    FN: ClassVar[Fn] = Fn.SUMMARY_HEADER
    LENGTH: ClassVar[int] = 8
    seq: int
    n_cycles: int
    harmonics: int
    cycle_index: int
    samples_per_cycle: int
    table_seq: int

    def _payload(self) -> bytes:
        packed = (_int(self.n_cycles, 1, MAX_SUMMARY_CYCLES, "n_cycles") - 1) << 4 | _int(
            self.harmonics, 1, MAX_TABLE_HARMONIC, "harmonics"
        )
        return (
            bytes([_int(self.seq, 0, 255, "seq"), packed])
            + _u24(self.cycle_index % CYCLE_MODULUS)
            + struct.pack(
                "<HB",
                _int(self.samples_per_cycle, 8, 0xFFFF, "samples_per_cycle"),
                _int(self.table_seq, 0, 255, "table_seq"),
            )
        )

    @classmethod
    def _parse(cls, d: bytes) -> SummaryHeader:
        spc, tseq = struct.unpack("<HB", d[5:8])
        n, h = (d[1] >> 4) + 1, d[1] & 0xF
        if not 1 <= h <= MAX_TABLE_HARMONIC or spc < 8 or h >= spc // 2:
            raise _err("out of range", f"summary header harmonics {h}, samples_per_cycle {spc}")
        return cls(d[0], n, h, int.from_bytes(d[2:5], "little"), spc, tseq)


@dataclass(frozen=True)
class SummaryData(Record):
    FN: ClassVar[Fn] = Fn.SUMMARY_DATA
    LENGTH: ClassVar[int] = 8
    seq: int
    channel: int
    k: int
    value_mps2: complex

    def _payload(self) -> bytes:
        ch = _int(self.channel, 0, MAX_CHANNELS - 1, "channel")
        k = _int(self.k, 1, MAX_TABLE_HARMONIC, "k")
        return bytes([_int(self.seq, 0, 255, "seq"), ch << 4 | k]) + _complex24(
            complex(self.value_mps2), SUMMARY_LSB_MPS2, "value_mps2"
        )

    @classmethod
    def _parse(cls, d: bytes) -> SummaryData:
        ch, k = d[1] >> 4, d[1] & 0xF
        if not 1 <= k <= MAX_TABLE_HARMONIC:
            raise _err("out of range", f"summary harmonic {k}")
        return cls(d[0], ch, k, _from_complex24(d[2:8], SUMMARY_LSB_MPS2))


@dataclass(frozen=True)
class RawHeader(Record):
    FN: ClassVar[Fn] = Fn.RAW_HEADER
    LENGTH: ClassVar[int] = 8
    capture_id: int
    n_cycles: int
    channel_mask: int
    start_cycle: int
    samples_per_cycle: int

    def _payload(self) -> bytes:
        head = _int(self.capture_id, 0, 15, "capture_id") << 4 | (
            _int(self.n_cycles, 1, MAX_RAW_CYCLES, "n_cycles") - 1
        )
        return (
            struct.pack("<BH", head, _int(self.channel_mask, 1, 0xFFFF, "channel_mask"))
            + _u24(self.start_cycle % CYCLE_MODULUS)
            + struct.pack("<H", _int(self.samples_per_cycle, 8, 0xFFFF, "samples_per_cycle"))
        )

    @classmethod
    def _parse(cls, d: bytes) -> RawHeader:
        head, mask = struct.unpack("<BH", d[0:3])
        (spc,) = struct.unpack("<H", d[6:8])
        n = (head & 0xF) + 1
        if mask == 0 or spc < 8 or n * spc > MAX_RAW_SAMPLES:
            raise _err("out of range", f"raw header mask {mask:#x}, samples_per_cycle {spc}, cycles {n}")
        return cls(head >> 4, n, mask, int.from_bytes(d[3:6], "little"), spc)


@dataclass(frozen=True)
class RawData(Record):
    FN: ClassVar[Fn] = Fn.RAW_DATA
    LENGTH: ClassVar[int] = 8
    channel: int
    index: int
    samples_mps2: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0))

    def _payload(self) -> bytes:
        ch = _int(self.channel, 0, MAX_CHANNELS - 1, "channel")
        idx = _int(self.index, 0, MAX_RAW_SAMPLES - 1, "index")
        vals = [_scaled(v, RAW_LSB_MPS2, -32768, 32767, "samples_mps2") for v in self.samples_mps2]
        return struct.pack("<H3h", ch << 12 | idx, *vals)

    @classmethod
    def _parse(cls, d: bytes) -> RawData:
        head, a, b, c = struct.unpack("<H3h", d)
        return cls(head >> 12, head & 0xFFF, (a * RAW_LSB_MPS2, b * RAW_LSB_MPS2, c * RAW_LSB_MPS2))


RECORDS: dict[Fn, type[Record]] = {cls.FN: cls for cls in Record.__subclasses__()}


def decode(msg: can.Message, *, node_id: int, direction: str) -> Record:
    """Decode one received frame.

    Parameters
    ----------
    msg : can.Message
    node_id : int
        The device node this receiver talks to (frames of other nodes are ``foreign node``).
    direction : {"to_device", "to_host"}
        Which frames this receiver accepts: the device decodes host -> device frames, the host
        decodes device -> host frames.

    Raises
    ------
    ProtocolError
        With ``reason`` one of: not a data frame, unknown id, foreign node, wrong direction,
        wrong length, out of range.
    """
    if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id or msg.is_fd:
        raise _err("not a data frame", f"id {msg.arbitration_id:#x} (error, remote, extended or FD frame)")
    if not 0 <= msg.arbitration_id <= 0x7FF:
        raise _err("unknown id", f"id {msg.arbitration_id:#x} is not an 11-bit identifier")
    fn, node = split_id(msg.arbitration_id)
    if fn not in Fn._value2member_map_:
        raise _err("unknown id", f"id {msg.arbitration_id:#x}: no function {fn}")
    fn = Fn(fn)
    if node != node_id and not (fn == Fn.ESTOP and node == BROADCAST_NODE):
        raise _err("foreign node", f"id {msg.arbitration_id:#x} addresses node {node}, not {node_id}")
    allowed = HOST_TO_DEVICE if direction == "to_device" else DEVICE_TO_HOST
    if fn not in allowed:
        raise _err("wrong direction", f"{fn.name} frames are not sent {direction.replace('_', ' ')}")
    cls = RECORDS[fn]
    data = bytes(msg.data)
    if fn == Fn.ESTOP:
        return cls._parse(data)
    if len(data) != cls.LENGTH:
        raise _err("wrong length", f"{fn.name} needs {cls.LENGTH} data bytes, got {len(data)}")
    return cls._parse(data)


@dataclass
class FrameCounters:
    """Counts of received frames: accepted, and rejected by reason; decoding never raises."""

    node_id: int
    direction: str
    accepted: int = 0
    rejected: Counter = field(default_factory=Counter)
    foreign: int = 0

    @property
    def rejected_total(self) -> int:
        return sum(self.rejected.values())

    def decode(self, msg: can.Message) -> Record | None:
        """The record, or None for a foreign-node frame or a rejected one (counted by reason)."""
        try:
            rec = decode(msg, node_id=self.node_id, direction=self.direction)
        except ProtocolError as exc:
            reason = getattr(exc, "reason", "invalid")
            # Other nodes' frames, and on the host side other hosts' commands, are normal traffic
            # on a shared bus, not errors.
            if reason == "foreign node" or (reason == "wrong direction" and self.direction == "to_host"):
                self.foreign += 1
            else:
                self.rejected[reason] += 1
            return None
        self.accepted += 1
        return rec


def encode_summary(header: SummaryHeader, phasors: np.ndarray, node: int) -> list[can.Message]:
    """A whole harmonic summary: the header and one SUMMARY_DATA frame per (channel, harmonic).

    Vectorised equivalent of ``[header] + [SummaryData(seq, c, k, phasors[k-1, c]) ...]`` (channel
    by channel, harmonics ascending), for the device's per-cycle output.

    Parameters
    ----------
    phasors : complex array, shape (H, C) with H == header.harmonics (m/s^2)
    """
    X = np.asarray(phasors, dtype=complex)
    H, C = X.shape
    if header.harmonics != H or not 1 <= C <= MAX_CHANNELS or not np.all(np.isfinite(X)):
        raise _err(
            "out of range",
            f"phasors: expected a finite ({header.harmonics}, <= {MAX_CHANNELS}) table, got {X.shape}",
        )
    parts = np.rint(np.stack([X.real, X.imag], axis=-1).transpose(1, 0, 2) / SUMMARY_LSB_MPS2)  # (C, H, 2)
    if np.any(np.abs(parts) > INT24_MAX):
        raise _err("out of range", f"phasors: a value exceeds +-{INT24_MAX * SUMMARY_LSB_MPS2:g} m/s^2")
    v = parts.astype(np.int64).reshape(-1, 2) & 0xFFFFFF
    data = np.empty((C * H, 8), dtype=np.uint8)
    data[:, 0] = header.seq
    data[:, 1] = (np.repeat(np.arange(C), H) << 4) | np.tile(np.arange(1, H + 1), C)
    for j in range(3):
        data[:, 2 + j] = (v[:, 0] >> (8 * j)) & 0xFF
        data[:, 5 + j] = (v[:, 1] >> (8 * j)) & 0xFF
    arb = can_id(Fn.SUMMARY_DATA, node)
    return [header.encode(node)] + [
        can.Message(arbitration_id=arb, data=row.tobytes(), is_extended_id=False) for row in data
    ]


def table_checksum(entries: list[TableEntry]) -> int:
    """CRC-16/CCITT (init 0xFFFF) over the entries' bytes 1..7, sorted by (k, actuator)."""
    data = b"".join(e.checksum_bytes() for e in sorted(entries, key=lambda e: (e.k, e.actuator)))
    return binascii.crc_hqx(data, 0xFFFF)


def encode_table(
    seq: int, frequency_hz: float, ramp_s: float, currents: np.ndarray, node: int
) -> list[can.Message]:
    """Frames that load and commit a current table: header, non-zero entries, commit.

    Parameters
    ----------
    currents : complex array, shape (K, 6)
        Row k-1 is harmonic k (A); entries that quantise to zero are not sent (the device fills
        zeros), so an all-zero table is a header and a commit.
    """
    currents = np.asarray(currents, dtype=complex)
    if currents.ndim != 2 or currents.shape[1] != NUM_ACTUATORS or currents.shape[0] > MAX_TABLE_HARMONIC:
        raise _err(
            "out of range", f"currents: expected shape (K <= {MAX_TABLE_HARMONIC}, 6), got {currents.shape}"
        )
    entries = []
    for k in range(1, currents.shape[0] + 1):
        for a in range(NUM_ACTUATORS):
            c = currents[k - 1, a]
            if round(c.real / CURRENT_LSB_A) or round(c.imag / CURRENT_LSB_A):
                entries.append(TableEntry(seq, a, k, c))
    header = TableHeader(seq, len(entries), frequency_hz, ramp_s)
    commit = TableCommit(seq, len(entries), table_checksum(entries))
    return [header.encode(node)] + [e.encode(node) for e in entries] + [commit.encode(node)]


__all__ = [
    "Control",
    "CoilRms",
    "CoilTemps",
    "Estop",
    "FaultEvent",
    "FrameCounters",
    "Heartbeat",
    "RECORDS",
    "RawData",
    "RawHeader",
    "RawRequest",
    "Record",
    "Status",
    "StatusExt",
    "SummaryData",
    "SummaryHeader",
    "TableAck",
    "TableCommit",
    "TableEntry",
    "TableHeader",
    "Version",
    "VersionRequest",
    "decode",
    "encode_summary",
    "encode_table",
    "table_checksum",
]

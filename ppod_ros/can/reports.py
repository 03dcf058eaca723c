"""Device -> host frames of the PPOD CAN protocol (docs/can_protocol.md): status and data."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from typing import ClassVar

from ppod_ros.can.packing import Field, Record, check_int, complex24, device_state, err, from_complex24, scaled, u24
from ppod_ros.can.protocol import (
    COIL_RMS_LSB_A,
    CYCLE_MODULUS,
    HEARTBEAT_AGE_LSB_S,
    LIMIT_LSB,
    MAX_CHANNELS,
    MAX_RAW_CYCLES,
    MAX_RAW_SAMPLES,
    MAX_SUMMARY_CYCLES,
    MAX_TABLE_HARMONIC,
    NUM_ACTUATORS,
    RAW_LSB_MPS2,
    SUMMARY_LSB_MPS2,
    TIME_LSB_S,
    AckResult,
    DeviceState,
    Fn,
)


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
            check_int(self.faults, 0, 0xFFFF, "faults"),
            int(self.state),
            scaled(self.device_time_s, TIME_LSB_S, 0, 0xFFFFFFFF, "device_time_s"),
        )

    @classmethod
    def _parse(cls, d: bytes) -> FaultEvent:
        faults, state, t = struct.unpack("<HBI", d)
        return cls(faults, device_state(state), t * TIME_LSB_S)


@dataclass(frozen=True)
class TableAck(Record):
    FN: ClassVar[Fn] = Fn.TABLE_ACK
    LENGTH: ClassVar[int] = 5
    seq: int
    result: AckResult
    cycle_index: int = 0

    def _payload(self) -> bytes:
        return bytes([check_int(self.seq, 0, 255, "seq"), int(self.result)]) + u24(
            self.cycle_index % CYCLE_MODULUS
        )

    @classmethod
    def _parse(cls, d: bytes) -> TableAck:
        if d[1] not in AckResult._value2member_map_:
            raise err("out of range", f"table ack result {d[1]}")
        return cls(d[0], AckResult(d[1]), int.from_bytes(d[2:5], "little"))


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
            check_int(self.faults, 0, 0xFFFF, "faults"),
            check_int(self.active_seq, 0, 255, "active_seq"),
            scaled(self.device_time_s, TIME_LSB_S, 0, 0xFFFFFFFF, "device_time_s"),
        )

    @classmethod
    def _parse(cls, d: bytes) -> Status:
        state, faults, seq, t = struct.unpack("<BHBI", d)
        return cls(device_state(state), faults, seq, t * TIME_LSB_S)


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
            255
            if not math.isfinite(age)
            else min(255, check_int(age / HEARTBEAT_AGE_LSB_S, 0, 1 << 30, "age"))
        )
        return struct.pack(
            "<IBBH",
            self.cycle_count & 0xFFFFFFFF,
            check_int(self.amplitude_scale * 255, 0, 255, "amplitude_scale"),
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
        return bytes(check_int(min(255.0, max(0.0, t)), 0, 255, "temperature_c") for t in self.temperature_c)

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
            min(255, check_int(i / COIL_RMS_LSB_A, 0, 1 << 30, "current_rms_a")) for i in self.current_rms_a
        )

    @classmethod
    def _parse(cls, d: bytes) -> CoilRms:
        return cls(tuple(b * COIL_RMS_LSB_A for b in d))


@dataclass(frozen=True)
class DeviceLimit(Record):
    """One of the device's own limits (``item``: a LimitItem number, ``count`` items in all), sent
    after VERSION: the host refuses a device description whose limits exceed these."""

    FN: ClassVar[Fn] = Fn.DEVICE_LIMIT
    LENGTH: ClassVar[int] = 6
    FIELDS: ClassVar[tuple[Field, ...]] = (
        Field("item", 0, 1),
        Field("count", 1, 1),
        Field("value", 2, 4, scale=LIMIT_LSB, unit="SI unit of the item"),
    )
    item: int
    count: int
    value: float

    def _payload(self) -> bytes:
        return struct.pack(
            "<BBI",
            check_int(self.item, 0, 255, "item"),
            check_int(self.count, 1, 255, "count"),
            scaled(self.value, LIMIT_LSB, 0, 0xFFFFFFFF, "value"),
        )

    @classmethod
    def _parse(cls, d: bytes) -> DeviceLimit:
        item, count, value = struct.unpack("<BBI", d)
        if count == 0 or item >= count:
            raise err("out of range", f"device limit item {item} of {count}")
        return cls(item, count, value * LIMIT_LSB)


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
                check_int(self.major, 0, 255, "major"),
                check_int(self.minor, 0, 255, "minor"),
                check_int(self.n_actuators, 1, NUM_ACTUATORS, "n_actuators"),
                check_int(self.n_channels, 1, MAX_CHANNELS, "n_channels"),
                check_int(self.max_harmonic, 1, MAX_TABLE_HARMONIC, "max_harmonic"),
                check_int(self.node_id, 1, 15, "node_id"),
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
            raise err("out of range", f"version fields {list(d)}")
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
        packed = (check_int(self.n_cycles, 1, MAX_SUMMARY_CYCLES, "n_cycles") - 1) << 4 | check_int(
            self.harmonics, 1, MAX_TABLE_HARMONIC, "harmonics"
        )
        return (
            bytes([check_int(self.seq, 0, 255, "seq"), packed])
            + u24(self.cycle_index % CYCLE_MODULUS)
            + struct.pack(
                "<HB",
                check_int(self.samples_per_cycle, 8, 0xFFFF, "samples_per_cycle"),
                check_int(self.table_seq, 0, 255, "table_seq"),
            )
        )

    @classmethod
    def _parse(cls, d: bytes) -> SummaryHeader:
        spc, tseq = struct.unpack("<HB", d[5:8])
        n, h = (d[1] >> 4) + 1, d[1] & 0xF
        if not 1 <= h <= MAX_TABLE_HARMONIC or spc < 8 or h >= spc // 2:
            raise err("out of range", f"summary header harmonics {h}, samples_per_cycle {spc}")
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
        ch = check_int(self.channel, 0, MAX_CHANNELS - 1, "channel")
        k = check_int(self.k, 1, MAX_TABLE_HARMONIC, "k")
        return bytes([check_int(self.seq, 0, 255, "seq"), ch << 4 | k]) + complex24(
            complex(self.value_mps2), SUMMARY_LSB_MPS2, "value_mps2"
        )

    @classmethod
    def _parse(cls, d: bytes) -> SummaryData:
        ch, k = d[1] >> 4, d[1] & 0xF
        if not 1 <= k <= MAX_TABLE_HARMONIC:
            raise err("out of range", f"summary harmonic {k}")
        return cls(d[0], ch, k, from_complex24(d[2:8], SUMMARY_LSB_MPS2))


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
        head = check_int(self.capture_id, 0, 15, "capture_id") << 4 | (
            check_int(self.n_cycles, 1, MAX_RAW_CYCLES, "n_cycles") - 1
        )
        return (
            struct.pack("<BH", head, check_int(self.channel_mask, 1, 0xFFFF, "channel_mask"))
            + u24(self.start_cycle % CYCLE_MODULUS)
            + struct.pack("<H", check_int(self.samples_per_cycle, 8, 0xFFFF, "samples_per_cycle"))
        )

    @classmethod
    def _parse(cls, d: bytes) -> RawHeader:
        head, mask = struct.unpack("<BH", d[0:3])
        (spc,) = struct.unpack("<H", d[6:8])
        n = (head & 0xF) + 1
        if mask == 0 or spc < 8 or n * spc > MAX_RAW_SAMPLES:
            raise err("out of range", f"raw header mask {mask:#x}, samples_per_cycle {spc}, cycles {n}")
        return cls(head >> 4, n, mask, int.from_bytes(d[3:6], "little"), spc)


@dataclass(frozen=True)
class RawData(Record):
    FN: ClassVar[Fn] = Fn.RAW_DATA
    LENGTH: ClassVar[int] = 8
    channel: int
    index: int
    samples_mps2: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0))

    def _payload(self) -> bytes:
        ch = check_int(self.channel, 0, MAX_CHANNELS - 1, "channel")
        idx = check_int(self.index, 0, MAX_RAW_SAMPLES - 1, "index")
        vals = [scaled(v, RAW_LSB_MPS2, -32768, 32767, "samples_mps2") for v in self.samples_mps2]
        return struct.pack("<H3h", ch << 12 | idx, *vals)

    @classmethod
    def _parse(cls, d: bytes) -> RawData:
        head, a, b, c = struct.unpack("<H3h", d)
        return cls(head >> 12, head & 0xFFF, (a * RAW_LSB_MPS2, b * RAW_LSB_MPS2, c * RAW_LSB_MPS2))


__all__ = [
    "DeviceLimit",
    "CoilRms",
    "CoilTemps",
    "FaultEvent",
    "RawData",
    "RawHeader",
    "Status",
    "StatusExt",
    "SummaryData",
    "SummaryHeader",
    "TableAck",
    "Version",
]

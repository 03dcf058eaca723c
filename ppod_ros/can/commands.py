"""Host -> device frames of the PPOD CAN protocol (docs/can_protocol.md): commands and tables."""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import ClassVar

from ppod_ros.can.packing import Field, Record, check_int, complex24, err, from_complex24, scaled
from ppod_ros.can.protocol import (
    CURRENT_LSB_A,
    FREQUENCY_LSB_HZ,
    MAX_RAW_CYCLES,
    MAX_TABLE_HARMONIC,
    NUM_ACTUATORS,
    RAMP_LSB_S,
    Command,
    Fn,
)


@dataclass(frozen=True)
class Estop(Record):
    FN: ClassVar[Fn] = Fn.ESTOP
    LENGTH: ClassVar[int] = 1
    reason: int = 0

    def _payload(self) -> bytes:
        return bytes([check_int(self.reason, 0, 255, "reason")])

    @classmethod
    def _parse(cls, d: bytes) -> Estop:
        # Any payload stops the device: the identifier alone is the command (fail safe).
        return cls(d[0] if d else 0)


@dataclass(frozen=True)
class Control(Record):
    """A device command; its u16 argument is the ramp (DISABLE) or the harmonic count (SUMMARY_HARMONICS)."""

    FN: ClassVar[Fn] = Fn.CONTROL
    LENGTH: ClassVar[int] = 3
    command: Command
    ramp_s: float = 0.0
    harmonics: int = 0

    def _payload(self) -> bytes:
        if self.command == Command.SUMMARY_HARMONICS:
            arg = check_int(self.harmonics, 1, MAX_TABLE_HARMONIC, "harmonics")
        else:
            arg = scaled(self.ramp_s, RAMP_LSB_S, 0, 0xFFFF, "ramp_s")
        return struct.pack("<BH", check_int(int(self.command), 1, 255, "command"), arg)

    @classmethod
    def _parse(cls, d: bytes) -> Control:
        cmd, arg = struct.unpack("<BH", d)
        if cmd not in Command._value2member_map_:
            raise err("out of range", f"control command {cmd} is unknown")
        if cmd == Command.SUMMARY_HARMONICS:
            if not 1 <= arg <= MAX_TABLE_HARMONIC:
                raise err("out of range", f"summary harmonics {arg} outside 1..{MAX_TABLE_HARMONIC}")
            return cls(Command(cmd), harmonics=arg)
        return cls(Command(cmd), arg * RAMP_LSB_S)


@dataclass(frozen=True)
class Heartbeat(Record):
    FN: ClassVar[Fn] = Fn.HEARTBEAT
    LENGTH: ClassVar[int] = 2
    counter: int
    host_node: int = 0

    def _payload(self) -> bytes:
        return bytes([self.counter & 0xFF, check_int(self.host_node, 0, 15, "host_node")])

    @classmethod
    def _parse(cls, d: bytes) -> Heartbeat:
        if d[1] > 15:
            raise err("out of range", f"heartbeat host node {d[1]} > 15")
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
            check_int(self.seq, 0, 255, "seq"),
            check_int(self.n_entries, 0, NUM_ACTUATORS * MAX_TABLE_HARMONIC, "n_entries"),
            scaled(self.frequency_hz, FREQUENCY_LSB_HZ, 1, 0xFFFFFFFF, "frequency_hz"),
            scaled(self.ramp_s, RAMP_LSB_S, 0, 0xFFFF, "ramp_s"),
        )

    @classmethod
    def _parse(cls, d: bytes) -> TableHeader:
        seq, n, f, ramp = struct.unpack("<BBIH", d)
        if n > NUM_ACTUATORS * MAX_TABLE_HARMONIC or f == 0:
            raise err("out of range", f"table header n_entries {n} or frequency {f} uHz")
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
        a = check_int(self.actuator, 0, NUM_ACTUATORS - 1, "actuator")
        k = check_int(self.k, 1, MAX_TABLE_HARMONIC, "k")
        return bytes([check_int(self.seq, 0, 255, "seq"), a << 4 | k]) + complex24(
            complex(self.current_a), CURRENT_LSB_A, "current_a"
        )

    @classmethod
    def _parse(cls, d: bytes) -> TableEntry:
        a, k = d[1] >> 4, d[1] & 0xF
        if a >= NUM_ACTUATORS or not 1 <= k <= MAX_TABLE_HARMONIC:
            raise err("out of range", f"table entry actuator {a} / harmonic {k}")
        return cls(d[0], a, k, from_complex24(d[2:8], CURRENT_LSB_A))

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
            check_int(self.seq, 0, 255, "seq"),
            check_int(self.n_entries, 0, NUM_ACTUATORS * MAX_TABLE_HARMONIC, "n_entries"),
            check_int(self.checksum, 0, 0xFFFF, "checksum"),
        )

    @classmethod
    def _parse(cls, d: bytes) -> TableCommit:
        seq, n, crc = struct.unpack("<BBH", d)
        if n > NUM_ACTUATORS * MAX_TABLE_HARMONIC:
            raise err("out of range", f"table commit n_entries {n}")
        return cls(seq, n, crc)


@dataclass(frozen=True)
class TableCrc(Record):
    """CRC-16/CCITT (init 0xFFFF) over a table's TABLE_HEADER payload (8 bytes) followed by every
    entry's bytes 1..7 sorted by (k, actuator): protects the header as well as the entries.
    Sent after the last entry and before the commit; a 2.0 device commits no table without it."""

    FN: ClassVar[Fn] = Fn.TABLE_CRC
    LENGTH: ClassVar[int] = 4
    FIELDS: ClassVar[tuple[Field, ...]] = (
        Field("seq", 0, 1),
        Field("n_entries", 1, 1),
        Field("crc", 2, 2),
    )
    seq: int
    n_entries: int
    crc: int

    def _payload(self) -> bytes:
        return struct.pack(
            "<BBH",
            check_int(self.seq, 0, 255, "seq"),
            check_int(self.n_entries, 0, NUM_ACTUATORS * MAX_TABLE_HARMONIC, "n_entries"),
            check_int(self.crc, 0, 0xFFFF, "crc"),
        )

    @classmethod
    def _parse(cls, d: bytes) -> TableCrc:
        seq, n, crc = struct.unpack("<BBH", d)
        if n > NUM_ACTUATORS * MAX_TABLE_HARMONIC:
            raise err("out of range", f"table crc n_entries {n}")
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
                check_int(self.major, 0, 255, "major"),
                check_int(self.minor, 0, 255, "minor"),
                check_int(self.host_node, 0, 15, "host_node"),
            ]
        )

    @classmethod
    def _parse(cls, d: bytes) -> VersionRequest:
        if d[2] > 15:
            raise err("out of range", f"version request host node {d[2]}")
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
            check_int(self.capture_id, 0, 15, "capture_id"),
            check_int(self.channel_mask, 1, 0xFFFF, "channel_mask"),
            check_int(self.n_cycles, 1, MAX_RAW_CYCLES, "n_cycles"),
        )

    @classmethod
    def _parse(cls, d: bytes) -> RawRequest:
        cid, mask, n = struct.unpack("<BHB", d)
        if cid > 15 or mask == 0 or not 1 <= n <= MAX_RAW_CYCLES:
            raise err("out of range", f"raw request id {cid}, mask {mask:#x}, cycles {n}")
        return cls(cid, mask, n)


__all__ = [
    "Control",
    "Estop",
    "Heartbeat",
    "RawRequest",
    "TableCommit",
    "TableCrc",
    "TableEntry",
    "TableHeader",
    "VersionRequest",
]

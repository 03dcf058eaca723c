"""Encoding and decoding of every PPOD CAN frame (docs/can_protocol.md), with error counting.

Each frame type is a frozen record with ``encode(node) -> can.Message`` (host -> device frames in
:mod:`ppod_ros.can.commands`, device -> host frames in :mod:`ppod_ros.can.reports`, all re-exported
here); :func:`decode` turns a received ``can.Message`` back into its record or raises
:class:`~ppod_ros.errors.ProtocolError` whose ``reason`` says why (``unknown id``, ``wrong
direction``, ``wrong length``, ``out of range``, ``not a data frame``). :class:`FrameCounters`
wraps it so that a receiver never crashes on a bad frame: it counts and drops it. Values that do
not fit their field are rejected when encoding too: nothing is silently clipped.
"""

from __future__ import annotations

import binascii
from collections import Counter
from dataclasses import dataclass, field

import can
import numpy as np

from ppod_ros.can.commands import (
    Control,
    Estop,
    Heartbeat,
    RawRequest,
    TableCommit,
    TableCrc,
    TableEntry,
    TableHeader,
    VersionRequest,
)
from ppod_ros.can.packing import Record, err
from ppod_ros.can.protocol import (
    BROADCAST_NODE,
    CURRENT_LSB_A,
    DEVICE_TO_HOST,
    HOST_TO_DEVICE,
    INT24_MAX,
    MAX_CHANNELS,
    MAX_TABLE_HARMONIC,
    NUM_ACTUATORS,
    SUMMARY_LSB_MPS2,
    Fn,
    can_id,
    split_id,
)
from ppod_ros.can.reports import (
    CoilRms,
    CoilTemps,
    DeviceLimit,
    FaultEvent,
    RawData,
    RawHeader,
    Status,
    StatusExt,
    SummaryData,
    SummaryHeader,
    TableAck,
    Version,
)
from ppod_ros.errors import ProtocolError

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
        raise err("not a data frame", f"id {msg.arbitration_id:#x} (error, remote, extended or FD frame)")
    if not 0 <= msg.arbitration_id <= 0x7FF:
        raise err("unknown id", f"id {msg.arbitration_id:#x} is not an 11-bit identifier")
    fn, node = split_id(msg.arbitration_id)
    if fn not in Fn._value2member_map_:
        raise err("unknown id", f"id {msg.arbitration_id:#x}: no function {fn}")
    fn = Fn(fn)
    if node != node_id and not (fn == Fn.ESTOP and node == BROADCAST_NODE):
        raise err("foreign node", f"id {msg.arbitration_id:#x} addresses node {node}, not {node_id}")
    allowed = HOST_TO_DEVICE if direction == "to_device" else DEVICE_TO_HOST
    if fn not in allowed:
        raise err("wrong direction", f"{fn.name} frames are not sent {direction.replace('_', ' ')}")
    cls = RECORDS[fn]
    data = bytes(msg.data)
    if fn == Fn.ESTOP:
        return cls._parse(data)
    if len(data) != cls.LENGTH:
        raise err("wrong length", f"{fn.name} needs {cls.LENGTH} data bytes, got {len(data)}")
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
        raise err(
            "out of range",
            f"phasors: expected a finite ({header.harmonics}, <= {MAX_CHANNELS}) table, got {X.shape}",
        )
    parts = np.rint(np.stack([X.real, X.imag], axis=-1).transpose(1, 0, 2) / SUMMARY_LSB_MPS2)  # (C, H, 2)
    if np.any(np.abs(parts) > INT24_MAX):
        raise err("out of range", f"phasors: a value exceeds +-{INT24_MAX * SUMMARY_LSB_MPS2:g} m/s^2")
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


def table_crc(header: TableHeader, entries: list[TableEntry]) -> int:
    """TABLE_CRC's CRC-16/CCITT (init 0xFFFF): the header's 8 payload bytes, then the entries' bytes
    1..7 sorted by (k, actuator). Covers frequency, ramp, entry count and sequence number."""
    data = header._payload() + b"".join(
        e.checksum_bytes() for e in sorted(entries, key=lambda e: (e.k, e.actuator))
    )
    return binascii.crc_hqx(data, 0xFFFF)


def encode_table(
    seq: int, frequency_hz: float, ramp_s: float, currents: np.ndarray, node: int
) -> list[can.Message]:
    """Frames that load and commit a current table: header, non-zero entries, TABLE_CRC, commit.

    Parameters
    ----------
    currents : complex array, shape (K, 6)
        Row k-1 is harmonic k (A); entries that quantise to zero are not sent (the device fills
        zeros), so an all-zero table is a header and a commit.
    """
    currents = np.asarray(currents, dtype=complex)
    if currents.ndim != 2 or currents.shape[1] != NUM_ACTUATORS or currents.shape[0] > MAX_TABLE_HARMONIC:
        raise err(
            "out of range", f"currents: expected shape (K <= {MAX_TABLE_HARMONIC}, 6), got {currents.shape}"
        )
    entries = []
    for k in range(1, currents.shape[0] + 1):
        for a in range(NUM_ACTUATORS):
            c = currents[k - 1, a]
            if round(c.real / CURRENT_LSB_A) or round(c.imag / CURRENT_LSB_A):
                entries.append(TableEntry(seq, a, k, c))
    header = TableHeader(seq, len(entries), frequency_hz, ramp_s)
    crc = TableCrc(seq, len(entries), table_crc(header, entries))
    commit = TableCommit(seq, len(entries), table_checksum(entries))
    return [header.encode(node)] + [e.encode(node) for e in entries] + [crc.encode(node), commit.encode(node)]


__all__ = [
    "Control",
    "CoilRms",
    "CoilTemps",
    "DeviceLimit",
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
    "TableCrc",
    "TableEntry",
    "TableHeader",
    "Version",
    "VersionRequest",
    "decode",
    "encode_summary",
    "encode_table",
    "table_checksum",
    "table_crc",
]

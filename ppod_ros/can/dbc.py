"""The PPOD CAN protocol as a DBC file, generated from the codec (cantools, SavvyCAN, candump -> DBC).

One source of truth: the messages are the codec's registry (:data:`ppod_ros.can.codec.RECORDS`, one
per frame kind, with its function code, direction and length), scalings and enumerations come from
:mod:`ppod_ros.can.protocol`; this module adds only where each field sits in the payload (the
layout tables of docs/can_protocol.md). Regenerate after any protocol change::

    python -m ppod_ros.can.dbc > docs/ppod.dbc            # node 1 (the default device)
    python -m ppod_ros.can.dbc --node 3 > ppod_node3.dbc

A frame kind that the codec knows but :data:`LAYOUTS` does not is still written, as one raw
payload signal with a comment saying so (and ``tests/can/test_dbc.py`` fails until its layout is
added), so a new frame never silently disappears from the DBC.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from enum import IntEnum

from ppod_ros.can.protocol import (
    COIL_RMS_LSB_A,
    CURRENT_LSB_A,
    DEVICE_TO_HOST,
    FREQUENCY_LSB_HZ,
    HEARTBEAT_AGE_LSB_S,
    LIMIT_LSB,
    PROTOCOL_VERSION,
    RAMP_LSB_S,
    RAW_LSB_MPS2,
    SUMMARY_LSB_MPS2,
    TIME_LSB_S,
    AckResult,
    Command,
    DeviceState,
    Fn,
    LimitItem,
    can_id,
)

HOST = "PPOD_HOST"
DEVICE = "PPOD_DEVICE"


@dataclass(frozen=True)
class Signal:
    """One field of a payload: little-endian (Intel) bits ``start .. start + length - 1``.

    ``field`` names the codec record's attribute it decodes to (``current_a.real``: a part of a
    complex; ``temperature_c[2]``: an item of a tuple), None where the record has no such attribute.
    Physical value = raw * scale + offset, as in the DBC.
    """

    name: str
    start: int
    length: int
    signed: bool = False
    scale: float = 1.0
    offset: float = 0.0
    unit: str = ""
    field: str | None = None
    choices: type[IntEnum] | None = None
    comment: str = ""

    def range(self) -> tuple[float, float]:
        half = 1 << (self.length - 1)
        lo, hi = (-half, half - 1) if self.signed else (0, 2 * half - 1)
        return lo * self.scale + self.offset, hi * self.scale + self.offset


def _u8(name: str, byte: int, **kw) -> Signal:
    return Signal(name, 8 * byte, 8, field=kw.pop("field", name), **kw)


def _coils(prefix: str, scale: float, unit: str, field: str) -> tuple[Signal, ...]:
    return tuple(Signal(f"{prefix}_{j}", 8 * j, 8, scale=scale, unit=unit, field=f"{field}[{j}]") for j in range(6))


def _phasor(name: str, lsb: float, unit: str, field: str) -> tuple[Signal, Signal]:
    return (Signal(f"{name}_re", 16, 24, True, lsb, unit=unit, field=f"{field}.real"),
            Signal(f"{name}_im", 40, 24, True, lsb, unit=unit, field=f"{field}.imag"))


#: Where each field sits (docs/can_protocol.md, "Payloads"); the frame kinds come from the codec.
LAYOUTS: dict[Fn, tuple[Signal, ...]] = {
    Fn.ESTOP: (_u8("reason", 0, comment="any payload, even none, stops the device"),),
    Fn.FAULT: (Signal("faults", 0, 16, field="faults"), Signal("state", 16, 8, field="state", choices=DeviceState),
               Signal("device_time", 24, 32, scale=TIME_LSB_S, unit="s", field="device_time_s")),
    Fn.CONTROL: (Signal("command", 0, 8, field="command", choices=Command),
                 Signal("argument", 8, 16, field=None,
                        comment="DISABLE: ramp (ms); SUMMARY_HARMONICS: harmonics n (1..10); else 0")),
    Fn.HEARTBEAT: (_u8("counter", 0), _u8("host_node", 1)),
    Fn.TABLE_ACK: (_u8("seq", 0), Signal("result", 8, 8, field="result", choices=AckResult),
                   Signal("cycle_index", 16, 24, field="cycle_index")),
    Fn.TABLE_HEADER: (_u8("seq", 0), _u8("n_entries", 1),
                      Signal("frequency", 16, 32, scale=FREQUENCY_LSB_HZ, unit="Hz", field="frequency_hz"),
                      Signal("ramp", 48, 16, scale=RAMP_LSB_S, unit="s", field="ramp_s")),
    Fn.TABLE_ENTRY: (_u8("seq", 0), Signal("k", 8, 4, field="k"), Signal("actuator", 12, 4, field="actuator"),
                     *_phasor("current", CURRENT_LSB_A, "A", "current_a")),
    Fn.TABLE_COMMIT: (_u8("seq", 0), _u8("n_entries", 1), Signal("checksum", 16, 16, field="checksum")),
    Fn.STATUS: (Signal("state", 0, 8, field="state", choices=DeviceState), Signal("faults", 8, 16, field="faults"),
                _u8("active_seq", 3),
                Signal("device_time", 32, 32, scale=TIME_LSB_S, unit="s", field="device_time_s")),
    Fn.STATUS_EXT: (Signal("cycle_count", 0, 32, field="cycle_count"),
                    Signal("ramp_progress", 32, 8, scale=1 / 255, field="amplitude_scale"),
                    Signal("heartbeat_age", 40, 8, scale=HEARTBEAT_AGE_LSB_S, unit="s", field=None,
                           comment="255: 510 ms or more, or never"),
                    Signal("frames_rejected", 48, 16, field="rx_rejected")),
    Fn.COIL_TEMP: _coils("temperature", 1.0, "degC", "temperature_c"),
    Fn.COIL_RMS: _coils("current_rms", COIL_RMS_LSB_A, "A", "current_rms_a"),
    Fn.VERSION_REQUEST: (_u8("major", 0), _u8("minor", 1), _u8("host_node", 2)),
    Fn.VERSION: (_u8("major", 0), _u8("minor", 1), _u8("actuators", 2, field="n_actuators"),
                 _u8("channels", 3, field="n_channels"), _u8("max_harmonic", 4), _u8("node", 5, field="node_id"),
                 _u8("simulated", 6)),
    Fn.SUMMARY_HEADER: (_u8("seq", 0), Signal("harmonics", 8, 4, field="harmonics"),
                        Signal("cycles", 12, 4, offset=1, field="n_cycles"),
                        Signal("cycle_index", 16, 24, field="cycle_index"),
                        Signal("samples_per_cycle", 40, 16, field="samples_per_cycle"), _u8("table_seq", 7)),
    Fn.SUMMARY_DATA: (_u8("seq", 0), Signal("k", 8, 4, field="k"), Signal("channel", 12, 4, field="channel"),
                      *_phasor("value", SUMMARY_LSB_MPS2, "m/s^2", "value_mps2")),
    Fn.RAW_REQUEST: (_u8("capture_id", 0), Signal("channel_mask", 8, 16, field="channel_mask"),
                     _u8("cycles", 3, field="n_cycles")),
    Fn.RAW_HEADER: (Signal("cycles", 0, 4, offset=1, field="n_cycles"), Signal("capture_id", 4, 4, field="capture_id"),
                    Signal("channel_mask", 8, 16, field="channel_mask"),
                    Signal("start_cycle", 24, 24, field="start_cycle"),
                    Signal("samples_per_cycle", 48, 16, field="samples_per_cycle")),
    Fn.RAW_DATA: (Signal("index", 0, 12, field="index"), Signal("channel", 12, 4, field="channel"),
                  *(Signal(f"sample_{i}", 16 + 16 * i, 16, True, RAW_LSB_MPS2, unit="m/s^2",
                           field=f"samples_mps2[{i}]") for i in range(3))),
    Fn.TABLE_CRC: (_u8("seq", 0), _u8("n_entries", 1),
                   Signal("crc", 16, 16, field="crc",
                          comment="CRC-16/CCITT (init 0xFFFF) over the header payload and the entries' bytes 1..7")),
    Fn.DEVICE_LIMIT: (Signal("item", 0, 8, field="item", choices=LimitItem,
                             comment="8 + 2 i / 9 + 2 i: lower / upper edge of excluded band i"),
                      _u8("count", 1),
                      Signal("value", 16, 32, scale=LIMIT_LSB, unit="SI", field="value")),
}


def _records():
    from ppod_ros.can.codec import RECORDS  # the codec's registry: every frame kind it encodes

    return RECORDS


def _number(x: float) -> str:
    return repr(float(x)) if x != int(x) or abs(x) >= 1e15 else str(int(x))


def _signal_line(sig: Signal, receiver: str) -> str:
    lo, hi = sig.range()
    sign = "-" if sig.signed else "+"
    return (f' SG_ {sig.name} : {sig.start}|{sig.length}@1{sign} ({_number(sig.scale)},{_number(sig.offset)}) '
            f'[{lo:.10g}|{hi:.10g}] "{sig.unit}" {receiver}')


def generate_dbc(node: int = 1) -> str:
    """The DBC text for a device at ``node`` (identifiers ``fn << 4 | node``)."""
    records = _records()
    major, minor = PROTOCOL_VERSION
    lines = [f'VERSION "PPOD CAN protocol {major}.{minor} (generated by ppod_ros.can.dbc; do not edit)"',
             "", "NS_ :", "", "BS_:", "", f"BU_: {HOST} {DEVICE}", ""]
    comments: list[str] = []
    values: list[str] = []
    for fn in sorted(records, key=int):
        cls = records[fn]
        frame_id = can_id(fn, node)
        to_host = fn in DEVICE_TO_HOST
        sender, receiver = (DEVICE, HOST) if to_host else (HOST, DEVICE)
        lines.append(f"BO_ {frame_id} PPOD_{fn.name}: {cls.LENGTH} {sender}")  # VERSION is a DBC keyword
        layout = LAYOUTS.get(fn)
        if layout is None:
            layout = (Signal("payload", 0, 8 * cls.LENGTH),)
            comments.append(f'CM_ BO_ {frame_id} "{cls.__name__}: layout not in ppod_ros.can.dbc.LAYOUTS";')
        else:
            doc = (cls.__doc__ or "").strip().splitlines()[0] if cls.__doc__ and not cls.__doc__.startswith(
                f"{cls.__name__}(") else ""
            direction = "device -> host" if to_host else "host -> device"
            text = f"{cls.__name__}, {direction}" + (f": {doc}" if doc else "")
            comments.append(f'CM_ BO_ {frame_id} "{text.replace(chr(34), chr(39))}";')
        for sig in layout:
            lines.append(_signal_line(sig, receiver))
            if sig.comment:
                comments.append(f'CM_ SG_ {frame_id} {sig.name} "{sig.comment}";')
            if sig.choices is not None:
                pairs = " ".join(f'{int(m)} "{m.name}"' for m in sig.choices)
                values.append(f"VAL_ {frame_id} {sig.name} {pairs} ;")
        lines.append("")
    return "\n".join(lines + comments + [""] + values) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ppod_ros.can.dbc", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--node", type=int, default=1, help="device node id 1..15 (default: %(default)s)")
    args = parser.parse_args(argv)
    if not 1 <= args.node <= 15:
        parser.error(f"--node: expected 1..15, got {args.node}")
    sys.stdout.write(generate_dbc(args.node))
    return 0


if __name__ == "__main__":
    sys.exit(main())

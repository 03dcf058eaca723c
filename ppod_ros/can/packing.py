"""Field packing shared by the frame records: range-checked integers, int24 values, the Record base.

Values that do not fit their field are rejected (a ProtocolError whose ``reason`` is "out of
range"), never clipped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import can
import numpy as np

from ppod_ros.can.protocol import INT24_MAX, DeviceState, Fn, can_id
from ppod_ros.errors import ProtocolError


def err(reason: str, detail: str) -> ProtocolError:
    """A ProtocolError carrying a short ``reason`` (receivers count rejected frames by it)."""
    exc = ProtocolError(f"{reason}: {detail}")
    exc.reason = reason  # type: ignore[attr-defined]
    return exc


def check_int(value: float, lo: int, hi: int, name: str) -> int:
    if not (isinstance(value, (int, np.integer)) or (isinstance(value, float) and math.isfinite(value))):
        raise err("out of range", f"{name}: expected a finite number, got {value!r}")
    v = int(round(value))
    if not lo <= v <= hi:
        raise err("out of range", f"{name}: {value!r} does not fit {lo}..{hi}")
    return v


def scaled(value: float, lsb: float, lo: int, hi: int, name: str) -> int:
    if not math.isfinite(value):
        raise err("out of range", f"{name}: must be finite, got {value!r}")
    return check_int(round(value / lsb), lo, hi, name)


def i24(v: int) -> bytes:
    return (v & 0xFFFFFF).to_bytes(3, "little")


def from_i24(b: bytes) -> int:
    v = int.from_bytes(b, "little")
    return v - (1 << 24) if v & 0x800000 else v


def u24(v: int) -> bytes:
    return v.to_bytes(3, "little")


def complex24(value: complex, lsb: float, name: str) -> bytes:
    return i24(scaled(value.real, lsb, -INT24_MAX, INT24_MAX, f"{name}.real")) + i24(
        scaled(value.imag, lsb, -INT24_MAX, INT24_MAX, f"{name}.imag")
    )


def from_complex24(b: bytes, lsb: float) -> complex:
    return complex(from_i24(b[0:3]) * lsb, from_i24(b[3:6]) * lsb)


def device_state(value: int) -> DeviceState:
    if value not in DeviceState._value2member_map_:
        raise err("out of range", f"device state {value}")
    return DeviceState(value)


@dataclass(frozen=True)
class Field:
    """One signal of a frame's payload, for generators (a DBC file) and independent decoders.

    ``offset`` and ``size`` in bytes (little-endian), ``signed`` two's complement, physical value =
    raw x ``scale`` in ``unit``.
    """

    name: str
    offset: int
    size: int
    signed: bool = False
    scale: float = 1.0
    unit: str = ""


@dataclass(frozen=True)
class Record:
    """Base of all frame records; subclasses define FN, LENGTH, ``_payload`` and ``_parse``.

    ``FIELDS`` declares the payload layout (name, offset, size, signedness, scale), where a record
    states it; the codec's ``RECORDS`` registry maps every function code to its record.
    """

    FN: ClassVar[Fn]
    LENGTH: ClassVar[int]
    FIELDS: ClassVar[tuple[Field, ...]] = ()

    def _payload(self) -> bytes:
        raise NotImplementedError

    def encode(self, node: int) -> can.Message:
        data = self._payload()
        if len(data) != self.LENGTH:
            raise err(
                "wrong length", f"{type(self).__name__} payload has {len(data)} bytes, expected {self.LENGTH}"
            )
        return can.Message(arbitration_id=can_id(self.FN, node), data=data, is_extended_id=False)


__all__ = [
    "Field",
    "Record",
    "check_int",
    "complex24",
    "device_state",
    "err",
    "from_complex24",
    "from_i24",
    "i24",
    "scaled",
    "u24",
]

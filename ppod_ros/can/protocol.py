"""The PPOD CAN protocol, version 2.0: identifiers, enumerations, scalings and frame timing.

docs/can_protocol.md is the normative description; this module is its machine-readable half.
Classic CAN, 11-bit identifiers, little-endian payloads. An identifier is ``function << 4 | node``:
the function code (7 bits) sets the priority (lower wins arbitration), the node id (4 bits) is the
device addressed or reporting. The emergency stop has function 0, so it beats every other frame;
``0x000`` stops every device on the bus.
"""

from __future__ import annotations

import math
from enum import IntEnum, IntFlag

import numpy as np

from ppod_ros.device.config import CYCLE_MODULUS  # cycle indices in frames: the count mod 2^24
from ppod_ros.errors import ProtocolError

#: 2.0: TABLE_CRC protects a table's header and entries (required before a commit) and the device
#: reports its own limits (DEVICE_LIMIT) with VERSION. 1.0 devices and hosts are refused.
PROTOCOL_VERSION = (2, 0)
BROADCAST_NODE = 0
MAX_NODE = 15
NUM_ACTUATORS = 6
MAX_CHANNELS = 16
MAX_TABLE_HARMONIC = 10
#: Raw captures: up to 16 cycles, sample index 12 bits per channel.
MAX_RAW_CYCLES = 16
MAX_RAW_SAMPLES = 4096
#: A harmonic summary averages at most 16 cycles (4 bits in its header).
MAX_SUMMARY_CYCLES = 16


class Fn(IntEnum):
    """Function codes, in priority order (the identifier is ``fn << 4 | node``)."""

    ESTOP = 0  # host -> device, any payload: stop now
    FAULT = 1  # device -> host, on every change of the fault flags
    CONTROL = 2  # host -> device: enable, disable, reset e-stop, clear faults
    HEARTBEAT = 3  # host -> device, every 50 ms
    TABLE_ACK = 4  # device -> host: commit accepted / active / rejected
    TABLE_HEADER = 5  # host -> device: starts a table in the back buffer
    TABLE_ENTRY = 6  # host -> device: one (actuator, harmonic) current phasor
    TABLE_COMMIT = 7  # host -> device: swap the back buffer in at the next cycle start
    STATUS = 8  # device -> host, status_rate_hz: state, faults, clock (the device heartbeat)
    STATUS_EXT = 9  # device -> host, status_rate_hz: cycle count, ramp, heartbeat age, errors
    COIL_TEMP = 10  # device -> host, 1 Hz: thermal estimate per coil
    COIL_RMS = 11  # device -> host, 1 Hz: RMS current per coil
    VERSION_REQUEST = 12  # host -> device: protocol handshake
    VERSION = 13  # device -> host: handshake reply
    SUMMARY_HEADER = 14  # device -> host: accelerometer harmonic summary, cycle index and timing
    SUMMARY_DATA = 15  # device -> host: one (channel, harmonic) phasor of that summary
    RAW_REQUEST = 16  # host -> device: capture raw samples (bounded)
    RAW_HEADER = 17  # device -> host: raw capture timing
    RAW_DATA = 18  # device -> host: three consecutive samples of one channel
    TABLE_CRC = 19  # host -> device: CRC-16 over a table's header and entries, before its commit (2.0)
    DEVICE_LIMIT = 20  # device -> host: one of the device's own limits, after VERSION (2.0)


HOST_TO_DEVICE = frozenset(
    {
        Fn.ESTOP,
        Fn.CONTROL,
        Fn.HEARTBEAT,
        Fn.TABLE_HEADER,
        Fn.TABLE_ENTRY,
        Fn.TABLE_COMMIT,
        Fn.VERSION_REQUEST,
        Fn.RAW_REQUEST,
        Fn.TABLE_CRC,
    }
)
DEVICE_TO_HOST = frozenset(set(Fn) - HOST_TO_DEVICE)


class DeviceState(IntEnum):
    """Device states (same numbering as ppod_msgs/DeviceStatus)."""

    DISABLED = 0
    ENABLED = 1
    RAMPING = 2
    WATCHDOG = 3
    ESTOP = 4
    FAULT = 5


class Command(IntEnum):
    ENABLE = 1
    DISABLE = 2  # ramp to zero (payload ramp, at least the device minimum), then disabled
    RESET_ESTOP = 3  # leave the latched emergency stop (-> disabled; -> fault if a stopping fault latched)
    CLEAR_FAULTS = 4  # leave the fault state (-> disabled) once its causes are gone
    SUMMARY_HARMONICS = 5  # payload: summaries carry harmonics 1..n at least (n 1..10), within the frame budget


class Fault(IntFlag):
    """Fault flags (16 bits in STATUS and FAULT frames)."""

    ESTOP = 0x0001  # emergency stop latched
    WATCHDOG = 0x0002  # host heartbeat lost; ramped to zero
    THERMAL = 0x0004  # a coil's thermal estimate passed limits.coil_temperature_c
    VOLTAGE = 0x0008  # an amplifier needed more than limits.amplifier_voltage_v
    STROKE = 0x0010  # a leg passed limits.leg_stroke_m
    OVER_CURRENT = 0x0020  # a coil passed limits.coil_current_a
    TABLE_REJECTED = 0x0040  # the last commit was rejected (see its TABLE_ACK)
    FRAME_ERRORS = 0x0080  # malformed or unexpected frames were received since the last status


#: Faults that stop the plate and latch the FAULT state until CLEAR_FAULTS.
STOPPING_FAULTS = Fault.THERMAL | Fault.VOLTAGE | Fault.STROKE | Fault.OVER_CURRENT


class LimitItem(IntEnum):
    """The device limits a DEVICE_LIMIT frame carries (value in 1e-6 of the SI unit)."""

    LEG_STROKE_M = 0
    COIL_CURRENT_A = 1
    AMPLIFIER_VOLTAGE_V = 2
    COIL_TEMPERATURE_C = 3
    PLATE_ACCEL_MPS2 = 4
    PLATE_ANGULAR_ACCEL_RADPS2 = 5
    FREQUENCY_MIN_HZ = 6
    FREQUENCY_MAX_HZ = 7
    #: Excluded bands follow as pairs: item 8 + 2 i is band i's lower edge, 9 + 2 i its upper edge.
    EXCLUDED_BAND = 8


class AckResult(IntEnum):
    ACCEPTED = 0  # complete and valid; becomes active at the next cycle start
    ACTIVE = 1  # now playing (cycle_index: the first cycle that plays it)
    INCOMPLETE = 2  # entries missing or duplicated, no header or no TABLE_CRC for this sequence number
    CHECKSUM = 3  # entries received, checksum (entries) or TABLE_CRC (header and entries) mismatch
    OVER_LIMIT = 4  # the device's own limit check failed (band, excluded bands, peak current, stroke)
    BAD_STATE = 5  # not enabled (disabled, watchdog, e-stop, fault)
    SUPERSEDED = 6  # a newer commit replaced this one before it became active


# ------------------------------------------------------------------------------------- scaling
CURRENT_LSB_A = 2.0**-19  # table entries: int24, +-16 A
SUMMARY_LSB_MPS2 = 2.0**-14  # summary phasors: int24, +-512 m/s^2
RAW_LSB_MPS2 = 2.0**-9  # raw samples: int16, +-64 m/s^2
FREQUENCY_LSB_HZ = 1e-6  # uint32 micro-hertz
RAMP_LSB_S = 1e-3  # uint16 milliseconds
TIME_LSB_S = 1e-3  # uint32 milliseconds of device time
LIMIT_LSB = 1e-6  # DEVICE_LIMIT values: uint32 micro-units of the limit's SI unit
MAX_RAMP_S = 0xFFFF * RAMP_LSB_S  # the u16 ramp field of TABLE_HEADER and CONTROL: 65.535 s
HEARTBEAT_AGE_LSB_S = 2e-3  # uint8; 255 = 510 ms or more, or never
COIL_RMS_LSB_A = 0.05  # uint8
INT24_MAX = 2**23 - 1


def can_id(fn: Fn, node: int) -> int:
    if not 0 <= node <= MAX_NODE:
        raise ProtocolError(f"node: expected 0..{MAX_NODE}, got {node}")
    return (int(fn) << 4) | node


def split_id(arbitration_id: int) -> tuple[int, int]:
    """(function code, node) of an 11-bit identifier."""
    return arbitration_id >> 4, arbitration_id & 0xF


def quantise(value: np.ndarray, lsb: float) -> np.ndarray:
    """Round to the protocol grid (what the receiver will decode), same shape."""
    return np.round(np.asarray(value) / lsb) * lsb


def quantise_currents(table: np.ndarray) -> np.ndarray:
    """A current table (complex, A) as the device will receive it (int24 steps of 2^-19 A)."""
    t = np.asarray(table, dtype=complex)
    return quantise(t.real, CURRENT_LSB_A) + 1j * quantise(t.imag, CURRENT_LSB_A)


def quantise_frequency(frequency_hz: float) -> float:
    return float(round(frequency_hz / FREQUENCY_LSB_HZ) * FREQUENCY_LSB_HZ)


def frame_bits(data_bytes: int) -> int:
    """Bits on the wire of a classic base-format data frame, worst-case bit stuffing included.

    ``8 s + 47 + floor((34 + 8 s - 1) / 4)`` for s data bytes (Davis, Burns, Bril and Lukkien, "Controller
    Area Network (CAN) schedulability analysis: refuted, revisited and revised", Real-Time Systems 35,
    2007): 47 bits of frame overhead including the 3-bit interframe space, of which the 34 bits
    from start-of-frame to the CRC and the data are subject to stuffing, one stuff bit per 4 bits.
    """
    if not 0 <= data_bytes <= 8:
        raise ProtocolError(f"data_bytes: classic CAN carries 0..8 bytes, got {data_bytes}")
    return 8 * data_bytes + 47 + (34 + 8 * data_bytes - 1) // 4


def bus_load(frame_sizes: list[int] | np.ndarray, duration_s: float, bitrate: int) -> float:
    """Fraction of the bit rate used by frames with these data lengths over ``duration_s``."""
    if duration_s <= 0 or not math.isfinite(duration_s):
        raise ProtocolError(f"duration_s: must be > 0, got {duration_s}")
    bits = sum(frame_bits(int(n)) for n in frame_sizes)
    return bits / (duration_s * bitrate)


__all__ = [
    "AckResult",
    "BROADCAST_NODE",
    "CURRENT_LSB_A",
    "CYCLE_MODULUS",
    "Command",
    "DEVICE_TO_HOST",
    "DeviceState",
    "FREQUENCY_LSB_HZ",
    "Fault",
    "Fn",
    "HOST_TO_DEVICE",
    "LIMIT_LSB",
    "LimitItem",
    "MAX_CHANNELS",
    "MAX_RAMP_S",
    "MAX_RAW_CYCLES",
    "MAX_RAW_SAMPLES",
    "MAX_SUMMARY_CYCLES",
    "MAX_TABLE_HARMONIC",
    "NUM_ACTUATORS",
    "PROTOCOL_VERSION",
    "RAW_LSB_MPS2",
    "STOPPING_FAULTS",
    "SUMMARY_LSB_MPS2",
    "TIME_LSB_S",
    "bus_load",
    "can_id",
    "frame_bits",
    "quantise",
    "quantise_currents",
    "quantise_frequency",
    "split_id",
]

"""Conversions between ppod_msgs messages and the core's types (nodes translate, nothing more)."""

from __future__ import annotations

import math

import numpy as np
from builtin_interfaces.msg import Time
from ppod_msgs.msg import PlateHarmonic
from ppod_msgs.msg import PlateMotion as PlateMotionMsg

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion


def motion_to_msg(motion: PlateMotion, stamp: Time | None = None) -> PlateMotionMsg:
    msg = PlateMotionMsg()
    if stamp is not None:
        msg.header.stamp = stamp
    msg.header.frame_id = "plate"
    msg.name = motion.name
    msg.frequency_hz = motion.frequency_hz
    msg.ramp_time_s = motion.ramp_time_s or 0.0
    msg.harmonics = harmonics_to_msg(motion.k, motion.amplitude, motion.phase)
    return msg


def harmonics_to_msg(k: np.ndarray, amplitude: np.ndarray, phase: np.ndarray) -> list[PlateHarmonic]:
    out = []
    for kk, amp, ph in zip(k, amplitude, phase):
        h = PlateHarmonic(k=int(kk))
        h.amplitude = np.asarray(amp, dtype=float)
        h.phase = np.asarray(ph, dtype=float)
        out.append(h)
    return out


def phasors_to_msg(k: np.ndarray, phasors: np.ndarray) -> list[PlateHarmonic]:
    """Harmonics from complex phasors (K, 6) (PHYSICS.md convention)."""
    X = np.asarray(phasors, dtype=complex)
    return harmonics_to_msg(np.asarray(k), np.abs(X), np.angle(X))


def motion_from_msg(msg: PlateMotionMsg) -> PlateMotion:
    """Validate a PlateMotion message into the core type (ConfigError names the field)."""
    ks = [int(h.k) for h in msg.harmonics]
    amp = np.array([np.asarray(h.amplitude, dtype=float) for h in msg.harmonics]).reshape(-1, 6)
    ph = np.array([np.asarray(h.phase, dtype=float) for h in msg.harmonics]).reshape(-1, 6)
    ramp = float(msg.ramp_time_s)
    if not math.isfinite(ramp) or ramp < 0:
        raise ConfigError(f"ramp_time_s: must be a finite number of seconds >= 0, got {ramp}")
    return PlateMotion(float(msg.frequency_hz), np.array(ks, dtype=np.int64), amp, ph, name=msg.name,
                       ramp_time_s=ramp if ramp > 0 else None)


def stamp_to_seconds(stamp: Time) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def seconds_to_stamp(t_s: float) -> Time:
    """A builtin_interfaces/Time from seconds, rounded to the nanosecond (2.9999999999 s -> 3 s)."""
    ns = round(t_s * 1e9)
    return Time(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))

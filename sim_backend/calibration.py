"""Calibrate the accelerometer array on a device: play a few motions, record summaries, fit.

:func:`record_calibration_motions` works on any device behind a :class:`DeviceLink` and a
:class:`WaveformGenerator` (``wait(seconds)`` lets device time pass: the simulator's ``advance``,
or ``time.sleep`` on the lab PC); :func:`calibrate_simulated_device` does it on an in-process
simulated device, faster than real time, and stores the result where the feedback finds it
(``<cache_dir>/<device>/accel_calibration.json``). The demo may call it at start-up.

The motions: one per rigid-body direction (translations along x, y, z, rotations about x, y, z),
so every channel sees specific force in three independent directions (a well-conditioned fit).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from ppod_ros.control.online import OnlineSettings, high_pass_response
from ppod_ros.device.schema import DeviceConfig
from ppod_ros.errors import DeviceError
from ppod_ros.estimation.calibration import AccelCalibration, MotionData, calibrate, save_calibration
from ppod_ros.motion import PlateMotion

#: Calibration motions: amplitude of each single-direction motion (m/s^2 along x, y, z; rad/s^2 about
#: x, y, z), at the frequency below; well inside the device's limits.
CALIBRATION_AMPLITUDES = (6.0, 6.0, 4.0, 25.0, 25.0, 40.0)
CALIBRATION_FREQUENCY_HZ = 30.0
#: Device time to let a motion ramp in and settle before recording (s), and summaries averaged.
SETTLE_S = 1.2
SUMMARIES_PER_MOTION = 12
_channels = itertools.count()


def calibration_motions(frequency_hz: float = CALIBRATION_FREQUENCY_HZ) -> list[PlateMotion]:
    """One single-direction motion per rigid-body axis (see the module docstring)."""
    names = ("TransX", "TransY", "Bounce", "RockX", "RockY", "TwistZ")
    out = []
    for j, (name, amp) in enumerate(zip(names, CALIBRATION_AMPLITUDES)):
        a = np.zeros(6)
        a[j] = amp
        out.append(PlateMotion.single(frequency_hz, a, name=f"calibration-{name}", ramp_time_s=0.3))
    return out


def record_calibration_motions(config: DeviceConfig, link, generator, motions: Sequence[PlateMotion],
                               wait: Callable[[float], None], summaries: int = SUMMARIES_PER_MOTION,
                               progress: Callable[[str], None] | None = None) -> list[MotionData]:
    """Play each motion, average ``summaries`` device summaries (AC coupling undone) per motion."""
    received: list = []
    link.on_summary.append(received.append)
    out = []
    try:
        for m in motions:
            result = generator.submit(m)
            if not result.accepted:
                raise DeviceError(f"calibration motion {m.name} rejected: {result.reason}")
            wait(SETTLE_S)
            received.clear()
            while len(received) < summaries:
                wait(0.05)
            P = np.stack([s.phasors for s in received[:summaries]])
            k = received[0].k
            dt = 1.0 / (m.frequency_hz * received[0].samples_per_cycle)
            hp = high_pass_response(np.asarray(k) * m.frequency_hz, config.accelerometers.ac_coupling_hz, dt)
            P = P / hp[:, None]
            out.append(MotionData(m.name, m.frequency_hz, np.asarray(k), P.mean(axis=0)))
            if progress is not None:
                progress(f"recorded {m.name}: {summaries} summaries")
        generator.submit(PlateMotion.zero(motions[0].frequency_hz))
    finally:
        link.on_summary.remove(received.append)
    return out


def calibrate_simulated_device(config: DeviceConfig, *, seed: int | None = None, sensor_errors=None,
                               cache_dir: str | Path | None = None,
                               progress: Callable[[str], None] | None = None) -> AccelCalibration:
    """Calibrate an in-process simulated device (its default sensor errors unless given); store it if asked."""
    from ppod_ros.actuation.generator import WaveformGenerator
    from ppod_ros.actuation.planning import GoalPlanner
    from ppod_ros.can import DeviceLink, open_bus
    from ppod_sim.device import SimDevice

    cfg = config.with_can(interface="virtual", channel=f"ppod-calibrate-{next(_channels)}")
    buses = [open_bus(cfg.can), open_bus(cfg.can)]
    try:
        device = SimDevice(cfg, buses[0], seed=seed, sensor_errors=sensor_errors)
        link = DeviceLink(buses[1], cfg)
        gen = WaveformGenerator(link, GoalPlanner(cfg))

        def wait(seconds: float) -> None:
            end = device.time_s + seconds
            while device.time_s < end - 1e-12:
                link.heartbeat()
                device.advance(0.05)
                link.poll()

        motions = record_calibration_motions(cfg, link, gen, calibration_motions(), wait, progress=progress)
    finally:
        for bus in buses:
            bus.shutdown()
    cal = calibrate(config.accelerometers.layout, motions,
                    second_order_terms=OnlineSettings().second_order_terms)
    if cache_dir is not None:
        path = save_calibration(cal, cache_dir, config.name)
        if progress is not None:
            progress(f"stored {path}")
    return cal


__all__ = ["calibrate_simulated_device", "calibration_motions", "record_calibration_motions"]

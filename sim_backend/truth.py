"""Ground truth of the simulated plate, one record per completed cycle (the real device has none).

The system tests compare the plate's *true* acceleration harmonics with the goal; the parts
simulation in the simulator process consumes ``CycleTruth.motion()``. ``TruthWriter`` appends the
records to a JSON-lines file for other processes (``python -m ppod_sim --truth-out FILE``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ppod_ros.motion import PlateMotion


@dataclass(frozen=True, eq=False)
class CycleTruth:
    """Ground truth of one completed cycle (simulation only; the real device has none).

    Attributes
    ----------
    cycle_index : int
    start_time_s : float
        Device time of the cycle start.
    frequency_hz : float
    table_seq : int
        The active table's sequence number at the end of the cycle.
    amplitude_scale : float
        Ramp progress at the end of the cycle.
    accel : complex ndarray, shape (H, 6)
        True plate acceleration harmonics 1..H in the plate frame, PHYSICS.md phasors.
    accel_samples : ndarray, shape (N, 6)
        The sampled true plate acceleration.
    current_peak_a, voltage_peak_v, leg_peak_m : ndarray, shape (6,)
        Peaks over the cycle of the coil currents, amplifier voltages and leg displacements.
    current_end_a : ndarray, shape (6,)
        Coil currents at the end of the cycle.
    """

    cycle_index: int
    start_time_s: float
    frequency_hz: float
    table_seq: int
    amplitude_scale: float
    accel: np.ndarray
    accel_samples: np.ndarray
    current_peak_a: np.ndarray
    voltage_peak_v: np.ndarray
    leg_peak_m: np.ndarray
    current_end_a: np.ndarray

    def motion(self, absolute_time: bool = False) -> PlateMotion:
        """The plate's actual motion over this cycle as a PlateMotion (harmonics 1..H), with phases
        referred to the cycle's start, or with ``absolute_time`` to device time t = 0 (the same as
        ``motion().time_shifted(-start_time_s)``, built once)."""
        k = np.arange(1, self.accel.shape[0] + 1)
        X = self.accel
        if absolute_time:
            X = X * np.exp(-1j * k[:, None] * (2.0 * np.pi * self.frequency_hz * self.start_time_s))
        return PlateMotion.from_phasors(self.frequency_hz, k, X, name=f"cycle {self.cycle_index}")


class TruthWriter:
    """Appends each cycle's ground truth to a JSON-lines file (one object per cycle)."""

    def __init__(self, path: str | Path):
        self.file = open(path, "a", encoding="utf-8")  # noqa: SIM115 (closed by close())

    def __call__(self, rec: CycleTruth) -> None:
        self.file.write(
            json.dumps(
                {
                    "cycle": rec.cycle_index,
                    "start_time_s": rec.start_time_s,
                    "frequency_hz": rec.frequency_hz,
                    "table_seq": rec.table_seq,
                    "amplitude_scale": rec.amplitude_scale,
                    "accel_re": rec.accel.real.round(7).tolist(),
                    "accel_im": rec.accel.imag.round(7).tolist(),
                    "current_peak_a": rec.current_peak_a.round(6).tolist(),
                }
            )
            + "\n"
        )
        self.file.flush()

    def close(self) -> None:
        self.file.close()


def save_cycles(path: str | Path, cycles: list[CycleTruth]) -> None:
    """Store the cycles' start times, frequencies and acceleration harmonics (what the parts physics
    reads: :meth:`SimWorld.advance_parts <ppod_sim.world.SimWorld.advance_parts>`) in an ``.npz``
    file, for replaying a run's parts physics (``ppod bench sim_parts``)."""
    np.savez_compressed(
        path,
        cycle_index=np.array([c.cycle_index for c in cycles], np.int64),
        start_time_s=np.array([c.start_time_s for c in cycles]),
        frequency_hz=np.array([c.frequency_hz for c in cycles]),
        table_seq=np.array([c.table_seq for c in cycles], np.int64),
        amplitude_scale=np.array([c.amplitude_scale for c in cycles]),
        accel=np.array([c.accel for c in cycles]),
    )


def load_cycles(path: str | Path) -> list[CycleTruth]:
    """The cycles :func:`save_cycles` stored (samples and peaks, not stored, are empty)."""
    with np.load(path) as d:
        empty = np.zeros(0)
        return [CycleTruth(int(d["cycle_index"][k]), float(d["start_time_s"][k]), float(d["frequency_hz"][k]),
                           int(d["table_seq"][k]), float(d["amplitude_scale"][k]), d["accel"][k], np.zeros((0, 6)),
                           empty, empty, empty, empty)
                for k in range(d["start_time_s"].size)]


__all__ = ["CycleTruth", "TruthWriter", "load_cycles", "save_cycles"]

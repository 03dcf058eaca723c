"""The PPOD2 lab's saved accelerometer cycles (public repository benbdon/PPOD2, SavedSignals_Pdd).

The JSON form (tests/data/ppod2_real_subset.json) holds ``source``, ``layout`` (one
``{position, axis}`` per single-axis channel, m) and ``signals``: per motion ``fs`` (Hz), ``T``
(nominal period, s), ``accel_channels`` (N x C, m/s^2, one saved cycle with its mean removed),
``plate_accel`` (N x 6, the lab's own least-squares rigid-body estimate), ``plate_accel_desired``
and ``desired`` (the lab's motion strings). The plate's period is the data's, N / fs, not ``T``.
Channels are named ``ch0``.. in the file's order (the numbering of the lab's notes).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.estimation.layout import AccelerometerLayout
from ppod_ros.estimation.recording import AccelRecording


@dataclass(frozen=True, eq=False)
class Ppod2Record:
    """One saved cycle: readings (N, C) m/s^2, sample rate, the lab's 6-DoF estimate (N, 6)."""

    name: str
    samples_mps2: np.ndarray
    sample_rate_hz: float
    lab_estimate: np.ndarray
    desired: tuple[str, ...]

    @property
    def frequency_hz(self) -> float:
        """The plate's frequency from the data: one saved cycle of N samples is fs / N."""
        return self.sample_rate_hz / self.samples_mps2.shape[0]

    @property
    def time_s(self) -> np.ndarray:
        return np.arange(self.samples_mps2.shape[0]) / self.sample_rate_hz

    def recording(self, channels: tuple[str, ...]) -> AccelRecording:
        return AccelRecording(self.frequency_hz, channels, self.time_s, self.samples_mps2,
                              meta={"motion": self.name})


def read_ppod2_json(path: str | Path) -> tuple[AccelerometerLayout, dict[str, Ppod2Record]]:
    """The layout and the records by motion name of a PPOD2 JSON file (module docstring)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: not a readable PPOD2 JSON file: {exc}") from exc
    if not isinstance(data, dict) or not {"layout", "signals"} <= set(data):
        raise ConfigError(f"{path}: expected keys 'layout' and 'signals'")
    try:
        layout = AccelerometerLayout.from_dict({"channels": [
            {"name": f"ch{i}", "position_m": c["position"], "axis": c["axis"]} for i, c in enumerate(data["layout"])
        ]})
    except (KeyError, TypeError) as exc:
        raise ConfigError(f"{path}: layout: expected a list of {{position, axis}} entries ({exc})") from exc
    records = {}
    for name, sig in data["signals"].items():
        try:
            y = np.asarray(sig["accel_channels"], float)
            lab = np.asarray(sig["plate_accel"], float)
            fs = float(sig["fs"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(f"{path}: signals.{name}: {exc}") from exc
        if y.ndim != 2 or y.shape[1] != layout.num_channels or lab.shape != (y.shape[0], 6) or not fs > 0:
            raise ConfigError(
                f"{path}: signals.{name}: expected accel_channels (N, {layout.num_channels}), plate_accel (N, 6) "
                f"and fs > 0 Hz, got {y.shape}, {lab.shape}, {fs}"
            )
        records[name] = Ppod2Record(name, y, fs, lab, tuple(str(d) for d in sig.get("desired", ())))
    return layout, records


__all__ = ["Ppod2Record", "read_ppod2_json"]

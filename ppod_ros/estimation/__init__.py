"""Accelerometer estimation: the plate's 6-DoF acceleration harmonics from single-axis channels.

Public API (docs/feedback.md):

- :class:`AccelerometerLayout`: channels (position, sensing axis), the PHYSICS.md default layout,
  strict YAML loading, observability check.
- :class:`AccelEstimator`: ``from_samples`` (raw samples with times from a cycle start),
  ``from_summaries`` (per-channel phasors, as a device DSP sends them), ``from_recording``; removes
  the tilted-gravity and second-order terms and drops dead channels while the rest determine the
  motion, else raises :class:`EstimationError`.
- :class:`PlateEstimate`: phasors (K, 6), noise, channel status, residuals.
- :func:`calibrate`, :class:`AccelCalibration`: per-channel gain and axis from several motions'
  readings, stored per device (:mod:`~ppod_ros.estimation.calibration`).
- :class:`AccelRecording`, :func:`read_recording`, :func:`write_recording`,
  :func:`register_reader`: recorded data (.npz, .csv; MCAP readers plug in).
"""

from ppod_ros.estimation.calibration import AccelCalibration, CalibrationError, calibrate
from ppod_ros.estimation.estimator import AccelEstimator
from ppod_ros.estimation.harmonic_fit import HealthSettings, cycle_times, fit_harmonics
from ppod_ros.estimation.layout import AccelerometerLayout, Observability
from ppod_ros.estimation.recording import AccelRecording, read_recording, register_reader, write_recording
from ppod_ros.estimation.second_order import SECOND_ORDER_TERMS, second_order_phasors
from ppod_ros.estimation.six_dof import EstimationError, PlateEstimate

__all__ = [
    "SECOND_ORDER_TERMS",
    "calibrate",
    "AccelCalibration",
    "AccelEstimator",
    "AccelRecording",
    "AccelerometerLayout",
    "CalibrationError",
    "EstimationError",
    "HealthSettings",
    "Observability",
    "PlateEstimate",
    "cycle_times",
    "fit_harmonics",
    "read_recording",
    "register_reader",
    "second_order_phasors",
    "write_recording",
]

"""The simulated accelerometer array: what each channel reads of the plate's true rigid-body motion.

A channel at plate-frame position l with sensing axis e (fixed in the plate) reads the specific
force along e, everything expressed in the tilted plate frame (PHYSICS.md, "Accelerometers"):

    y = e . (a_P + alpha x l + omega x (omega x l) - g)

with a_P, alpha, omega the plate's true acceleration, angular acceleration and angular velocity
and g = (0, 0, -9.81) m/s^2 in the base frame, rotated into the plate. The centripetal term and the
tilted gravity are therefore in the readings. Then, per channel:

* AC coupling: a first-order high-pass ``y_n = a (y_{n-1} + x_n - x_{n-1})``, ``a = exp(-2 pi f_c dt)``
  (frequency response ``a (1 - z^-1) / (1 - a z^-1)``; at 30 Hz and f_c = 0.1 Hz it leads by
  0.19 deg and passes 0.99999 of the amplitude), which removes the static 1 g;
* white Gaussian noise (``noise_mps2`` per sample) from the simulation's seeded generator;
* quantisation to ``quantisation_mps2`` steps (the ADC).

Real sensors are not the layout's nominal ones (:class:`SensorErrors`, on by default, sized like the
PPOD2 lab's device, tests/data/ppod2_real_subset.json): each channel reads with its own gain error
and a sensing axis tilted from the nominal one, and the vertical channels see the plate's bending,
a non-rigid residual proportional to the plate's vertical acceleration. The estimator knows none of
this unless a calibration tells it (``ppod calibrate accel``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.signal

from ppod_ros.device.config import Accelerometers
from ppod_ros.errors import ConfigError
from ppod_ros.kinematics.stewart import cross
from ppod_ros.motion import GRAVITY_MPS2


def specific_force(
    accel_plate: np.ndarray,
    omega_plate: np.ndarray,
    gravity_plate: np.ndarray,
    position_m: np.ndarray,
    axis: np.ndarray,
) -> np.ndarray:
    """Noise-free channel readings before AC coupling, shape (n, C).

    Parameters
    ----------
    accel_plate : (n, 6) [a_P, alpha] in the plate frame; omega_plate : (n, 3); gravity_plate : (n, 3)
    position_m, axis : (C, 3)
    """
    a = accel_plate[:, None, :3]
    alpha = accel_plate[:, None, 3:]
    om = omega_plate[:, None, :]
    l = position_m[None]
    s = a + cross(alpha, l) + cross(om, cross(om, l)) - gravity_plate[:, None, :]
    return np.einsum("ncj,cj->nc", s, axis)


#: Default gain of each channel of the 12-channel layout (relative): like the lab's device, one
#: tangential channel 8 % weak (u230.t) and one 6 % strong (u250.t), the others within 2 %.
DEFAULT_GAINS = (1.01, 0.99, 1.02, 0.98, 1.0, 1.01, 0.92, 0.99, 1.06, 1.0, 0.98, 1.02)
#: Default tilts out of the plate (degrees) of those two tangential channels (opposite senses: a
#: common tilt of all tangential axes is invisible to any calibration from the array's own data).
DEFAULT_TILTS_DEG = ((6, 4.0), (8, -4.0))
#: Default bending residual of the vertical channels: this fraction of the plate's vertical
#: acceleration, with a cos 2 theta (saddle) shape around the plate, which no rigid motion makes.
DEFAULT_BENDING = 0.02


@dataclass(frozen=True)
class SensorErrors:
    """How the simulated channels differ from the nominal layout (see the module docstring).

    Attributes
    ----------
    gain : tuple of float, length C, or None (all 1)
    tilt_deg : tuple of (channel index, degrees)
        Tilts of a channel's axis about the in-plane direction perpendicular to it (out of the plate
        for an in-plane axis).
    bending : float
        Saddle-shaped bending residual of vertical channels, fraction of the vertical acceleration.
    """

    gain: tuple[float, ...] | None = None
    tilt_deg: tuple[tuple[int, float], ...] = ()
    bending: float = 0.0

    @classmethod
    def default(cls, num_channels: int) -> SensorErrors:
        """The lab-like errors for the 12-channel layout; none for other layouts."""
        if num_channels != len(DEFAULT_GAINS):
            return cls()
        return cls(DEFAULT_GAINS, DEFAULT_TILTS_DEG, DEFAULT_BENDING)

    @classmethod
    def none(cls) -> SensorErrors:
        return cls()

    def sensing(self, position_m: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(sensitivity vectors gain x true axis (C, 3), bending weights (C,)) for a layout."""
        C = axis.shape[0]
        gain = np.ones(C) if self.gain is None else np.asarray(self.gain, float)
        if gain.shape != (C,):
            raise ConfigError(f"sensor_errors.gain: expected {C} values, got {gain.size}")
        true_axis = np.array(axis, float)
        for c, deg in self.tilt_deg:
            e = true_axis[c]
            about = np.cross(e, [0.0, 0.0, 1.0])
            if np.linalg.norm(about) < 1e-9:
                about = np.array([1.0, 0.0, 0.0])
            about /= np.linalg.norm(about)
            th = math.radians(deg)
            true_axis[c] = e * math.cos(th) + np.cross(about, e) * math.sin(th)  # e is perpendicular to about
        vertical = np.abs(true_axis[:, 2]) > 0.9
        theta = np.arctan2(position_m[:, 1], position_m[:, 0])
        bend = np.where(vertical, self.bending * np.cos(2 * theta), 0.0)
        return true_axis * gain[:, None], bend


class AccelerometerArray:
    """Seeded, stateful accelerometer channels (see the module docstring).

    Parameters
    ----------
    layout : Accelerometers
    rng : numpy.random.Generator
    """

    def __init__(self, layout: Accelerometers, rng: np.random.Generator, errors: SensorErrors | None = None):
        self.layout = layout
        self.rng = rng
        self.position = np.asarray(layout.position_m)
        self.errors = SensorErrors.default(len(self.position)) if errors is None else errors
        # The channels' true sensitivity vectors (gain x axis) and bending weights.
        self.axis, self.bending = self.errors.sensing(self.position, np.asarray(layout.axis))
        # At rest the channels read +1 g along the vertical: start the high-pass settled there.
        rest = self.axis @ np.array([0.0, 0.0, GRAVITY_MPS2])
        self._x_prev = rest.copy()
        self._y_prev = np.zeros_like(rest)

    def high_pass_response(self, freq_hz: np.ndarray, dt_s: float) -> np.ndarray:
        """Complex response of the AC coupling at ``freq_hz`` for sample interval ``dt_s``."""
        a = math.exp(-2 * math.pi * self.layout.ac_coupling_hz * dt_s)
        z1 = np.exp(-2j * math.pi * np.asarray(freq_hz) * dt_s)
        return a * (1 - z1) / (1 - a * z1)

    def read(
        self, accel_plate: np.ndarray, omega_plate: np.ndarray, gravity_plate: np.ndarray, dt_s: float
    ) -> np.ndarray:
        """Readings (n, C) (m/s^2) for n consecutive samples ``dt_s`` apart."""
        x = specific_force(accel_plate, omega_plate, gravity_plate, self.position, self.axis)
        if np.any(self.bending):
            x = x + accel_plate[:, 2:3] * self.bending[None]
        if self.layout.ac_coupling_hz > 0:
            a = math.exp(-2 * math.pi * self.layout.ac_coupling_hz * dt_s)
            # Direct form II transposed: the filter state carries a (y_prev - x_prev).
            zi = (a * (self._y_prev - self._x_prev))[None]
            y, _ = scipy.signal.lfilter([a, -a], [1.0, -a], x, axis=0, zi=zi)
            x_prev, y_prev = x[-1], y[-1]
            self._x_prev, self._y_prev = x_prev, y_prev
        else:
            y = x
        if self.layout.noise_mps2 > 0:
            y = y + self.rng.normal(0.0, self.layout.noise_mps2, y.shape)
        q = self.layout.quantisation_mps2
        return np.round(y / q) * q if q > 0 else y


__all__ = ["AccelerometerArray", "SensorErrors", "specific_force"]

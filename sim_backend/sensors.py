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
"""

from __future__ import annotations

import math

import numpy as np
import scipy.signal

from ppod_ros.device.config import Accelerometers
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


class AccelerometerArray:
    """Seeded, stateful accelerometer channels (see the module docstring).

    Parameters
    ----------
    layout : Accelerometers
    rng : numpy.random.Generator
    """

    def __init__(self, layout: Accelerometers, rng: np.random.Generator):
        self.layout = layout
        self.rng = rng
        self.position = np.asarray(layout.position_m)
        self.axis = np.asarray(layout.axis)
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


__all__ = ["AccelerometerArray", "specific_force"]

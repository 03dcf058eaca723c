"""Constant-velocity Kalman filter of a part's planar pose (x, y, theta).

Each coordinate has the state (position, rate) with the discrete white-noise-acceleration model:
over dt, F = [[1, dt], [0, 1]] and Q = sigma_a^2 [[dt^4/4, dt^3/2], [dt^3/2, dt^2]], where sigma_a
is the typical acceleration (m/s^2, or rad/s^2 for theta). Measurements are positions with known
variance. The three coordinates are independent given diagonal measurement noise, so each is a
2-state filter in closed form (no matrix algebra per frame: this runs for every track every frame).

theta is kept continuous inside the filter; a measurement known only modulo a symmetry period is
applied with the innovation wrapped into [-period/2, period/2), so a rectangle turning through
pi/2 and beyond never jumps. A part type without orientation (disks) has no theta filter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class FilterSettings:
    """Noise model of the pose filter.

    accel_mps2, alpha_radps2 : typical linear and angular acceleration (process noise).
    sigma_pos_m, sigma_theta_rad : measurement noise of one detection.
    initial_speed_mps, initial_rate_radps : prior spread of the velocity of a new track.
    """

    accel_mps2: float = 0.05
    alpha_radps2: float = 0.3
    sigma_pos_m: float = 5e-5
    sigma_theta_rad: float = 1.5e-3
    initial_speed_mps: float = 0.05
    initial_rate_radps: float = 1.0


class _Axis:
    """One coordinate: position p, rate v, covariance [[a, b], [b, c]]."""

    __slots__ = ("p", "v", "a", "b", "c")

    def __init__(self, p: float, var_p: float, var_v: float):
        self.p, self.v = p, 0.0
        self.a, self.b, self.c = var_p, 0.0, var_v

    def predict(self, dt: float, q: float) -> None:
        a, b, c = self.a, self.b, self.c
        self.p += self.v * dt
        self.a = a + 2 * dt * b + dt * dt * c + q * dt**4 / 4
        self.b = b + dt * c + q * dt**3 / 2
        self.c = c + q * dt * dt

    def update(self, innovation: float, r: float) -> None:
        a, b, c = self.a, self.b, self.c
        s = a + r
        k0, k1 = a / s, b / s
        self.p += k0 * innovation
        self.v += k1 * innovation
        self.a = (1 - k0) * a
        self.b = (1 - k0) * b
        self.c = c - k1 * b


class PoseFilter:
    """Pose and velocity of one part from its detections.

    Parameters
    ----------
    x_m, y_m, theta_rad : float
        First measurement.
    symmetry_rad : float
        Period of theta's ambiguity (2 pi: none; 0: no orientation).
    settings : FilterSettings
    """

    def __init__(
        self, x_m: float, y_m: float, theta_rad: float, symmetry_rad: float, settings: FilterSettings
    ):
        s = settings
        self.settings = settings
        self.symmetry_rad = float(symmetry_rad)
        rp, rt = s.sigma_pos_m**2, s.sigma_theta_rad**2
        self._x = _Axis(x_m, rp, s.initial_speed_mps**2)
        self._y = _Axis(y_m, rp, s.initial_speed_mps**2)
        self._t = _Axis(theta_rad, rt, s.initial_rate_radps**2) if self.has_theta else None

    @property
    def has_theta(self) -> bool:
        return self.symmetry_rad > 0

    def predict(self, dt_s: float) -> None:
        if dt_s <= 0:
            return
        q = self.settings.accel_mps2**2
        self._x.predict(dt_s, q)
        self._y.predict(dt_s, q)
        if self._t is not None:
            self._t.predict(dt_s, self.settings.alpha_radps2**2)

    def update(self, x_m: float, y_m: float, theta_rad: float) -> None:
        rp = self.settings.sigma_pos_m**2
        self._x.update(x_m - self._x.p, rp)
        self._y.update(y_m - self._y.p, rp)
        if self._t is not None:
            self._t.update(self.theta_innovation(theta_rad), self.settings.sigma_theta_rad**2)

    def hold(self) -> None:
        """Set the velocity to zero (a part pressed against another stops moving relative to it:
        predicting it onward would carry it through its neighbour)."""
        for axis in (self._x, self._y, self._t):
            if axis is not None:
                axis.v = 0.0
                axis.b = 0.0

    def theta_innovation(self, theta_rad: float) -> float:
        """Measured minus predicted theta, wrapped by the symmetry period (0 without theta)."""
        if self._t is None:
            return 0.0
        period = self.symmetry_rad
        d = theta_rad - self._t.p
        return (d + period / 2) % period - period / 2

    @property
    def position(self) -> tuple[float, float]:
        return self._x.p, self._y.p

    @property
    def theta(self) -> float:
        """Continuous theta (not wrapped); 0 without orientation."""
        return self._t.p if self._t is not None else 0.0

    @property
    def velocity(self) -> tuple[float, float, float]:
        """(vx m/s, vy m/s, omega rad/s); omega is 0 without orientation."""
        return self._x.v, self._y.v, (self._t.v if self._t is not None else 0.0)

    def covariance(self) -> list[list[float]]:
        """3 x 3 covariance of (x, y, theta); theta's variance is inf without orientation."""
        vt = self._t.a if self._t is not None else math.inf
        return [[self._x.a, 0.0, 0.0], [0.0, self._y.a, 0.0], [0.0, 0.0, vt]]

    def velocity_covariance(self) -> list[float]:
        """Variances of (vx, vy, omega)."""
        return [self._x.c, self._y.c, self._t.c if self._t is not None else math.inf]

    def position_sigma_m(self) -> float:
        """Root of the larger position variance (m): the scale for association gates."""
        return math.sqrt(max(self._x.a, self._y.a))


__all__ = ["FilterSettings", "PoseFilter"]

"""Desired velocity fields: what the planner is asked for (PlanField's field_type and params).

=============  =====================  ==========================================================
field_type     params                 target velocity v(r), r = (x, y) in the plate frame
=============  =====================  ==========================================================
``sink``       [x0, y0, gain]         -gain (r - r0)                       (gain 1/s, > 0)
``line_sink``  [x0, y0, angle, gain]  -gain n (n . (r - r0)), n normal to the line through r0
                                      at ``angle`` (rad from +x): parts gather on the line
``transport``  [vx, vy]               (vx, vy)                             (m/s)
``rotation``   [x0, y0, omega]        omega z x (r - r0)                   (rad/s)
``orient``     [x0, y0, theta]        a rigid part's stable orientation theta (and theta + pi) on
                                      the line through r0 along theta + pi/2, which gathers
                                      parts (the rotated and shifted u1 motion of PHYSICS.md)
=============  =====================  ==========================================================

Centres must lie inside the working disc (radius 0.07 m here, inside the device's 0.08 m where the
contact margin is guaranteed), gains and speeds inside what the plate can produce.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ppod_ros.errors import ConfigError

#: Centres of requested fields must lie within this radius (m).
CENTRE_RADIUS_M = 0.07

_PARAMS = {
    "sink": ("x0", "y0", "gain"),
    "line_sink": ("x0", "y0", "angle", "gain"),
    "transport": ("vx", "vy"),
    "rotation": ("x0", "y0", "omega"),
    "orient": ("x0", "y0", "theta"),
}
_RANGES = {"gain": (1e-3, 3.0, "1/s"), "omega": (-3.0, 3.0, "rad/s"), "vx": (-0.1, 0.1, "m/s"),
           "vy": (-0.1, 0.1, "m/s"), "angle": (-4 * math.pi, 4 * math.pi, "rad"),
           "theta": (-4 * math.pi, 4 * math.pi, "rad")}


@dataclass(frozen=True)
class FieldSpec:
    """A requested linear velocity field (see the module docstring). Build with :meth:`from_request`."""

    kind: str
    params: tuple[float, ...]

    @classmethod
    def from_request(cls, field_type: str, params: Sequence[float]) -> FieldSpec:
        """Validate a PlanField request; ConfigError naming the field otherwise."""
        if field_type not in _PARAMS:
            raise ConfigError(f"field_type: expected one of {', '.join(_PARAMS)}, got {field_type!r}")
        names = _PARAMS[field_type]
        try:
            values = [float(v) for v in params]
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"params: expected numbers, got {params!r}") from exc
        if len(values) != len(names):
            raise ConfigError(f"params: {field_type} takes {len(names)} values [{', '.join(names)}], "
                              f"got {len(values)}")
        for name, v in zip(names, values):
            if not math.isfinite(v):
                raise ConfigError(f"params.{name}: must be finite, got {v}")
            if name in _RANGES:
                lo, hi, unit = _RANGES[name]
                if not lo <= v <= hi:
                    raise ConfigError(f"params.{name}: {v:g} {unit} is outside [{lo:g}, {hi:g}] {unit}")
        if field_type == "sink" and values[2] <= 0:
            raise ConfigError("params.gain: must be > 0")
        if "x0" in names:
            r = math.hypot(values[0], values[1])
            if r > CENTRE_RADIUS_M:
                raise ConfigError(f"params.x0, y0: ({values[0]:g}, {values[1]:g}) m is {r:.3f} m from the plate "
                                  f"centre, outside the working disc (radius {CENTRE_RADIUS_M} m)")
        return cls(field_type, tuple(values))

    @property
    def centre(self) -> np.ndarray:
        """r0 (m); the origin for transport."""
        return np.array(self.params[:2]) if self.kind != "transport" else np.zeros(2)

    def target_velocity(self, x_m, y_m) -> np.ndarray:
        """The requested velocity (..., 2) in m/s at plate points (broadcast x, y)."""
        x, y = np.broadcast_arrays(np.asarray(x_m, float), np.asarray(y_m, float))
        p = self.params
        if self.kind == "transport":
            return np.stack([np.full(x.shape, p[0]), np.full(x.shape, p[1])], axis=-1)
        dx, dy = x - p[0], y - p[1]
        if self.kind == "sink":
            return np.stack([-p[2] * dx, -p[2] * dy], axis=-1)
        if self.kind in ("line_sink", "orient"):
            # orient: the line through r0 along theta + pi/2, normal along theta (module docstring).
            angle, gain = (p[2], p[3]) if self.kind == "line_sink" else (p[2] + math.pi / 2, ORIENT_GAIN)
            nx, ny = -math.sin(angle), math.cos(angle)
            d = nx * dx + ny * dy
            return np.stack([-gain * d * nx, -gain * d * ny], axis=-1)
        return np.stack([-p[2] * dy, p[2] * dx], axis=-1)  # rotation

    def key(self) -> tuple:
        return (self.kind, tuple(round(v, 9) for v in self.params))

    def describe(self) -> str:
        return f"{self.kind} [{', '.join(f'{v:g}' for v in self.params)}]"


#: Nominal line-sink gain of the orienting motion, for its target field (1/s).
ORIENT_GAIN = 0.45

__all__ = ["CENTRE_RADIUS_M", "ORIENT_GAIN", "FieldSpec"]

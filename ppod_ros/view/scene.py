"""The scene the live view draws and the drawable topics carry, as plain data (no ROS, no Foxglove).

Frames: ``plate`` (origin at the centre of the plate's top surface, z up: PHYSICS.md's frame P) and
``camera`` (OpenCV convention: z along the optical axis), placed by the camera's mounting pose
(:meth:`CameraConfig.rotation_plate_from_camera`, ``position_m``). Everything else is drawn in
``plate``: the working disc, each tracked part (a disc with a heading arrow and its label), MovePart
targets, and the current field as arrows whose length is velocity x ``arrow_scale_s``.

Two adapters turn a :class:`Scene` into messages: ``ppod_nodes.viz`` (visualization_msgs/MarkerArray
and TF, recorded by ``ppod record``) and ``ppod view`` (Foxglove SceneUpdate over the live server).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ppod_ros.errors import ConfigError

#: Arrow length per velocity (s): 0.02 m/s draws as a 30 mm arrow on a 0.35 m plate.
DEFAULT_ARROW_SCALE_S = 1.5
#: Field grid points across the plate's diameter (the field is drawn inside the working disc).
DEFAULT_FIELD_GRID = 9


@dataclass(frozen=True)
class PartDrawing:
    """A tracked part (or a MovePart target) in the plate frame: id, label, pose (m, m, rad)."""

    id: int
    label: str
    x: float
    y: float
    theta: float
    tracked: bool = True


@dataclass(frozen=True)
class Arrow:
    """One field arrow: where (m) and the velocity there (m/s), plate frame."""

    x: float
    y: float
    vx: float
    vy: float


@dataclass(frozen=True)
class Scene:
    """Everything drawn at one instant (see the module docstring)."""

    plate_radius_m: float
    parts: tuple[PartDrawing, ...] = ()
    goals: tuple[PartDrawing, ...] = ()
    arrows: tuple[Arrow, ...] = ()
    arrow_scale_s: float = DEFAULT_ARROW_SCALE_S
    motion_name: str = ""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.plate_radius_m) and self.plate_radius_m > 0):
            raise ConfigError(f"plate_radius_m: must be > 0 m, got {self.plate_radius_m}")
        if not (math.isfinite(self.arrow_scale_s) and self.arrow_scale_s > 0):
            raise ConfigError(f"arrow_scale_s: must be > 0 s, got {self.arrow_scale_s}")


def field_arrows(motion, radius_m: float, mu: float = 0.3, n: int = DEFAULT_FIELD_GRID,
                 settings=None) -> tuple[Arrow, ...]:
    """The asymptotic field of ``motion`` for a point part of friction ``mu`` on an n x n grid inside the disc.

    Invalid points (contact lost) are left out.
    """
    from ppod_ros.parts import PointPart
    from ppod_ros.physics.field import solve_field

    if n < 2:
        raise ConfigError(f"n: need at least 2 grid points per side, got {n}")
    ticks = np.linspace(-radius_m, radius_m, n) * (n - 1) / n
    X, Y = np.meshgrid(ticks, ticks)
    inside = np.hypot(X, Y) <= radius_m
    pts = np.column_stack([X[inside], Y[inside]])
    result = solve_field(motion, PointPart(mu=mu), pts, settings)
    return tuple(Arrow(float(x), float(y), float(v[0]), float(v[1]))
                 for (x, y), v, ok in zip(pts, result.velocity, result.valid) if ok)


def quaternion_from_matrix(R: np.ndarray) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation matrix (3, 3), w >= 0."""
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3):
        raise ConfigError(f"R: expected a (3, 3) rotation matrix, got shape {R.shape}")
    w = math.sqrt(max(0.0, 1.0 + R[0, 0] + R[1, 1] + R[2, 2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1.0 + R[0, 0] - R[1, 1] - R[2, 2])) / 2, R[2, 1] - R[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1.0 - R[0, 0] + R[1, 1] - R[2, 2])) / 2, R[0, 2] - R[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1.0 - R[0, 0] - R[1, 1] + R[2, 2])) / 2, R[1, 0] - R[0, 1])
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    return (x / norm, y / norm, z / norm, w / norm)


def camera_transform(camera) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """The camera frame in the plate frame: translation (m) and rotation quaternion (x, y, z, w)."""
    return tuple(float(v) for v in camera.position_m), quaternion_from_matrix(camera.rotation_plate_from_camera)


__all__ = ["DEFAULT_ARROW_SCALE_S", "DEFAULT_FIELD_GRID", "Arrow", "PartDrawing", "Scene", "camera_transform",
           "field_arrows", "quaternion_from_matrix"]

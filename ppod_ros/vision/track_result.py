"""What the tracker reports: per-frame results and per-track states (plain, frozen data).

Status numbers match ppod_msgs/PartPose, so a node copies them into messages unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np


class TrackStatus(IntEnum):
    """Track status; values match ppod_msgs/PartPose STATUS_*."""

    TRACKED = 0
    PREDICTED = 1
    LOST = 2


@dataclass(frozen=True)
class TrackedPart:
    """One track in one frame.

    Attributes
    ----------
    id : int
        Stable track id (>= 1).
    label : str
        Part type.
    status : TrackStatus
    reason : str
        Why a track is not TRACKED: ``merged``, ``touching``, ``occluded``, ``edge``, ``out_of_view``
        or ``missed``
        ("" when measured).
    x_m, y_m, theta_rad : float
        Pose in the plate frame; theta in [-symmetry/2, symmetry/2) (0 when symmetry is 0).
    covariance : ndarray, shape (3, 3)
        Covariance of (x, y, theta) (m^2, m rad, rad^2); theta's variance is inf for disks.
    vx_mps, vy_mps, omega_radps : float
        Filtered velocity in the plate frame.
    symmetry_rad : float
        theta is known modulo this (2 pi: fully; 0: not at all).
    last_measured_s : float
        Stamp of the last frame that measured this part.
    reacquired : bool
        True in the frame where a lost part got its id back.
    """

    id: int
    label: str
    status: TrackStatus
    reason: str
    x_m: float
    y_m: float
    theta_rad: float
    covariance: np.ndarray
    vx_mps: float
    vy_mps: float
    omega_radps: float
    symmetry_rad: float
    last_measured_s: float
    reacquired: bool = False

    @property
    def pose(self) -> np.ndarray:
        """(x_m, y_m, theta_rad), shape (3,)."""
        return np.array([self.x_m, self.y_m, self.theta_rad])

    @property
    def velocity(self) -> np.ndarray:
        """(vx_mps, vy_mps, omega_radps), shape (3,)."""
        return np.array([self.vx_mps, self.vy_mps, self.omega_radps])


@dataclass(frozen=True)
class UnexplainedBlob:
    """A blob that is not a measurement of one part: ``kind`` is merged, touching, occluded or edge."""

    kind: str
    x_m: float
    y_m: float
    area_m2: float


@dataclass(frozen=True)
class TrackResult:
    """Everything the tracker knows after one frame."""

    stamp_s: float
    frame_index: int
    parts: tuple[TrackedPart, ...]
    unexplained: tuple[UnexplainedBlob, ...]
    new_ids: tuple[int, ...]
    lost_ids: tuple[int, ...]
    reacquired_ids: tuple[int, ...]
    forgotten_ids: tuple[int, ...]
    processing_s: float

    def by_id(self, track_id: int) -> TrackedPart | None:
        return next((p for p in self.parts if p.id == track_id), None)

    def with_status(self, status: TrackStatus) -> tuple[TrackedPart, ...]:
        return tuple(p for p in self.parts if p.status == status)


__all__ = ["TrackResult", "TrackStatus", "TrackedPart", "UnexplainedBlob"]

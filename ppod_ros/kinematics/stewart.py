"""Exact kinematics of the flexure Stewart platform that carries the plate.

A plate pose is a 6-vector ``[px, py, pz, phi_x, phi_y, phi_z]``: the displacement of the plate
origin P from its home position (base frame, m) and the rotation vector phi of the plate (rad),
``R = exp([phi]x)``. Leg i joins base point a_i (base frame) to plate point b_i (plate frame);
its length is ``L_i = |P_home + p + R b_i - a_i|``.

For a plate motion (PHYSICS.md) the pose trajectory is its zero-mean displacement: the linear part
is the double integral of p'', the rotation vector the double integral of alpha (to first order the
two agree; the second-order difference is below the plate motion's own definition). The exact
inverse kinematics of that trajectory, sampled over one period, gives the leg displacement
harmonics, including the second-order harmonics and offsets that a Jacobian would miss.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ppod_ros.actuation.harmonics import analyze, cycle_phases
from ppod_ros.config.fields import check_array
from ppod_ros.device.config import Geometry
from ppod_ros.errors import ConfigError, SolverError
from ppod_ros.motion import PlateMotion


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices [v]x, shape (..., 3, 3), of vectors (..., 3)."""
    v = np.asarray(v, dtype=float)
    K = np.zeros(v.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return K


def _series(theta2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """sin(t)/t, (1-cos t)/t^2, (t - sin t)/t^3 and their argument t, robust near t = 0."""
    t = np.sqrt(theta2)
    small = t < 1e-4
    ts = np.where(small, 1.0, t)
    a = np.where(small, 1 - theta2 / 6, np.sin(ts) / ts)
    b = np.where(small, 0.5 - theta2 / 24, (1 - np.cos(ts)) / ts**2)
    c = np.where(small, 1.0 / 6 - theta2 / 120, (ts - np.sin(ts)) / ts**3)
    return a, b, c, t


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b over the last axis with broadcasting (np.cross without its per-call overhead)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def rotation_and_left_jacobian(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R = exp([phi]x) and J_l(phi) together (they share [phi]x and its square), (..., 3, 3) each."""
    phi = np.asarray(phi, dtype=float)
    K = skew(phi)
    theta2 = np.sum(phi * phi, axis=-1)
    K2 = phi[..., :, None] * phi[..., None, :]  # [phi]x^2 = phi phi^T - |phi|^2 I
    K2[..., [0, 1, 2], [0, 1, 2]] -= theta2[..., None]
    a, b, c, _ = _series(theta2)
    a, b, c = a[..., None, None], b[..., None, None], c[..., None, None]
    R = a * K + b * K2
    Jl = b * K + c * K2
    R[..., [0, 1, 2], [0, 1, 2]] += 1.0
    Jl[..., [0, 1, 2], [0, 1, 2]] += 1.0
    return R, Jl


def rotation_matrix(phi: np.ndarray) -> np.ndarray:
    """Rodrigues' formula: R = exp([phi]x), shape (..., 3, 3)."""
    phi = np.asarray(phi, dtype=float)
    K = skew(phi)
    a, b, _, _ = _series(np.sum(phi * phi, axis=-1))
    return np.eye(3) + a[..., None, None] * K + b[..., None, None] * (K @ K)


def left_jacobian(phi: np.ndarray) -> np.ndarray:
    """J_l(phi), shape (..., 3, 3): the world angular velocity is omega = J_l(phi) dphi/dt."""
    phi = np.asarray(phi, dtype=float)
    K = skew(phi)
    _, b, c, _ = _series(np.sum(phi * phi, axis=-1))
    return np.eye(3) + b[..., None, None] * K + c[..., None, None] * (K @ K)


class StewartKinematics:
    """Inverse kinematics, Jacobians and a numerical forward kinematics for one geometry.

    Parameters
    ----------
    geometry : Geometry
        Attachment points and home height (see :mod:`ppod_ros.device.config`).
    """

    def __init__(self, geometry: Geometry):
        self.geometry = geometry
        self.base = np.asarray(geometry.base_points_m, dtype=float)
        self.plate = np.asarray(geometry.plate_points_m, dtype=float)
        self.home = np.array([0.0, 0.0, geometry.home_height_m])
        self.home_lengths_m = self.leg_lengths(np.zeros(6))

    @staticmethod
    def _pose(pose: np.ndarray) -> np.ndarray:
        pose = np.asarray(pose, dtype=float)
        if pose.shape[-1:] != (6,):
            raise ConfigError(
                f"pose: expected shape (..., 6) [px, py, pz, phi_x, phi_y, phi_z], got {pose.shape}"
            )
        return pose

    def attachment_points(self, pose: np.ndarray) -> np.ndarray:
        """Plate attachment points in the base frame, shape (..., 6, 3)."""
        pose = self._pose(pose)
        R = rotation_matrix(pose[..., 3:])
        rb = np.einsum("...ij,lj->...li", R, self.plate)
        return self.home + pose[..., None, :3] + rb

    def leg_vectors(self, pose: np.ndarray) -> np.ndarray:
        """Vectors from base to plate attachment, shape (..., 6, 3) (m)."""
        return self.attachment_points(pose) - self.base

    def leg_lengths(self, pose: np.ndarray) -> np.ndarray:
        """Exact leg lengths L_i(pose), shape (..., 6) (m)."""
        return np.linalg.norm(self.leg_vectors(pose), axis=-1)

    def leg_displacements(self, pose: np.ndarray) -> np.ndarray:
        """L_i(pose) - L_i(home), shape (..., 6) (m)."""
        return self.leg_lengths(pose) - self.home_lengths_m

    def twist_jacobian(self, pose: np.ndarray) -> np.ndarray:
        """dL/dt per unit [v, omega] (world velocity of P, world angular velocity), shape (..., 6, 6).

        Row i is ``[n_i, (R b_i) x n_i]`` with n_i the unit leg vector.
        """
        pose = self._pose(pose)
        legs = self.leg_vectors(pose)
        n = legs / np.linalg.norm(legs, axis=-1, keepdims=True)
        rb = np.einsum("...ij,lj->...li", rotation_matrix(pose[..., 3:]), self.plate)
        return np.concatenate([n, cross(rb, n)], axis=-1)

    def jacobian(self, pose: np.ndarray | None = None) -> np.ndarray:
        """dL/dpose, exact, shape (..., 6, 6); at the home pose (default) ``[n_i, b_i x n_i]``."""
        pose = np.zeros(6) if pose is None else self._pose(pose)
        Jt = self.twist_jacobian(pose)
        Jl = left_jacobian(pose[..., 3:])
        return np.concatenate([Jt[..., :3], Jt[..., 3:] @ Jl], axis=-1)

    def forward(
        self,
        lengths_m: np.ndarray,
        guess: np.ndarray | None = None,
        *,
        tol_m: float = 1e-13,
        max_iter: int = 50,
    ) -> np.ndarray:
        """Numerical forward kinematics: the pose whose legs have ``lengths_m`` (6,), by Newton's method.

        Raises
        ------
        SolverError
            When Newton's method does not converge from ``guess`` (default: the home pose).
        """
        target = check_array(lengths_m, "lengths_m", shape=(6,), min_value=0.0, unit="m")
        pose = np.zeros(6) if guess is None else check_array(guess, "guess", shape=(6,)).copy()
        for _ in range(max_iter):
            r = self.leg_lengths(pose) - target
            if np.max(np.abs(r)) <= tol_m:
                return pose
            pose = pose - np.linalg.solve(self.jacobian(pose), r)
        raise SolverError(
            f"forward kinematics did not converge to {tol_m:g} m in {max_iter} iterations "
            f"(residual {np.max(np.abs(r)):.3g} m)"
        )


@dataclass(frozen=True)
class LegTrajectory:
    """Leg displacements of a plate motion over one period, from the exact inverse kinematics.

    Attributes
    ----------
    k : ndarray, shape (K,)
        Harmonics 1..K.
    harmonics_m : complex ndarray, shape (K, 6)
        Leg displacement phasors (m), same convention as the plate motion.
    mean_m : ndarray, shape (6,)
        Mean leg displacement over the cycle (a second-order offset) (m).
    peak_m : ndarray, shape (6,)
        Peak |L_i(t) - L_i(home)| over the cycle (m).
    samples_m : ndarray, shape (N, 6)
        The sampled displacements at t_n = n T / N.
    """

    k: np.ndarray
    harmonics_m: np.ndarray
    mean_m: np.ndarray
    peak_m: np.ndarray
    samples_m: np.ndarray


def motion_samples_per_cycle(motion: PlateMotion, kmax: int) -> int:
    """Samples per period resolving ``kmax`` harmonics and the peaks (>= 64 per top-harmonic period)."""
    top = int(motion.k.max()) if motion.num_harmonics else 1
    return int(max(256, 64 * top, 4 * kmax + 4))


def leg_trajectory(
    kin: StewartKinematics, motion: PlateMotion, kmax: int | None = None, n_samples: int | None = None
) -> LegTrajectory:
    """Apply the exact inverse kinematics to ``motion``'s displacement over one period.

    Parameters
    ----------
    kin : StewartKinematics
    motion : PlateMotion
    kmax : int, optional
        Highest leg harmonic to report (default: twice the motion's highest harmonic, which holds
        the second-order terms).
    n_samples : int, optional
        Samples per period (default :func:`motion_samples_per_cycle`).
    """
    return leg_trajectories(kin, [motion], kmax, n_samples)[0]


def leg_trajectories(
    kin: StewartKinematics, motions: Sequence[PlateMotion], kmax: int | None = None, n_samples: int | None = None
) -> list[LegTrajectory]:
    """:func:`leg_trajectory` of motions of one frequency and one set of harmonics, in one vectorised
    pass (each motion's numbers are those it has alone: the arithmetic is elementwise per sample, and
    the transform per leg)."""
    motions = list(motions)
    first = motions[0]
    if any(m.frequency_hz != first.frequency_hz or not np.array_equal(m.k, first.k) for m in motions[1:]):
        raise ConfigError("motions: leg_trajectories needs one frequency and one set of harmonics")
    top = int(first.k.max()) if first.num_harmonics else 1
    kmax = 2 * top if kmax is None else int(kmax)
    n = motion_samples_per_cycle(first, kmax) if n_samples is None else int(n_samples)
    t = cycle_phases(n) / first.omega
    S = len(motions)
    delta = kin.leg_displacements(np.stack([m.displacement(t) for m in motions]))  # (S, n, 6)
    harmonics = analyze(delta.transpose(1, 0, 2).reshape(n, S * 6), kmax).reshape(kmax, S, 6)
    mean, peak = delta.mean(axis=1), np.max(np.abs(delta), axis=1)
    k = np.arange(1, kmax + 1)
    return [LegTrajectory(k=k, harmonics_m=harmonics[:, i], mean_m=mean[i], peak_m=peak[i], samples_m=delta[i])
            for i in range(S)]


__all__ = [
    "LegTrajectory",
    "StewartKinematics",
    "leg_trajectory",
    "leg_trajectories",
    "left_jacobian",
    "motion_samples_per_cycle",
    "rotation_and_left_jacobian",
    "rotation_matrix",
    "skew",
    "cross",
]

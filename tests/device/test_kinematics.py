"""Stewart kinematics: exact IK against a numerical FK, Jacobians against finite differences."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ppod_ros.device import default_device_config
from ppod_ros.errors import SolverError
from ppod_ros.kinematics.stewart import (
    StewartKinematics,
    left_jacobian,
    leg_trajectories,
    leg_trajectory,
    rotation_and_left_jacobian,
    rotation_matrix,
)
from ppod_ros.motion import PlateMotion

KIN = StewartKinematics(default_device_config().geometry)
LINESINKX = PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0])

# Poses within a few millimetres and tens of milliradians (far beyond the plate's sub-mm motion).
poses = st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6).map(
    lambda v: np.array(v) * np.array([3e-3, 3e-3, 3e-3, 3e-2, 3e-2, 3e-2])
)


def test_home_pose_gives_the_configured_leg_lengths():
    g = default_device_config().geometry
    expected = np.linalg.norm(g.plate_points_m + [0, 0, g.home_height_m] - g.base_points_m, axis=1)
    assert np.allclose(KIN.leg_lengths(np.zeros(6)), expected, rtol=0, atol=1e-15)
    assert np.allclose(KIN.leg_displacements(np.zeros(6)), 0.0)


def test_rotation_matrix_is_orthonormal_and_matches_rodrigues_about_an_axis():
    phi = np.array([0.0, 0.0, 0.3])
    R = rotation_matrix(phi)
    c, s = np.cos(0.3), np.sin(0.3)
    assert np.allclose(R, [[c, -s, 0], [s, c, 0], [0, 0, 1]])
    many = rotation_matrix(np.random.default_rng(0).normal(size=(10, 3)))
    assert np.allclose(many @ np.swapaxes(many, 1, 2), np.eye(3), atol=1e-12)
    assert np.allclose(rotation_matrix(np.zeros(3)), np.eye(3))


def test_left_jacobian_maps_rotation_vector_rates_to_angular_velocity():
    rng = np.random.default_rng(1)
    phi, dphi = rng.normal(size=3) * 0.4, rng.normal(size=3)
    h = 1e-6
    R0, R1 = rotation_matrix(phi - h * dphi), rotation_matrix(phi + h * dphi)
    Rdot = (R1 - R0) / (2 * h)
    W = Rdot @ rotation_matrix(phi).T  # [omega]x in the world frame
    omega = np.array([W[2, 1], W[0, 2], W[1, 0]])
    assert np.allclose(left_jacobian(phi) @ dphi, omega, atol=1e-8)
    R, Jl = rotation_and_left_jacobian(phi)
    assert np.allclose(R, rotation_matrix(phi)) and np.allclose(Jl, left_jacobian(phi))


@settings(max_examples=60, deadline=None)
@given(poses)
def test_forward_kinematics_inverts_the_exact_inverse_kinematics(pose):
    lengths = KIN.leg_lengths(pose)
    found = KIN.forward(lengths)
    assert np.allclose(found, pose, rtol=0, atol=1e-11)
    assert np.allclose(KIN.leg_lengths(found), lengths, rtol=0, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(poses)
def test_jacobian_equals_central_finite_differences_at_any_pose(pose):
    J = KIN.jacobian(pose)
    h = 1e-7
    fd = np.stack(
        [(KIN.leg_lengths(pose + h * e) - KIN.leg_lengths(pose - h * e)) / (2 * h) for e in np.eye(6)], 1
    )
    assert np.allclose(J, fd, rtol=0, atol=1e-7)


def test_small_motion_limit_of_the_exact_ik_is_the_jacobian():
    rng = np.random.default_rng(2)
    direction = rng.normal(size=6) * np.array([1e-3, 1e-3, 1e-3, 1e-2, 1e-2, 1e-2])
    J0 = KIN.jacobian()
    errors = []
    for eps in [1e-1, 1e-2, 1e-3]:
        dl = KIN.leg_displacements(eps * direction)
        errors.append(np.max(np.abs(dl - eps * J0 @ direction)) / eps)
    # The residual of the linearisation shrinks like eps (second-order remainder).
    assert errors[1] < errors[0] / 5 and errors[2] < errors[1] / 5
    assert errors[2] < 1e-6


def test_twist_jacobian_gives_leg_rates_from_the_world_velocity():
    pose = np.array([1e-3, -2e-3, 5e-4, 0.01, -0.02, 0.015])
    twist = np.array([0.01, 0.02, -0.03, 0.5, -0.2, 0.3])  # v (m/s), omega (rad/s)
    h = 1e-7
    # Move the pose along the twist: p += v h, R <- exp([omega h]) R.
    R_next = rotation_matrix(twist[3:] * h) @ rotation_matrix(pose[3:])
    from scipy.spatial.transform import Rotation

    phi_next = Rotation.from_matrix(R_next).as_rotvec()
    pose_next = np.concatenate([pose[:3] + twist[:3] * h, phi_next])
    rate = (KIN.leg_lengths(pose_next) - KIN.leg_lengths(pose)) / h
    assert np.allclose(KIN.twist_jacobian(pose) @ twist, rate, atol=1e-6)


def test_forward_kinematics_reports_non_convergence():
    with pytest.raises(SolverError, match="did not converge"):
        KIN.forward(KIN.home_lengths_m * 3, max_iter=3)


def test_leg_trajectory_first_harmonic_is_the_jacobian_of_the_pose_phasors():
    legs = leg_trajectory(KIN, LINESINKX)
    omega = LINESINKX.omega
    pose_phasor = -LINESINKX.phasor_table(1)[0] / omega**2  # displacement = -X / Omega^2
    linear = KIN.jacobian() @ pose_phasor
    assert np.allclose(legs.harmonics_m[0], linear, rtol=2e-3, atol=1e-9)
    # Second-order terms: a mean offset and a second harmonic, small against the first harmonic.
    first = np.max(np.abs(legs.harmonics_m[0]))
    assert 0 < np.max(np.abs(legs.harmonics_m[1])) < 0.01 * first
    assert 0 < np.max(np.abs(legs.mean_m)) < 0.01 * first
    assert np.allclose(legs.peak_m, np.max(np.abs(legs.samples_m), axis=0))
    assert legs.samples_m.shape[0] >= 256


def test_leg_trajectories_of_several_motions_are_each_motions_own_bit_for_bit():
    """The checker batches the exact stroke of the motions it checks together; each motion's numbers
    must not depend on the others (the planner remembers reports of motions checked before)."""
    from ppod_ros.errors import ConfigError

    rng = np.random.default_rng(3)
    for k in ([1], [1, 2]):
        motions = [PlateMotion.from_phasors(30.0, k, (rng.normal(size=(len(k), 6)) + 1j * rng.normal(size=(len(k), 6)))
                                            * [2, 2, 1, 20, 20, 20]) for _ in range(3)]
        for motion, together in zip(motions, leg_trajectories(KIN, motions)):
            alone = leg_trajectory(KIN, motion)
            for name in ("k", "harmonics_m", "mean_m", "peak_m", "samples_m"):
                assert np.array_equal(getattr(alone, name), getattr(together, name)), name
    with pytest.raises(ConfigError, match="one frequency"):
        leg_trajectories(KIN, [LINESINKX, PlateMotion.single(35, [10, 0, 0, 0, 100, 0], [0] * 6)])

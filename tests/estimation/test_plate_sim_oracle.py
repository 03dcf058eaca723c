"""The test oracle itself: exact rotations and derivatives, and the first-order limit."""

import numpy as np

from ppod_ros.estimation import AccelerometerLayout, AccelEstimator, cycle_times
from tests.estimation.plate_sim import first_order_readings, plate_pose, readings, sample_times

LAYOUT = AccelerometerLayout.default()
U = np.array([[3, -2, 1, 40, -60, 30], [1, 0.5, -1, 10, 5, -8]]) * np.exp(1j * np.arange(12).reshape(2, 6))


def test_oracle_rotation_is_orthonormal_and_its_derivatives_match_finite_differences():
    t = np.array([0.0123, 0.0456])
    h = 1e-5
    _, R, Rd, Rdd = plate_pose(U, [1, 2], 20.0, t)
    np.testing.assert_allclose(
        np.einsum("nij,nkj->nik", R, R), np.broadcast_to(np.eye(3), R.shape), atol=1e-14
    )
    _, Rp, _, _ = plate_pose(U, [1, 2], 20.0, t + h)
    _, Rm, _, _ = plate_pose(U, [1, 2], 20.0, t - h)
    np.testing.assert_allclose((Rp - Rm) / (2 * h), Rd, atol=1e-5 * np.abs(Rd).max())
    np.testing.assert_allclose((Rp - 2 * R + Rm) / h**2, Rdd, atol=2e-4 * np.abs(Rdd).max())


def test_oracle_reduces_to_the_first_order_model_for_vanishing_motion():
    t = sample_times(20.0, 1, 2000)
    small = U * 1e-6
    exact = readings(small, [1, 2], 20.0, t, LAYOUT.position_m, LAYOUT.axis, gravity=0.0)
    first = first_order_readings(small, [1, 2], 20.0, t, LAYOUT.position_m, LAYOUT.axis)
    np.testing.assert_allclose(exact, first, atol=1e-7 * np.abs(first).max())


def test_sample_indices_within_cycles_give_the_same_estimate_as_times():
    cycle = np.repeat(np.arange(5), 200)
    index = np.tile(np.arange(200), 5)
    t = cycle_times(cycle, index, 200, 20.0)
    np.testing.assert_allclose(t, np.arange(1000) / 4000)
    r = readings(U, [1, 2], 20.0, t, LAYOUT.position_m, LAYOUT.axis)
    est = AccelEstimator(LAYOUT).from_samples(t, r, 20.0)
    np.testing.assert_allclose(est.table(2), U, atol=5e-4 * np.abs(U).max())

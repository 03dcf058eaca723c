"""The nominal plant: frequency response, its inverse (feed-forward) and its physical limits."""

import math

import numpy as np
import pytest

from ppod_ros.actuation.harmonics import analyze, cycle_phases, peak_abs, rms, synthesize, to_dense
from ppod_ros.actuation.plant import NominalPlant, rigid_body_mass_matrix
from ppod_ros.device import default_device_config
from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion

CFG = default_device_config()
PLANT = NominalPlant(CFG)
LINESINKX = PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0])


def test_frequency_response_has_the_documented_shape_and_broadcasts():
    assert PLANT.frequency_response(30.0).shape == (6, 6)
    G = PLANT.frequency_response(np.array([[20.0, 30.0], [40.0, 60.0]]))
    assert G.shape == (2, 2, 6, 6) and G.dtype == complex
    assert np.allclose(G[0, 1], PLANT.frequency_response(30.0))


def test_remembered_solves_equal_a_fresh_solve_and_callers_cannot_change_them():
    # responses() remembers (sI - A)^-1 B per set of frequencies (the checker asks for the same few
    # harmonics for every motion): the answer is the fresh solve's, bit for bit, and what a caller does
    # to its copy never reaches the next caller; the state space it was solved from cannot change.
    plant = NominalPlant(CFG)
    f = np.array([30.0, 60.0])
    s = 2j * math.pi * f[:, None, None]
    nx = plant.A.shape[0]
    X = np.linalg.solve(s * np.eye(nx) - plant.A, np.broadcast_to(plant.B[:, :6], (2, nx, 6)))
    Cy, Dy = plant.output_matrices("accel")
    first = plant.responses(f, ("accel", "voltage"))
    assert np.array_equal(first["accel"], Cy @ X + Dy[:, :6])
    first["accel"][:] = 0.0
    again = plant.responses(f.copy(), ("accel",))["accel"]
    assert np.array_equal(again, Cy @ X + Dy[:, :6])
    assert not np.array_equal(plant.response(np.array([30.0, 90.0]))[1], again[1])   # keyed by the frequencies
    with pytest.raises(ValueError):
        plant.A[0, 0] = 1.0


def test_frequency_response_rejects_non_positive_frequencies():
    for bad in (0.0, -30.0, math.nan):
        with pytest.raises(ConfigError, match="freq_hz"):
            PLANT.frequency_response(bad)


def test_inverse_response_inverts_the_frequency_response():
    f = np.array([20.0, 45.0, 120.0])
    assert np.allclose(PLANT.inverse_response(f) @ PLANT.frequency_response(f), np.eye(6), atol=1e-9)


def test_far_above_the_suspension_modes_the_plate_is_mass_controlled():
    # Well above the flexure modes and below the current loop: a = M^-1 J^T k_f i.
    f = 150.0
    G = PLANT.frequency_response(f)
    expected = np.linalg.solve(PLANT.M, PLANT.J.T * CFG.actuators.force_constant_n_per_a)
    wc = CFG.actuators.current_loop_bandwidth_hz
    lag = 1 / (1 + 1j * f / wc)
    assert np.allclose(G, expected * lag, rtol=0.08, atol=0.08 * np.abs(expected).max())


def test_mass_matrix_of_a_point_mass_offset_below_the_origin():
    from ppod_ros.device.config import PlateParams

    p = PlateParams(2.0, np.array([0.0, 0.0, -0.1]), np.zeros((3, 3)) + np.eye(3) * 1e-9, 0.1)
    M = rigid_body_mass_matrix(p)
    # Angular acceleration alpha_x about the origin moves the mass along +y: a = alpha x c.
    alpha = np.array([0, 0, 0, 1.0, 0, 0])
    force = M @ alpha
    assert np.allclose(force[:3], 2.0 * np.cross([1.0, 0, 0], [0, 0, -0.1]))
    assert np.allclose(M, M.T)


def test_feedforward_currents_reproduce_the_goal_through_the_nominal_model():
    motion = PlateMotion(
        40.0, [1, 2], [[3, 1, 2, 10, 20, 30], [1, 0.5, 0, 5, 0, 8]], [[0, 1, 2, 3, 4, 5], [1, 0, 2, 0, 1, 0]]
    )
    table = PLANT.feedforward(motion, kmax=3)
    assert table.shape == (3, 6) and np.all(table[2] == 0)
    achieved = PLANT.predict(40.0, table, "accel")
    assert np.allclose(achieved, motion.phasor_table(3), atol=1e-9)


def test_feedforward_needs_a_table_big_enough_for_the_goal():
    with pytest.raises(ConfigError, match="kmax"):
        PLANT.feedforward(PlateMotion(30.0, [3], [[1, 0, 0, 0, 0, 0]], [[0] * 6]), kmax=2)


def test_linesinkx_needs_about_a_newton_metre_class_drive_within_the_default_limits():
    table = PLANT.feedforward(LINESINKX, kmax=1)
    peak = peak_abs(table, [1])
    volts = np.abs(PLANT.predict(30.0, table, "voltage"))
    legs = np.abs(PLANT.predict(30.0, table, "leg"))
    assert np.all(peak < CFG.limits.coil_current_a / 2) and np.all(peak > 0.2)
    assert np.all(volts < CFG.limits.amplifier_voltage_v / 2)
    assert np.all(legs < CFG.limits.leg_stroke_m / 2)


def test_modes_are_lightly_damped_suspension_modes_below_the_working_band():
    modes = PLANT.modes()
    assert len(modes) == 6
    assert all(3 < m.frequency_hz < 18 and 0 < m.damping_ratio < 0.3 for m in modes)


def test_harmonic_analysis_inverts_synthesis():
    rng = np.random.default_rng(0)
    table = rng.normal(size=(4, 3)) + 1j * rng.normal(size=(4, 3))
    k = np.array([1, 2, 3, 4])
    theta = cycle_phases(64)
    y = synthesize(table, k, theta)
    assert np.allclose(analyze(y, 4), table)
    # Convention: a pure sine of phase phi has phasor A e^{i phi}.
    assert np.allclose(analyze(2.0 * np.sin(theta + 0.3), 1)[0], 2.0 * np.exp(0.3j))
    assert np.allclose(rms(table), np.sqrt(np.mean(y**2, axis=0)))
    assert np.all(peak_abs(table, k) <= np.sum(np.abs(table), axis=0) + 1e-12)
    assert np.allclose(to_dense(np.array([2]), table[:1], 3)[1], table[0])
    with pytest.raises(ConfigError):
        analyze(y, 40)

"""The simulated plant: exact discretisation, exact geometry, against independent references."""

import numpy as np
import pytest

from ppod_ros.actuation.harmonics import analyze, synthesize
from ppod_ros.actuation.plant import NominalPlant
from ppod_ros.device import default_device_config
from ppod_ros.motion import PlateMotion
from ppod_sim.plant import PlantSimulator, foh_discretise
from tests.device.device_reference_plant import reference_run

CFG = default_device_config()
PLANT = NominalPlant(CFG)
LINESINKX = PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0])
STEPS_PER_CYCLE, CHUNK, EVERY = 280, 40, 4


def drive(sim, table, cycles, freq=30.0):
    """Play a (K, 6) current table from rest; returns the reported states and plate-frame accelerations."""
    dt = 1.0 / freq / STEPS_PER_CYCLE
    k = np.arange(1, table.shape[0] + 1)
    states, accel, refs = [], [], []
    for c in range(cycles * STEPS_PER_CYCLE // CHUNK):
        n = np.arange(c * CHUNK, (c + 1) * CHUNK + 1)
        ref = synthesize(table, k, 2 * np.pi * n / STEPS_PER_CYCLE)
        res = sim.simulate(ref, dt, every=EVERY)
        states.append(res.x)
        accel.append(res.accel_plate)
        refs.append(ref[:-1])
    return np.concatenate(states), np.concatenate(accel), np.concatenate(refs), dt


def block_scale(ref):
    """Per-column scale: the largest value of the column's block (same units and size)."""
    scale = np.empty(ref.shape[1])
    for lo, hi in [(0, 3), (3, 6), (6, 9), (9, 12), (12, 18), (18, 24)][: ref.shape[1] // 3]:
        scale[lo:hi] = np.max(np.abs(ref[:, lo:hi]))
    return scale


def test_foh_discretisation_is_exact_for_a_ramp_input():
    A = np.array([[0.0, 1.0], [-4.0, -0.4]])
    B = np.array([[0.0], [1.0]])
    dt = 0.05
    Phi, G0, G1 = foh_discretise(A, B, dt)
    from scipy.integrate import solve_ivp

    sol = solve_ivp(
        lambda t, x: A @ x + B[:, 0] * (1.0 + 3.0 * t / dt), (0, dt), [0.3, -0.2], rtol=1e-12, atol=1e-14
    )
    assert np.allclose(Phi @ [0.3, -0.2] + G0[:, 0] * 1.0 + G1[:, 0] * 4.0, sol.y[:, -1], atol=1e-11)


def test_linear_simulation_equals_the_continuous_model_with_interpolated_references():
    sim = PlantSimulator(CFG, exact_geometry=False)
    table = PLANT.feedforward(LINESINKX, 1)
    states, _, refs, dt = drive(sim, table, cycles=2)
    t_grid = np.arange(refs.shape[0] + 1) * dt
    ref_full = np.vstack([refs, synthesize(table, [1], [2 * np.pi * refs.shape[0] / STEPS_PER_CYCLE])])
    ref = reference_run(CFG, t_grid, ref_full, exact=False, substeps=16)
    rows = np.arange(0, refs.shape[0], EVERY)
    assert np.max(np.abs(states - ref[rows]) / block_scale(ref)) < 1e-7


def exact_run_errors(scale_factor):
    """Max relative state errors of the exact and the linear simulated plant against the reference."""
    table = PLANT.feedforward(LINESINKX, 1) * scale_factor
    states, _, refs, dt = drive(PlantSimulator(CFG, exact_geometry=True), table, cycles=1)
    linear_states = drive(PlantSimulator(CFG, exact_geometry=False), table, cycles=1)[0]
    t_grid = np.arange(refs.shape[0] + 1) * dt
    ref_full = np.vstack([refs, synthesize(table, [1], [2 * np.pi * refs.shape[0] / STEPS_PER_CYCLE])])
    ref = reference_run(CFG, t_grid, ref_full, exact=True, substeps=2)[np.arange(0, refs.shape[0], EVERY)]
    scale = block_scale(ref[:, :12])
    err_exact = np.max(np.abs(states[:, :12] - ref[:, :12]) / scale)
    err_linear = np.max(np.abs(linear_states[:, :12] - ref[:, :12]) / scale)
    return err_exact, err_linear


@pytest.mark.slow
def test_exact_geometry_simulation_matches_the_nonlinear_equations():
    err1, lin1 = exact_run_errors(1.0)
    err2, lin2 = exact_run_errors(2.0)
    # The linearised plant misses second-order terms (error grows like the motion) ...
    assert lin1 > 5e-3 and lin2 / lin1 == pytest.approx(2.0, rel=0.2)
    # ... the simulated exact plant has them: what remains is the third-order remainder of its
    # single Picard step (grows like the motion squared), 1/300 of the linear plant's error here.
    assert err1 < 5e-5 and err1 < lin1 / 300
    assert err2 / err1 == pytest.approx(4.0, rel=0.3)


def test_exact_terms_are_second_order_in_the_motion():
    sim = PlantSimulator(CFG, exact_geometry=True)
    rng = np.random.default_rng(3)
    X = np.zeros((1, 24))
    X[0, :12] = rng.normal(size=12) * np.r_[[1e-4] * 3, [1e-3] * 3, [0.02] * 3, [0.2] * 3]
    X[0, 12:18] = rng.normal(size=6)
    qdd = rng.normal(size=(1, 6)) * np.r_[[10.0] * 3, [100.0] * 3]
    sizes = []
    for s in [1.0, 0.1]:
        f_d, v_d = sim._disturbance(X * s, qdd * s)
        sizes.append(np.max(np.abs(f_d)))
    assert sizes[1] < sizes[0] / 50  # quadratic: a tenth of the motion gives a hundredth


def test_steady_state_of_the_linear_plant_is_the_nominal_frequency_response():
    sim = PlantSimulator(CFG, exact_geometry=False)
    table = PLANT.feedforward(LINESINKX, 1)
    _, accel, _, _ = drive(sim, table, cycles=90)
    last = accel[-STEPS_PER_CYCLE // EVERY :]
    achieved = analyze(last, 3)
    goal = LINESINKX.phasor_table(3)
    # The device interpolates the references linearly between control steps, which passes the
    # fundamental at sinc^2(pi / 280) = 1 - 4.2e-5; transients (10-16 % damping) are gone after 3 s.
    assert np.allclose(achieved[0], goal[0], rtol=1e-4, atol=1e-4)
    assert np.max(np.abs(achieved[2])) < 2e-3


def test_truth_is_expressed_in_the_tilted_plate_frame():
    sim = PlantSimulator(CFG, exact_geometry=True)
    table = PLANT.feedforward(LINESINKX, 1)
    _, accel, _, _ = drive(sim, table, cycles=3)
    # R^T p'' of the tilting plate: the pitch phi_y = -alpha_y / Omega^2 turns p''x into p''z at 2 Omega.
    second = analyze(accel[-STEPS_PER_CYCLE // EVERY :], 3)[1]
    expected = 10 * 100 / (2 * (2 * np.pi * 30) ** 2)  # |phi_y| |p''x| / 2
    assert abs(second[2]) == pytest.approx(expected, rel=0.5)


def test_a_cycles_motion_in_absolute_time_is_the_time_shifted_one():
    from ppod_sim.truth import CycleTruth

    X = np.array([[1.0 + 2.0j, 0, 3.0j, 0, 0, 0.5], [0.2, 0.1j, 0, 0, 0, 0]])
    z = np.zeros(6)
    truth = CycleTruth(7, 0.23, 30.0, 0, 1.0, X, np.zeros((1, 6)), z, z, z, z)
    t = np.linspace(0.0, 0.1, 17)
    shifted = truth.motion().time_shifted(-truth.start_time_s)
    assert np.allclose(truth.motion(absolute_time=True).acceleration(t), shifted.acceleration(t), atol=1e-12)

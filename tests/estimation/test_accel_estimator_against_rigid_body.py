"""The estimator against the independent rigid-body simulation (tests/estimation/plate_sim.py)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ppod_ros.estimation import SECOND_ORDER_TERMS, AccelerometerLayout, AccelEstimator, fit_harmonics
from ppod_ros.estimation.second_order import second_order_phasors
from ppod_ros.motion import PlateMotion, acceleration_error
from tests.estimation.plate_sim import first_order_readings, readings, sample_times

LAYOUT = AccelerometerLayout.default()
LINE_SINK_X = PlateMotion(
    30, [1], [[10, 0, 0, 0, 100, 0]], [[0, 0, 0, 0, 3 * math.pi / 2, 0]], name="LineSinkX"
)
#: MEMS accelerometer noise, RMS per sample at 5 kHz (about 10 mg): realistic to pessimistic.
NOISE_MPS2 = 0.1
RATE_HZ = 5000.0


def _record(motion, cycles=None, noise=0.0, seed=0, start_s=0.0):
    """Simulated readings over ``cycles`` periods (default: a third of a second, 10 cycles at 30 Hz)."""
    K = int(motion.k.max())
    cycles = motion.frequency_hz / 3 if cycles is None else cycles
    t = sample_times(motion.frequency_hz, cycles, RATE_HZ, start_s)
    r = readings(
        motion.phasor_table(K), np.arange(1, K + 1), motion.frequency_hz, t, LAYOUT.position_m, LAYOUT.axis
    )
    return t, r + np.random.default_rng(seed).normal(0.0, noise, r.shape)


def _relative_error(motion, estimate, kmax=6):
    return acceleration_error(motion.phasor_table(kmax), estimate.table(kmax))[1]


MOTIONS = {
    "LineSinkX": LINE_SINK_X,
    "rotation": PlateMotion(
        25, [1], [[6, 6, 2, 0, 0, 80]], [[0, math.pi / 2, 0, 0, 0, 1.0]], name="rotation"
    ),
    "two harmonics": PlateMotion(
        20, [1, 2], [[8, 2, 3, 40, 60, 30], [2, 1, 1, 10, 15, 5]], [[0, 1, 2, 3, 4, 5], [1, 0, 2, 1, 0, 2]]
    ),
    "tilt at 8 Hz": PlateMotion(8, [1], [[0, 0, 1, 0, 20, 0]], [[0, 0, 0, 0, 0.5, 0]]),
}


@pytest.mark.parametrize("name", list(MOTIONS))
def test_noise_free_estimate_matches_the_rigid_body_truth_to_third_order(name):
    motion = MOTIONS[name]
    t, r = _record(motion)
    est = AccelEstimator(LAYOUT).from_samples(t, r, motion.frequency_hz)
    assert _relative_error(motion, est) < 2e-5
    assert est.last_change < 1e-8 and not est.dropped


def test_first_order_estimate_is_off_by_the_tilt_and_second_order_terms_that_the_correction_removes():
    t, r = _record(LINE_SINK_X)
    plain = AccelEstimator(LAYOUT, second_order_terms=(), gravity_mps2=0.0).from_samples(t, r, 30)
    corrected = AccelEstimator(LAYOUT).from_samples(t, r, 30)
    # PHYSICS.md: the tilted gravity is about 0.3 % of p''x and the centripetal term about 0.5 % of
    # the fundamental at twice the frequency for LineSinkX.
    tilt = abs(plain.phasors[0, 0] - LINE_SINK_X.phasors()[0, 0]) / 10
    assert 0.002 < tilt < 0.004
    second = np.linalg.norm(plain.phasors[1] * [1, 1, 1, 0.1, 0.1, 0.1]) / np.linalg.norm([10, 10])
    assert second > 0.001
    assert _relative_error(LINE_SINK_X, plain) > 0.002
    assert _relative_error(LINE_SINK_X, corrected) < 2e-5
    assert corrected.second_order_mps2[1] > 0.01  # what was removed at 2 Omega, reported


def test_gravity_tilt_sign_matches_the_specific_force_in_the_tilted_frame():
    # A slow pure pitch: g / Omega^2 is 3.9 mm at 8 Hz, so the tilt term is a large share of the
    # tangential readings, and a sign error would be glaring.
    motion = PlateMotion(8, [1], [[0, 0, 0, 0, 20, 0]], [[0, 0, 0, 0, 0, 0]])
    t, r = _record(motion)
    fit = fit_harmonics(t, r, 8, 2)
    H = LAYOUT.measurement_matrix(2 * math.pi * 8, 9.81)
    np.testing.assert_allclose(
        fit.phasors[0], H @ motion.phasors()[0], atol=2e-3 * np.abs(fit.phasors[0]).max()
    )
    wrong = LAYOUT.measurement_matrix(2 * math.pi * 8, -9.81)
    assert np.abs(fit.phasors[0] - wrong @ motion.phasors()[0]).max() > 0.05


def test_second_order_phasors_match_what_the_simulation_adds_to_the_first_order_model():
    # A one-harmonic motion in all six axes: the second-order terms sit at 0 and 2 Omega, the
    # third-order ones at Omega and 3 Omega, so harmonic 2 compares the second-order model alone.
    motion = PlateMotion(20, [1], [[8, 5, 3, 60, 80, 50]], [[0, 1, 2, 3, 4, 5]])
    t = sample_times(20, 4, RATE_HZ)
    U = motion.phasor_table(1)
    exact = fit_harmonics(t, readings(U, [1], 20, t, LAYOUT.position_m, LAYOUT.axis), 20, 3)
    first = fit_harmonics(t, first_order_readings(U, [1], 20, t, LAYOUT.position_m, LAYOUT.axis), 20, 3)
    model = second_order_phasors(np.vstack([U, np.zeros((2, 6))]), 20, LAYOUT.position_m, LAYOUT.axis)
    seen = exact.phasors[1] - first.phasors[1]
    assert np.abs(seen).max() > 0.02  # the terms are not negligible here
    np.testing.assert_allclose(model[1], seen, atol=1e-3 * np.abs(seen).max())
    np.testing.assert_allclose(model[[0, 2]], 0, atol=1e-12)  # products of one harmonic are even


@pytest.mark.parametrize(
    ("term", "motion"),
    [
        ("centripetal", "LineSinkX"),
        ("frame", "rotation"),
        ("euler", "two harmonics"),
        ("gravity", "tilt at 8 Hz"),
    ],
)
def test_each_second_order_term_is_needed_to_match_the_simulation(term, motion):
    m = MOTIONS[motion]
    t, r = _record(m)
    full = _relative_error(m, AccelEstimator(LAYOUT).from_samples(t, r, m.frequency_hz))
    terms = tuple(x for x in SECOND_ORDER_TERMS if x != term)
    without = _relative_error(
        m, AccelEstimator(LAYOUT, second_order_terms=terms).from_samples(t, r, m.frequency_hz)
    )
    assert without > 5 * full


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_line_sink_estimate_with_realistic_noise_is_within_0_2_percent_of_the_goal_norm(seed):
    t, r = _record(LINE_SINK_X, cycles=10, noise=NOISE_MPS2, seed=seed)
    est = AccelEstimator(LAYOUT).from_samples(t, r, 30)
    assert _relative_error(LINE_SINK_X, est) <= 0.002
    assert not est.dropped
    # The reported noise matches the actual scatter within a factor of two.
    err = np.abs(est.table(6) - LINE_SINK_X.phasor_table(6))
    ratio = np.sqrt(np.mean(err**2)) / np.sqrt(np.mean(est.std**2))
    assert 0.5 < ratio < 2.0


@settings(max_examples=15, deadline=None)
@given(
    freq=st.floats(20, 60),
    amp=st.lists(st.floats(0, 1), min_size=6, max_size=6),
    phase=st.lists(st.floats(0, 2 * math.pi), min_size=6, max_size=6),
    start_cycles=st.floats(0, 3),
    cycles=st.floats(2.2, 6),
)
def test_random_motions_are_recovered_from_any_start_and_partial_cycles(
    freq, amp, phase, start_cycles, cycles
):
    amplitude = np.array(amp) * [10, 10, 10, 100, 100, 100]
    if not np.any(amplitude > 1):
        amplitude[0] = 5.0
    motion = PlateMotion(freq, [1], [amplitude], [phase])
    t, r = _record(motion, cycles=cycles, start_s=start_cycles / freq)
    est = AccelEstimator(LAYOUT).from_samples(t, r, freq)
    assert _relative_error(motion, est) < 1e-4

"""Dead, missing, stuck, saturated and inconsistent channels; missing samples and partial cycles."""

import math

import numpy as np
import pytest

from ppod_ros.errors import ConfigError, DeviceError
from ppod_ros.estimation import AccelerometerLayout, AccelEstimator, EstimationError
from ppod_ros.motion import PlateMotion, acceleration_error
from tests.estimation.plate_sim import readings, sample_times

LAYOUT = AccelerometerLayout.default()
GOAL = PlateMotion(30, [1], [[10, 0, 0, 0, 100, 0]], [[0, 0, 0, 0, 3 * math.pi / 2, 0]], name="LineSinkX")
NOISE_MPS2 = 0.1
T = sample_times(30, 10, 5000)
CLEAN = readings(GOAL.phasor_table(1), [1], 30, T, LAYOUT.position_m, LAYOUT.axis)


def _noisy(seed=0):
    return CLEAN + np.random.default_rng(seed).normal(0, NOISE_MPS2, CLEAN.shape)


def _error(est):
    return acceleration_error(GOAL.phasor_table(6), est.table(6))[1]


def _estimate(t, r, layout=LAYOUT):
    return AccelEstimator(layout).from_samples(t, r, 30)


@pytest.mark.parametrize("channel", range(12))
def test_a_channel_reading_zero_is_dropped_and_the_estimate_stays_within_0_2_percent(channel):
    r = _noisy(channel)
    r[:, channel] = 0.0
    est = _estimate(T, r)
    assert list(est.dropped) == [LAYOUT.names[channel]]
    assert "flat" in est.dropped[LAYOUT.names[channel]]
    assert _error(est) <= 0.002


def test_a_channel_dying_mid_record_is_dropped():
    r = _noisy(1)
    r[T.size // 2 :, 3] = 0.0
    est = _estimate(T, r)
    assert list(est.dropped) == ["u110.z"]
    assert _error(est) <= 0.002


def test_a_channel_dying_late_in_the_record_is_caught_by_its_fit_residual():
    r = _noisy(2)
    r[int(T.size * 0.8) :, 6] = 0.0
    est = _estimate(T, r)
    assert list(est.dropped) == ["u230.t"]
    assert "not periodic" in est.dropped["u230.t"] or "inconsistent" in est.dropped["u230.t"]
    assert _error(est) <= 0.002


def test_a_channel_of_nan_is_dropped_as_missing():
    r = _noisy(3)
    r[:, 8] = np.nan
    est = _estimate(T, r)
    assert est.dropped == {"u250.t": f"missing: 0 of {T.size} samples valid"}


def test_a_stuck_channel_that_repeats_its_values_is_dropped():
    r = _noisy(4)
    r[:, 5] = np.repeat(r[::20, 5], 20)[: T.size]
    est = _estimate(T, r)
    assert list(est.dropped) == ["u130.z"] and "stuck" in est.dropped["u130.z"]
    assert _error(est) <= 0.002


def test_a_saturated_channel_is_dropped():
    full_scale = np.full(12, 200.0)
    full_scale[1] = 12.0  # the vertical unit at 10 deg reads about 16.7 m/s^2: it clips
    layout = AccelerometerLayout(LAYOUT.names, LAYOUT.position_m, LAYOUT.axis, full_scale)
    r = _noisy(5)
    r[:, 1] = np.clip(r[:, 1], -12.0, 12.0)
    est = _estimate(T, r, layout)
    assert list(est.dropped) == ["u10.z"] and "saturated" in est.dropped["u10.z"]


def test_a_channel_reading_only_noise_is_dropped_as_inconsistent_without_dragging_a_good_one_along():
    r = _noisy(6)
    r[:, 5] = np.random.default_rng(60).normal(0, 0.3, T.size)
    est = _estimate(T, r)
    assert list(est.dropped) == ["u130.z"] and "inconsistent residual" in est.dropped["u130.z"]
    assert _error(est) <= 0.002


def test_a_channel_with_the_wrong_sign_is_dropped_as_inconsistent():
    r = _noisy(7)
    r[:, 2] *= -1
    est = _estimate(T, r)
    assert list(est.dropped) == ["u110.t"]
    assert _error(est) <= 0.002


def test_quiet_channels_that_read_what_the_others_predict_are_kept():
    # Pure vertical motion, noise-free: every tangential channel reads exactly zero (flat), which is
    # what the vertical channels predict, so none is dropped.
    bounce = PlateMotion(30, [1], [[0, 0, 5, 0, 0, 0]], [[0] * 6])
    r = readings(bounce.phasor_table(1), [1], 30, T, LAYOUT.position_m, LAYOUT.axis)
    assert np.ptp(r[:, 0]) < 1e-12
    est = _estimate(T, r)
    assert not est.dropped
    np.testing.assert_allclose(est.phasors[0], bounce.phasors()[0], atol=1e-9)


def test_too_many_dead_channels_raise_a_fault_naming_channels_and_the_unobservable_motion():
    r = _noisy(8)
    r[:, [1, 3, 5, 7]] = 0.0  # four of the six vertical channels
    with pytest.raises(EstimationError) as info:
        _estimate(T, r)
    assert isinstance(info.value, DeviceError)
    assert "u10.z" in str(info.value) and "flat" in str(info.value)
    assert info.value.channel_status["u350.z"] == "ok"


def test_dead_channels_beyond_what_the_layout_can_spare_raise_a_fault():
    r = _noisy(9)
    r[:, [0, 2, 4, 6]] = np.nan  # four of the six tangential channels
    with pytest.raises(EstimationError, match="no longer determine") as info:
        _estimate(T, r)
    assert "missing" in info.value.channel_status["u10.t"]
    assert "unobservable" in str(info.value)


def test_missing_samples_are_skipped():
    r = _noisy(10)
    r[np.random.default_rng(11).random(r.shape) < 0.25] = np.nan
    est = _estimate(T, r)
    assert not est.dropped
    assert _error(est) <= 0.002


@pytest.mark.parametrize(("start_cycles", "cycles"), [(0.0, 2.6), (0.37, 3.3), (5.81, 1.4)])
def test_partial_cycles_from_any_start_give_the_motion(start_cycles, cycles):
    t = sample_times(30, cycles, 5000, start_cycles / 30)
    r = readings(GOAL.phasor_table(1), [1], 30, t, LAYOUT.position_m, LAYOUT.axis)
    est = _estimate(t, r + np.random.default_rng(12).normal(0, NOISE_MPS2, r.shape))
    assert est.cycles == pytest.approx(cycles, abs=0.01)
    assert _error(est) <= 0.004  # fewer samples than 10 cycles: more noise


def test_staggered_sampling_per_channel_is_supported():
    # Each channel sampled at its own instants (a multiplexed ADC).
    offsets = np.arange(12) / 5000 / 12
    t = T[:, None] + offsets[None, :]
    U = GOAL.phasor_table(1)
    r = np.column_stack(
        [
            readings(U, [1], 30, t[:, c], LAYOUT.position_m[c : c + 1], LAYOUT.axis[c : c + 1])[:, 0]
            for c in range(12)
        ]
    )
    est = _estimate(t, r)
    assert _error(est) < 2e-5


def test_less_than_a_cycle_cannot_separate_the_harmonics_and_says_so():
    n = int(0.6 * 5000 / 30)
    with pytest.raises(EstimationError, match=r"coverage: samples span 0\.59 cycles"):
        _estimate(T[:n], CLEAN[:n])


def test_columns_can_be_a_named_subset_of_the_layout_in_any_order():
    order = [11, 3, 0, 7, 5, 9, 1, 2, 4, 6, 8]  # channel 10 not recorded
    est = AccelEstimator(LAYOUT).from_samples(
        T, CLEAN[:, order], 30, channels=[LAYOUT.names[i] for i in order]
    )
    assert est.channels == tuple(LAYOUT.names[i] for i in order)
    assert _error(est) < 2e-5


def test_harmonics_above_the_nyquist_frequency_are_refused():
    t = sample_times(30, 10, 300)  # 10 samples per cycle: harmonics up to 4 only
    r = readings(GOAL.phasor_table(1), [1], 30, t, LAYOUT.position_m, LAYOUT.axis)
    with pytest.raises(ConfigError, match="above the Nyquist frequency 150 Hz"):
        AccelEstimator(LAYOUT, harmonics=6).from_samples(t, r, 30)
    est = AccelEstimator(LAYOUT, harmonics=4).from_samples(t, r, 30)
    assert abs(est.phasors[0, 0] - GOAL.phasors()[0, 0]) < 1e-3

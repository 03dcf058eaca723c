import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ppod_ros.vision import FilterSettings, PoseFilter, wrap_angle


def test_the_filter_converges_to_a_constant_velocity_and_shrinks_its_covariance():
    rng = np.random.default_rng(1)
    f = PoseFilter(0.0, 0.0, 0.0, 2 * math.pi, FilterSettings())
    v = np.array([0.01, -0.004, 0.3])
    for k in range(1, 40):
        f.predict(0.1)
        truth = v * 0.1 * k
        f.update(*(truth + rng.normal(0, [5e-5, 5e-5, 1.5e-3])))
    assert np.all(np.abs(np.array(f.velocity) - v) < [1e-3, 1e-3, 0.02])
    assert np.all(np.abs(np.array([*f.position, f.theta]) - v * 3.9) < [1e-4, 1e-4, 3e-3])
    cov = np.array(f.covariance())
    assert cov[0, 0] < 5e-5**2 and cov[2, 2] < 1.5e-3**2 and np.all(np.linalg.eigvalsh(cov) > 0)


def test_theta_stays_continuous_through_the_symmetry_period():
    # A rectangle (period pi) turning at 1 rad/s is seen as theta modulo pi; the filter unwraps it.
    f = PoseFilter(0.0, 0.0, 1.4, math.pi, FilterSettings(alpha_radps2=0.5))
    for k in range(1, 30):
        f.predict(0.1)
        f.update(0.0, 0.0, wrap_angle(1.4 + 0.1 * k, math.pi))
    assert f.theta == pytest.approx(1.4 + 2.9, abs=1e-3)
    assert f.velocity[2] == pytest.approx(1.0, abs=0.01)


def test_a_disk_has_no_orientation_state():
    f = PoseFilter(0.01, 0.02, 0.7, 0.0, FilterSettings())
    f.predict(0.1)
    f.update(0.011, 0.02, 2.0)
    assert f.theta == 0.0 and f.velocity[2] == 0.0 and math.isinf(f.covariance()[2][2])


def test_holding_a_track_stops_its_prediction_but_not_its_growing_uncertainty():
    f = PoseFilter(0.0, 0.0, 0.0, math.pi, FilterSettings())
    for k in range(1, 10):
        f.predict(0.1)
        f.update(0.002 * k, 0.0, 0.0)
    before = f.covariance()[0][0]
    f.hold()
    f.predict(0.5)
    assert f.position[0] == pytest.approx(0.018, abs=2e-4) and f.velocity == (0.0, 0.0, 0.0)
    assert f.covariance()[0][0] > before


@settings(max_examples=200, deadline=None)
@given(theta=st.floats(min_value=-100, max_value=100), n=st.integers(min_value=1, max_value=8))
def test_wrap_angle_lands_in_the_half_open_period_and_keeps_the_class(theta, n):
    period = 2 * math.pi / n
    w = wrap_angle(theta, period)
    assert -period / 2 <= w < period / 2
    k = (theta - w) / period
    assert abs(k - round(k)) < 1e-9 * max(1.0, abs(theta))

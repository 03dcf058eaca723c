import math

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion, acceleration_error, point_kinematics

LINE_SINK_X = """
name: LineSinkX
frequency_hz: 30
harmonics:
  - k: 1
    amplitude: [10, 0, 0, 0, 100, 0]
    phase: [0, 0, 0, 0, 4.71238898, 0]
"""


def test_motion_yaml_round_trips_through_to_dict():
    m = PlateMotion.from_yaml_text(LINE_SINK_X)
    assert m.name == "LineSinkX" and m.frequency_hz == 30.0
    again = PlateMotion.from_dict(m.to_dict())
    assert again == m
    np.testing.assert_array_equal(again.amplitude, m.amplitude)


def test_acceleration_velocity_and_displacement_are_consistent_integrals():
    phases = np.random.default_rng(1).uniform(-3, 3, (2, 6))
    m = PlateMotion(7.0, [1, 3], [[1, 2, 3, 4, 5, 6], [0.5, 0, 1, 0, 2, 0]], phases)
    t = np.linspace(0, m.period_s, 4001)
    a, v, d = m.acceleration(t), m.velocity(t), m.displacement(t)
    dt = t[1] - t[0]
    np.testing.assert_allclose(np.gradient(v, dt, axis=0)[2:-2], a[2:-2], atol=1e-3 * np.abs(a).max())
    np.testing.assert_allclose(np.gradient(d, dt, axis=0)[2:-2], v[2:-2], atol=1e-3 * np.abs(v).max())
    # zero mean over a period
    np.testing.assert_allclose(v[:-1].mean(axis=0), 0, atol=1e-12)
    np.testing.assert_allclose(d[:-1].mean(axis=0), 0, atol=1e-12)


def test_phasor_convention_is_im_of_x_times_exp_ikwt():
    m = PlateMotion(5.0, [2], [[1, 0, 0, 0, 0, 3]], [[0.3, 0, 0, 0, 0, -1.0]])
    t = 0.0123
    X = m.phasors()
    expected = np.imag(X[0] * np.exp(1j * 2 * m.omega * t))
    np.testing.assert_allclose(m.acceleration(t), expected)
    assert PlateMotion.from_phasors(5.0, [2], X) == m


def test_time_shift_by_one_period_is_the_same_motion_and_mirror_is_an_involution():
    m = PlateMotion.from_yaml_text(LINE_SINK_X)
    assert m.time_shifted(m.period_s) == m
    assert m.mirrored_x().mirrored_x() == m
    t = np.linspace(0, 0.1, 7)
    np.testing.assert_allclose(m.time_shifted(0.004).acceleration(t), m.acceleration(t + 0.004), atol=1e-12)


def test_point_kinematics_match_physics_md_formulas():
    m = PlateMotion.single(10.0, [1, 2, 3, 4, 5, 6], [0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    x, y, t = 0.03, -0.02, 0.017
    u, v = m.acceleration(t), m.velocity(t)
    kin = point_kinematics(m, x, y, t)
    np.testing.assert_allclose(kin["a_h"], [u[0] - u[5] * y, u[1] + u[5] * x])
    np.testing.assert_allclose(kin["a_n"], u[2] + u[3] * y - u[4] * x)
    np.testing.assert_allclose(kin["v_h"], [v[0] - v[5] * y, v[1] + v[5] * x])


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("frequency_hz: 0\nharmonics: []", "frequency_hz"),
        ("frequency_hz: -3\nharmonics: []", "frequency_hz"),
        ("frequency_hz: .nan\nharmonics: []", "frequency_hz"),
        ("frequency_hz: 30\nharmonics: [{k: 1, amplitude: [1, 2, 3]}]", "harmonics[0].amplitude"),
        ("frequency_hz: 30\nharmonics: [{k: 1, amplitude: [1, 2, 3, 4, 5, .nan]}]", "harmonics[0].amplitude"),
        ("frequency_hz: 30\nharmonics: [{k: 1, amplitude: [-1, 0, 0, 0, 0, 0]}]", "harmonics[0].amplitude"),
        ("frequency_hz: 30\nharmonics: [{k: 11, amplitude: [1, 0, 0, 0, 0, 0]}]", "harmonics[0].k"),
        ("frequency_hz: 30\nharmonics: [{k: 1, amplitude: [1, 0, 0, 0, 0, 0]}, {k: 1, amplitude: [1, 0, 0, 0, 0, 0]}]",
         "harmonics[1].k"),
        ("frequency_hz: 30\nfrequncy: 3\nharmonics: []", "frequncy"),
        ("frequency_hz: 30\nharmonics: [{k: 1, amplitude: [1, 0, 0, 0, 0, 0], phse: 0}]", "harmonics[0].phse"),
        ("frequency_hz: 30\nramp_time_s: -1\nharmonics: []", "ramp_time_s"),
        ("- 1\n- 2", "mapping"),
    ],
)
def test_bad_motion_yaml_is_rejected_naming_the_key(text, fragment):
    with pytest.raises(ConfigError, match=fragment.replace("[", r"\[").replace("]", r"\]").replace(".", r"\.")):
        PlateMotion.from_yaml_text(text)


def test_eleven_harmonics_are_rejected():
    items = "\n".join(f"  - {{k: {k}, amplitude: [1, 0, 0, 0, 0, 0]}}" for k in range(1, 12))
    with pytest.raises(ConfigError, match="at most 10"):
        PlateMotion.from_yaml_text(f"frequency_hz: 30\nharmonics:\n{items}")


def test_motion_identity_ignores_zero_entries_and_full_turns_of_phase():
    a = PlateMotion(30, [1], [[1, 0, 0, 0, 0, 0]], [[0.5, 1, 2, 3, 4, 5]])
    b = PlateMotion(30, [1, 2], [[1, 0, 0, 0, 0, 0], [0] * 6], [[0.5 + 2 * math.pi, 0, 0, 0, 0, 0], [0] * 6])
    assert a == b and hash(a) == hash(b)
    assert a != a.scaled(2.0)


def test_acceleration_error_scales_angular_axes_by_the_length():
    goal = np.zeros((2, 6), complex)
    goal[0] = [10, 0, 0, 0, 100, 0]
    ach = goal.copy()
    ach[1, 0] = 0.1  # a third-harmonic-like component the goal lacks
    ach[0, 4] = 101  # 1 rad/s^2 off, i.e. 0.1 m/s^2 at L = 0.1 m
    err, rel = acceleration_error(goal, ach)
    assert err == pytest.approx(math.hypot(0.1, 0.1))
    assert rel == pytest.approx(err / math.hypot(10, 10))

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


# ---------------------------------------------------------------- the checked-arrays construction
def _validated(f, k, amp, ph, **kw):
    """The same motion through the general path (a list of harmonics is never the array path)."""
    return PlateMotion(f, [int(x) for x in k], amp.tolist(), ph.tolist(), **kw)


def _reference_key(m):
    """The motion key as first written (sha1 of the frequency, harmonics and rounded nonzero phasors)."""
    import hashlib

    h = hashlib.sha1()
    h.update(np.float64(m.frequency_hz).tobytes())
    X = m.phasors()
    X = np.where(np.abs(X) > 0, X, 0.0)
    keep = np.any(X != 0, axis=1)
    h.update(m.k[keep].tobytes())
    h.update((np.round(X[keep].view(float), 10) + 0.0).tobytes())
    return h.digest()


def test_array_construction_matches_the_validated_one_bit_for_bit():
    rng = np.random.default_rng(3)
    for K in (0, 1, 2, 3):
        for _ in range(20):
            k = np.sort(rng.choice(np.arange(1, 11), K, replace=False)).astype(np.int64)
            amp = np.abs(rng.normal(size=(K, 6))) * rng.choice([0.0, -0.0, 1.0, 1e-12, 1e-310, 50.0], size=(K, 6))
            ph = rng.normal(size=(K, 6)) * 7.0
            f = float(rng.uniform(5, 60))
            fast = PlateMotion(f, k, amp, ph, name="x")
            slow = _validated(f, k, amp, ph, name="x")
            assert fast.key == slow.key == _reference_key(slow) and fast.is_zero() == slow.is_zero()
            assert type(fast.frequency_hz) is float and fast.frequency_hz == slow.frequency_hz
            for a, b in ((fast.k, slow.k), (fast.amplitude, slow.amplitude), (fast.phase, slow.phase)):
                assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
                assert not a.flags.writeable and a.flags.c_contiguous
            assert fast.pruned().key == slow.pruned().key
            assert fast.scaled(0.7).key == slow.scaled(0.7).key


def test_array_construction_copies_and_still_rejects_bad_values():
    amp, ph = np.ones((1, 6)), np.zeros((1, 6))
    m = PlateMotion(30.0, np.array([1]), amp, ph)
    amp[0, 0] = 5.0
    assert m.amplitude[0, 0] == 1.0   # the caller's array is not shared
    for bad in (np.nan, np.inf, -np.inf):
        a = np.ones((1, 6))
        a[0, 2] = bad
        with pytest.raises(ConfigError):
            PlateMotion(30.0, np.array([1]), a, ph)
        with pytest.raises(ConfigError):
            PlateMotion(30.0, np.array([1]), amp, np.full((1, 6), bad))
        with pytest.raises(ConfigError):
            PlateMotion(bad, np.array([1]), amp, ph)
        with pytest.raises(ConfigError):
            PlateMotion.from_phasors(30.0, [1], np.full((1, 6), complex(bad, 0.0)))
    with pytest.raises(ConfigError):
        PlateMotion(30.0, np.array([1]), -np.ones((1, 6)), ph)
    with pytest.raises(ConfigError):
        PlateMotion(30.0, np.array([11]), amp, ph)
    with pytest.raises(ConfigError):
        PlateMotion(30.0, np.array([2, 2]), np.ones((2, 6)), np.zeros((2, 6)))
    with pytest.raises(ConfigError):
        PlateMotion(-30.0, np.array([1]), amp, ph)
    # Harmonics out of order take the general path, which sorts them.
    m = PlateMotion(30.0, np.array([3, 1]), np.array([[1.0] * 6, [2.0] * 6]), np.zeros((2, 6)))
    assert m.k.tolist() == [1, 3] and m.amplitude[0, 0] == 2.0


def test_pruned_without_empty_rows_is_the_motion_itself():
    m = PlateMotion.single(30.0, [1, 0, 0, 0, 0, 0])
    assert m.pruned() is m
    two = PlateMotion(30.0, np.array([1, 2]), np.array([[1.0] + [0.0] * 5, [0.0] * 6]), np.zeros((2, 6)))
    assert two.pruned().k.tolist() == [1] and two.pruned().key == two.key

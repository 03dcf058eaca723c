"""Property tests (hypothesis) of the point-part theory: PHYSICS.md's theorem and symmetries."""

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ppod_ros.motion import PlateMotion, point_kinematics
from ppod_ros.parts import PointPart
from ppod_ros.physics import SolverSettings, limit_cycle, solve_field

SOLVER = SolverSettings(cache=False, rtol=1e-8, fixed_point_rtol=1e-7)
PROPS = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@st.composite
def motions(draw, max_harmonics=2):
    """Motions that keep contact over |x|, |y| <= 0.05 m: |a_n| <= 0.9 g there."""
    K = draw(st.integers(1, max_harmonics))
    ks = draw(st.lists(st.integers(1, 4), min_size=K, max_size=K, unique=True))
    amp = np.zeros((K, 6))
    ph = np.zeros((K, 6))
    for i in range(K):
        amp[i, :2] = [draw(st.floats(0.0, 15.0)) for _ in range(2)]
        amp[i, 5] = draw(st.floats(0.0, 150.0))
        amp[i, 2] = draw(st.floats(0.0, 4.0))
        amp[i, 3:5] = [draw(st.floats(0.0, 40.0)) for _ in range(2)]
        ph[i] = [draw(st.floats(0.0, 2 * math.pi)) for _ in range(6)]
    normal = amp[:, 2] + 0.05 * (amp[:, 3] + amp[:, 4])
    amp[:, 2:5] *= min(1.0, 0.9 * 9.81 / max(normal.sum(), 1e-9))
    return PlateMotion(draw(st.sampled_from([10.0, 30.0, 60.0])), np.array(ks), amp, ph)


points = st.tuples(st.floats(-0.05, 0.05), st.floats(-0.05, 0.05))


def tolerance(motion, xy):
    """What SOLVER promises (1e-5 of the plate's velocity scale at the point), in m/s."""
    vh = point_kinematics(motion, xy[0], xy[1], np.linspace(0, motion.period_s, 64))["v_h"]
    return 1e-5 * np.abs(vh).max() + 1e-12
mus = st.floats(0.05, 1.0)


@PROPS
@given(motions(), points, mus)
def test_the_limit_cycle_lies_in_the_convex_hull_of_the_plate_velocity(motion, xy, mu):
    part = PointPart(mu)
    t, s = limit_cycle(motion, part, list(xy), 128, SOLVER)
    tt = np.linspace(0, motion.period_s, 2048, endpoint=False)
    vh = point_kinematics(motion, xy[0], xy[1], tt)["v_h"]
    scale = np.abs(vh).max() + 1e-12
    for ang in np.linspace(0, math.pi, 24, endpoint=False):  # support functions in 48 directions
        d = np.array([math.cos(ang), math.sin(ang)])
        assert (s @ d).max() <= (vh @ d).max() + 1e-6 * scale
        assert (s @ d).min() >= (vh @ d).min() - 1e-6 * scale


@PROPS
@given(motions(), points, mus, st.tuples(st.floats(-50, 50), st.floats(-50, 50)))
def test_the_result_does_not_depend_on_the_initial_velocity(motion, xy, mu, s0):
    part = PointPart(mu)
    a = solve_field(motion, part, [xy], SOLVER)
    b = solve_field(motion, part, [xy], SOLVER, initial=[s0])
    assert a.valid[0] and b.valid[0]
    assert np.abs(a.velocity - b.velocity).max() <= tolerance(motion, xy)


@PROPS
@given(motions(), points, mus)
def test_a_mirrored_motion_gives_the_mirrored_field(motion, xy, mu):
    part = PointPart(mu)
    a = solve_field(motion, part, [xy], SOLVER)
    b = solve_field(motion.mirrored_x(), part, [[-xy[0], xy[1]]], SOLVER)
    mirrored = [-a.velocity[0, 0], a.velocity[0, 1]]
    assert np.allclose(b.velocity[0], mirrored, rtol=0, atol=tolerance(motion, xy))


@PROPS
@given(motions(), points, mus, st.floats(0.0, 1.0))
def test_shifting_time_changes_nothing(motion, xy, mu, frac):
    part = PointPart(mu)
    a = solve_field(motion, part, [xy], SOLVER)
    b = solve_field(motion.time_shifted(frac * motion.period_s), part, [xy], SOLVER)
    assert np.allclose(a.velocity, b.velocity, rtol=0, atol=tolerance(motion, xy))


@PROPS
@given(motions(max_harmonics=3), st.lists(st.tuples(st.floats(-0.12, 0.12), st.floats(-0.12, 0.12)),
                                          min_size=1, max_size=6), mus)
def test_results_are_finite_exactly_where_they_are_flagged_valid(motion, cfg, mu):
    r = solve_field(motion.scaled(3.0), PointPart(mu), cfg, SolverSettings(cache=False))
    assert np.isfinite(r.velocity[r.valid]).all()
    assert np.isnan(r.velocity[~r.valid]).all()
    assert all((why is None) == ok for why, ok in zip(r.reason, r.valid))


def test_zero_motion_gives_a_zero_field(point_part):
    r = solve_field(PlateMotion.zero(), point_part, [[0.0, 0.0], [0.05, -0.02]], SolverSettings(cache=False))
    assert r.valid.all()
    assert np.all(r.velocity == 0.0)
    assert np.all(r.stick_fraction == 1.0)

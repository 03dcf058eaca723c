"""Full dynamics: trajectories follow the asymptotic field; chunking, stick-slip, contact loss."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion
from ppod_ros.physics import PartDynamics, SolverSettings, solve_field
from tests.physics.physics_suite import suite_motion


def _run(sim, motion, t0, duration, chunk):
    times, states = [], []
    t = t0
    while t < t0 + duration - 1e-12:
        st = sim.advance(motion, t, min(chunk, t0 + duration - t))
        t = st.time_s
        times.append(t)
        states.append(st.configurations.copy())
    return np.array(times), np.array(states)


@pytest.mark.parametrize("name", ["Sink", "LineSinkX"])
def test_after_the_transient_a_trajectory_follows_the_integral_curve_of_the_field(name, point_part):
    m = suite_motion(name)
    T = m.period_s
    sim = PartDynamics([point_part], [[0.06, 0.03]])
    times, states = _run(sim, m, 0.0, 60 * T, 2 * T)  # samples at cycle starts
    xy = states[:, 0, :2]
    i0 = 3  # past the transient (a few periods)

    def field(t, q):
        return solve_field(m, point_part, [q]).velocity[0]

    curve = solve_ivp(field, (times[i0], times[-1]), xy[i0], t_eval=times[i0:], rtol=1e-8, atol=1e-10)
    travelled = np.linalg.norm(xy[-1] - xy[i0])
    assert travelled > 0.01
    # The part oscillates with the plate (~0.3 mm) about the averaged motion.
    assert np.abs(curve.y.T - xy[i0:]).max() < 0.05 * travelled


def test_advancing_in_chunks_matches_one_long_advance(point_part, rigid_part):
    m = suite_motion("RigidU1")
    parts = [point_part, rigid_part]
    cfg = [[0.03, -0.02, 0.0], [-0.02, 0.01, 0.5]]
    a = PartDynamics(parts, cfg)
    b = PartDynamics(parts, cfg)
    sa = a.advance(m, 0.0, 0.5)
    _, _ = _run(b, m, 0.0, 0.5, 0.0123)
    sb = b.state
    assert sa.time_s == pytest.approx(sb.time_s)
    assert np.abs(sa.configurations - sb.configurations).max() < 1e-6
    assert np.abs(sa.twists - sb.twists).max() < 1e-4


def test_phases_refer_to_absolute_time_so_a_later_start_sees_the_same_cycle(point_part):
    m = suite_motion("LineSinkX")
    a = PartDynamics([point_part], [[0.05, 0.0]], time_s=0.0).advance(m, 0.0, 1.0)
    b = PartDynamics([point_part], [[0.05, 0.0]], time_s=100.0).advance(m, 100.0, 1.0)
    assert np.abs(a.configurations - b.configurations).max() < 1e-7


def test_the_motion_may_change_between_chunks(point_part):
    sim = PartDynamics([point_part], [[0.0, 0.0]])
    right = suite_motion("TranslateX")
    left = right.mirrored_x()
    x1 = sim.advance(right, 0.0, 1.0).configurations[0, 0]
    x2 = sim.advance(left, 1.0, 1.0).configurations[0, 0]
    v = solve_field(right, point_part, [[0.0, 0.0]]).velocity[0, 0]
    assert x1 == pytest.approx(v, rel=0.05)  # 1 s at the asymptotic speed (the transient is short)
    assert x2 == pytest.approx(0.0, abs=0.05 * abs(v))


def test_contact_loss_is_flagged_and_the_part_is_left_where_it_was(point_part):
    m = suite_motion("NearContactLoss")
    sim = PartDynamics([point_part, point_part], [[0.08, 0.0], [0.01, 0.0]])
    st = sim.advance(m, 0.0, 0.2)
    assert st.contact_lost.tolist() == [True, False]
    assert st.reason[0] == "contact lost"
    frozen = st.configurations[0].copy()
    st2 = sim.advance(m, 0.2, 0.2)
    assert np.array_equal(st2.configurations[0], frozen)
    sim.set_part(0, [0.0, 0.0])
    assert not sim.state.contact_lost[0]


def test_a_gently_shaken_part_sticks_and_moves_with_the_plate(point_part):
    gentle = PlateMotion.single(30.0, [1.0, 0, 0, 0, 0, 0])
    sim = PartDynamics([point_part], [[0.0, 0.0]], twists=[gentle.velocity(0.0)[:2]])
    st = sim.advance(gentle, 0.0, 0.3)
    assert st.sticking[0] and st.stick_fraction[0] > 0.99
    assert abs(st.configurations[0, 0] - gentle.displacement(0.3)[0] + gentle.displacement(0.0)[0]) < 1e-9


def test_rigid_parts_turn_towards_their_stable_orientation(rigid_part):
    m = suite_motion("RigidU1")
    sim = PartDynamics([rigid_part], [[0.02, 0.0, 0.6]], settings=SolverSettings(threads=1))
    st = sim.advance(m, 0.0, 3.0)
    assert abs(st.configurations[0, 2]) < 0.6 and abs(st.configurations[0, 0]) < 0.02


def test_a_rigid_part_that_sticks_and_breaks_away_keeps_contact_as_the_field_says(rigid_part):
    # A rotation field about (-0.05, 0.04) (the planner's turning field): the limit cycle sticks a
    # third of each cycle. The stuck twist once drifted off the plate's as the configuration
    # evolved, and each break-away then looked like a contact loss (regularised friction of many
    # times mu N); the full dynamics must keep contact and turn at the asymptotic rate.
    m = PlateMotion.from_phasors(30.0, [1], [[8.691, 11.0195, 3.0835 * np.exp(-1.5708j), 25.2 * np.exp(0.21j),
                                              36.469 * np.exp(0.22j), 206.6]])
    cfg = [-0.05, 0.04, -1.2]
    field = solve_field(m, rigid_part, [cfg])
    assert field.valid[0] and 0.1 < field.stick_fraction[0] < 0.9
    sim = PartDynamics([rigid_part], [cfg], settings=SolverSettings(threads=1))
    times, states = _run(sim, m, 0.0, 1.0, 0.1)
    assert not sim.state.contact_lost[0], sim.state.reason
    rate = (states[-1, 0, 2] - states[4, 0, 2]) / (times[-1] - times[4])
    assert rate == pytest.approx(field.velocity[0, 2], rel=0.1)


def test_set_parts_places_several_parts_like_set_part_one_by_one(point_part, rigid_part):
    parts = [point_part, rigid_part, point_part]
    start = [[0.0, 0.0, 0.0], [0.02, 0.01, 0.3], [-0.02, 0.0, 0.0]]
    one, many = PartDynamics(parts, start), PartDynamics(parts, start)
    cfg = np.array([[0.03, -0.01, 0.5], [0.01, 0.02, 0.0]])
    tw = np.array([[1e-3, 0.0, 0.2], [0.0, -2e-3, 0.0]])
    for i, c, w in zip([1, 2], cfg, tw):
        one.set_part(i, c, w)
    many.set_parts([1, 2], cfg, tw)
    a, b = one.state, many.state
    assert np.array_equal(a.configurations, b.configurations) and np.array_equal(a.twists, b.twists)
    assert np.allclose(b.configurations[1:], cfg) and np.allclose(b.twists[1], tw[0])
    with pytest.raises(ConfigError, match="index"):
        many.set_parts([3], cfg[:1])


def test_bad_calls_are_clear_errors_naming_the_argument(point_part):
    m = suite_motion("LineSinkX")
    sim = PartDynamics([point_part], [[0.0, 0.0]])
    with pytest.raises(ConfigError, match="t_start_s"):
        sim.advance(m, 1.0, 0.1)
    with pytest.raises(ConfigError, match="duration_s"):
        sim.advance(m, 0.0, -0.1)
    with pytest.raises(ConfigError, match="configurations"):
        PartDynamics([point_part], [[0.0, 0.0, 0.0, 1.0]])
    with pytest.raises(ConfigError, match="parts\\[0\\]"):
        PartDynamics(["not a part"], [[0.0, 0.0]])

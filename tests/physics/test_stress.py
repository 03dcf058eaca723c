"""Numerical stress: extreme friction, frequencies, harmonics, amplitudes, starts, and bad parts."""

import math

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion, point_kinematics
from ppod_ros.parts import PointPart, RigidPart, published_rigid_part
from ppod_ros.physics import SolverSettings, grid_configs, solve_field
from tests.physics.physics_suite import suite_motion

CFG = [[0.03, 0.01], [-0.02, 0.04], [0.0, 0.0]]


def _check_point_result(motion, r):
    """Valid results are finite and inside the bound of the plate velocity; invalid ones are NaN."""
    assert np.isfinite(r.velocity[r.valid]).all() and np.isnan(r.velocity[~r.valid]).all()
    for (x, y), v, ok in zip(r.configs, r.velocity, r.valid):
        if ok:
            vh = point_kinematics(motion, x, y, np.linspace(0, motion.period_s, 256))["v_h"]
            assert np.hypot(*v) <= np.hypot(vh[:, 0], vh[:, 1]).max() * (1 + 1e-6) + 1e-15


@pytest.mark.parametrize("mu", [0.01, 0.1, 0.5, 1.0, 2.0])
@pytest.mark.parametrize("name", ["LineSinkX", "Sink", "Swirl3H"])
def test_friction_from_0_01_to_2_gives_valid_bounded_fields(mu, name):
    m = suite_motion(name)
    r = solve_field(m, PointPart(mu), CFG, SolverSettings(cache=False))
    assert r.valid.all(), r.reason
    _check_point_result(m, r)


def test_high_friction_holds_the_part_on_the_plate(point_part):
    r = solve_field(suite_motion("Sink"), PointPart(2.0), CFG, SolverSettings(cache=False))
    assert np.all(r.stick_fraction == 1.0) and np.all(np.abs(r.velocity) < 1e-12)


@pytest.mark.parametrize("freq", [5.0, 50.0, 200.0])
def test_frequencies_from_5_to_200_hz_scale_the_field_as_1_over_f(freq, point_part):
    """With accelerations fixed, velocities scale as 1/f and the field with them."""
    base = suite_motion("Sink")
    m = PlateMotion(freq, base.k, base.amplitude, base.phase)
    r = solve_field(m, point_part, CFG, SolverSettings(cache=False))
    r30 = solve_field(base, point_part, CFG, SolverSettings(cache=False))
    assert r.valid.all()
    assert np.allclose(r.velocity * freq, r30.velocity * 30.0, rtol=1e-3, atol=1e-6)


def test_five_harmonics_give_a_valid_field(point_part):
    k = np.arange(1, 6)
    rng = np.random.default_rng(7)
    amp = np.array([6.0, 4.0, 1.0, 15.0, 15.0, 30.0]) / k[:, None]
    m = PlateMotion(25.0, k, amp, rng.uniform(0, 2 * math.pi, (5, 6)))
    cfg = grid_configs([-0.05, 0.0, 0.05], [-0.03, 0.02])
    r = solve_field(m, point_part, cfg, SolverSettings(cache=False))
    assert r.valid.all()
    _check_point_result(m, r)


def test_tiny_amplitudes_keep_the_part_stuck(point_part):
    for m in (suite_motion("Sink").scaled(1e-6), suite_motion("LineSinkX").scaled(1e-6)):
        r = solve_field(m, point_part, CFG, SolverSettings(cache=False))
        assert r.valid.all() and np.all(np.abs(r.velocity) < 1e-15) and np.all(r.stick_fraction == 1.0)


def test_huge_horizontal_amplitudes_give_the_symmetric_zero_field(point_part):
    """A purely horizontal motion (a_n = 0) has s(t + T/2) = -s(t) on its limit cycle: zero mean.

    The one-period map then barely contracts (friction is tiny next to the plate's swing), so the
    answer is as good as the fixed-point tolerance over (1 - rate): 1e-4 of the velocity scale."""
    m = PlateMotion.single(30.0, [1e4, 1e4, 0, 0, 0, 0], [0, 1.0, 0, 0, 0, 0])
    r = solve_field(m, point_part, CFG, SolverSettings(cache=False))
    assert r.valid.all()
    assert np.abs(r.velocity).max() < 1e-4 * 1e4 / m.omega


def test_huge_vertical_amplitudes_lose_contact_everywhere(point_part):
    cfg = [[0.03, 0.01], [-0.02, 0.04]]  # off x = 0, where LineSinkX has a vertical component
    r = solve_field(suite_motion("LineSinkX").scaled(1e4), point_part, cfg, SolverSettings(cache=False))
    assert not r.valid.any() and set(r.reason) == {"contact lost"}


def test_initial_velocities_far_outside_the_hull_converge_to_the_same_field(point_part):
    m = suite_motion("Sink")
    a = solve_field(m, point_part, CFG, SolverSettings(cache=False))
    b = solve_field(m, point_part, CFG, SolverSettings(cache=False), initial=[[1e3, -1e3]] * 3)
    assert np.abs(a.velocity - b.velocity).max() < 1e-6


def test_the_edge_of_contact_loss_is_valid_just_inside_and_flagged_on_it(point_part, line_sink_x):
    edge = 9.81 / 100.0
    r = solve_field(line_sink_x, point_part, [[edge - 1e-7, 0.0], [edge, 0.0], [edge + 1e-7, 0.0]],
                    SolverSettings(cache=False))
    assert r.valid.tolist() == [True, False, False]
    assert np.isfinite(r.velocity[0]).all()


def test_collinear_contacts_are_a_clear_error_at_load_time():
    with pytest.raises(ConfigError, match="collinear"):
        RigidPart(0.02, [1e-5, 1e-5, 1e-5], [[0, 0, 0], [0.01, 0, 0], [0.02, 0, 0]], 0.3)


def test_contacts_at_different_heights_are_rejected():
    with pytest.raises(ConfigError, match="same z"):
        RigidPart(0.02, [1e-5, 1e-5, 1e-5], [[0.01, 0, -0.001], [0, 0.01, -0.002], [-0.01, 0, -0.001]], 0.3)


def test_a_tall_part_whose_contacts_lift_off_is_flagged_not_integrated():
    z = -0.05
    tall = RigidPart(0.02, [1e-5, 1e-5, 1e-5], [[0.01, -0.01, z], [0, 0.01, z], [-0.01, -0.01, z]], [1.0] * 3)
    cfg = [[0.0, 0.0, 0.0], [0.03, 0.0, 1.0]]
    r = solve_field(suite_motion("RigidU1"), tall, cfg, SolverSettings(cache=False))
    assert not r.valid.any() and set(r.reason) == {"contact lost"}


@pytest.mark.parametrize("mu", [0.05, 0.6, 1.5])
def test_rigid_parts_give_finite_or_flagged_twists_across_friction(mu):
    base = published_rigid_part()
    part = RigidPart(base.mass, base.inertia, base.contacts, [mu] * 3)
    cfg = grid_configs([-0.03, 0.02], [0.0], [0.0, 0.8, 2.0])
    r = solve_field(suite_motion("RigidU1"), part, cfg, SolverSettings(cache=False))
    assert r.valid.all()
    # The regularisation speed eps changes the answer by little (eps = 1e-5 m/s vs the default 1e-6).
    r5 = solve_field(suite_motion("RigidU1"), part, cfg, SolverSettings(cache=False, friction_eps_mps=1e-5))
    assert r5.valid.all()
    assert np.abs(r.velocity[:, :2] - r5.velocity[:, :2]).max() < 1e-5
    assert np.abs(r.velocity[:, 2] - r5.velocity[:, 2]).max() < 1e-4

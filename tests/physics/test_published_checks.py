"""PHYSICS.md's published numbers: LineSinkX and the rigid part under u1."""

import math

import numpy as np
import pytest

from ppod_ros.physics import SolverSettings, grid_configs, solve_field
from tests.physics.physics_suite import suite_motion

CLOSED = SolverSettings(cache=False)
ODE = SolverSettings(cache=False, closed_form=False, rtol=1e-8, fixed_point_rtol=1e-7)


@pytest.mark.parametrize("settings", [CLOSED, ODE], ids=["closed_form", "integrated"])
def test_line_sink_point_values_match_the_published_ones_to_1e_5(line_sink_x, point_part, settings):
    r = solve_field(line_sink_x, point_part, [[0.02, 0.0], [0.05, 0.0]], settings)
    assert r.valid.all()
    assert r.velocity[0, 0] == pytest.approx(-0.007288, abs=1e-5)
    assert r.velocity[1, 0] == pytest.approx(-0.015315, abs=1e-5)
    assert np.all(np.abs(r.velocity[:, 1]) < 1e-12)


@pytest.mark.parametrize(("n", "expected"), [(8, -0.284), (21, -0.293)])
def test_line_sink_fit_coefficient_matches_the_published_figure(line_sink_x, point_part, n, expected):
    xs = np.linspace(-0.07, 0.07, n)
    cfg = grid_configs(xs, xs)
    r = solve_field(line_sink_x, point_part, cfg, CLOSED)
    assert r.valid.all()
    A = np.column_stack([cfg[:, 0], cfg[:, 1], np.ones(len(cfg))])
    c1, c2, c0 = np.linalg.lstsq(A, r.velocity[:, 0], rcond=None)[0]
    assert c1 == pytest.approx(expected, abs=0.005)
    assert abs(c2) < 1e-6 and abs(c0) < 1e-6  # independent of y, odd in x (to the tolerances)


def test_line_sink_sticks_for_the_published_fractions_of_the_cycle(line_sink_x, point_part):
    r = solve_field(line_sink_x, point_part, [[0.07, 0.0], [0.09, 0.0]], CLOSED)
    assert r.stick_fraction[0] == pytest.approx(0.002, abs=0.0005)
    assert r.stick_fraction[1] == pytest.approx(0.034, abs=0.0005)


def test_line_sink_loses_contact_beyond_0_098_m(line_sink_x, point_part):
    r = solve_field(line_sink_x, point_part, [[0.097, 0.0], [0.099, 0.0], [-0.099, 0.03]], CLOSED)
    assert r.valid.tolist() == [True, False, False]
    assert r.reason.tolist()[1:] == ["contact lost", "contact lost"]
    assert np.isnan(r.velocity[1:]).all()


def test_rigid_part_under_u1_has_stable_lines_at_0_and_pi_and_unstable_ones_between(rigid_part):
    u1 = suite_motion("RigidU1")
    d = 0.05
    thetas = [0.0, math.pi / 2, math.pi, 3 * math.pi / 2]
    cfg = []
    for sy in (-0.03, 0.02):
        for th in thetas:
            cfg += [[0.0, sy, th - d], [0.0, sy, th], [0.0, sy, th + d]]
    r = solve_field(u1, rigid_part, cfg, SolverSettings(cache=False))
    assert r.valid.all()
    w = r.velocity[:, 2].reshape(2, 4, 3)
    v = r.velocity[:, :2].reshape(2, 4, 3, 2)
    # On the lines themselves the twist vanishes (fixed configurations).
    assert np.abs(w[:, :, 1]).max() < 1e-4
    assert np.abs(v[:, :, 1]).max() < 1e-5
    # theta' changes sign across each line: stable (-) at 0 and pi, unstable (+) at pi/2, 3 pi/2.
    slope = w[:, :, 2] - w[:, :, 0]
    assert np.all(slope[:, [0, 2]] < 0)
    assert np.all(slope[:, [1, 3]] > 0)


def test_rigid_part_under_u1_moves_towards_x_0(rigid_part):
    u1 = suite_motion("RigidU1")
    cfg = grid_configs([-0.04, -0.02, 0.02, 0.04], [0.0, 0.03], [0.0, 1.0, math.pi, 4.0])
    r = solve_field(u1, rigid_part, cfg, SolverSettings(cache=False))
    assert r.valid.all()
    assert np.all(np.sign(r.velocity[:, 0]) == -np.sign(cfg[:, 0]))

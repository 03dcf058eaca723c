"""The solver's methods agree with each other and with an independent integration."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ppod_ros.motion import point_kinematics
from ppod_ros.parts import PointPart
from ppod_ros.physics import INTEGRATORS, SolverSettings, grid_configs, limit_cycle, solve_field
from tests.physics.physics_suite import suite_motion

TIGHT = dict(rtol=1e-9, fixed_point_rtol=1e-7, cache=False)


@pytest.mark.parametrize("name", ["LineSinkX", "RotateZ", "TwoHarmonicX", "StickingHeavy", "TranslateX"])
def test_closed_form_and_integration_agree_on_collinear_motions(name, point_part):
    m = suite_motion(name)
    cfg = grid_configs(np.linspace(-0.09, 0.09, 7), np.linspace(-0.05, 0.05, 3))
    a = solve_field(m, point_part, cfg, SolverSettings(**TIGHT))
    b = solve_field(m, point_part, cfg, SolverSettings(closed_form=False, **TIGHT))
    assert (a.valid == b.valid).all()
    assert np.nanmax(np.abs(a.velocity - b.velocity)) < 1e-7
    assert np.nanmax(np.abs(a.stick_fraction - b.stick_fraction)) < 1e-5


@pytest.mark.parametrize("integrator", sorted(INTEGRATORS))
@pytest.mark.parametrize("method", ["anderson", "picard"])
def test_every_integrator_and_fixed_point_method_gives_the_same_field(integrator, method, point_part):
    m = suite_motion("Sink")
    cfg = grid_configs([-0.05, 0.0, 0.03], [-0.02, 0.04])
    ref = solve_field(m, point_part, cfg, SolverSettings(integrator="dop853", **TIGHT))
    r = solve_field(m, point_part, cfg, SolverSettings(integrator=integrator, fixed_point=method, rtol=1e-7,
                                                       fixed_point_rtol=1e-6, cache=False))
    assert r.valid.all()
    assert np.abs(r.velocity - ref.velocity).max() < 1e-6


def _independent_average(motion, x, y, mu, s0, periods=3):
    """Plain regularised Coulomb (|w| floor 1e-9 m/s) with scipy's Radau, from the solver's cycle start."""
    T = motion.period_s

    def f(t, s):
        k = point_kinematics(motion, x, y, t)
        w = s - k["v_h"]
        return -mu * (9.81 + k["a_n"]) * w / max(np.hypot(*w), 1e-9)

    s = np.array(s0, float)
    for p in range(periods):
        sol = solve_ivp(f, (p * T, (p + 1) * T), s, method="Radau", rtol=1e-10, atol=1e-13, dense_output=True)
        s = sol.y[:, -1]
    t = np.linspace((periods - 1) * T, periods * T, 2001)
    return np.trapezoid(sol.sol(t), t, axis=1) / T, s


@pytest.mark.parametrize(("name", "x", "y"), [("Sink", 0.03, -0.02), ("Swirl3H", -0.092, 0.056),
                                              ("StickingHeavy", 0.04, 0.0), ("Whirlpool", -0.05, 0.05)])
def test_fields_match_an_independent_stiff_integration(name, x, y):
    m = suite_motion(name)
    r = solve_field(m, PointPart(0.3), [[x, y]], SolverSettings(cache=False))
    assert r.valid[0]
    avg, end = _independent_average(m, x, y, 0.3, r.cycle_start[0])
    assert np.abs(r.velocity[0] - avg).max() < 2e-6
    assert np.abs(end - r.cycle_start[0]).max() < 1e-5  # the cycle start is a fixed point


def test_limit_cycle_samples_average_to_the_asymptotic_velocity(line_sink_x, point_part):
    t, v = limit_cycle(line_sink_x, point_part, [0.05, 0.0], 512)
    r = solve_field(line_sink_x, point_part, [[0.05, 0.0]])
    assert t.shape == (512,) and v.shape == (512, 2)
    assert v.mean(axis=0) == pytest.approx(r.velocity[0], abs=2e-5)


def test_rigid_fields_agree_across_integrators(rigid_part):
    m = suite_motion("RigidU1")
    cfg = grid_configs([-0.04, 0.02], [0.0, 0.05], [0.4, 2.0, 3.5])
    ref = solve_field(m, rigid_part, cfg, SolverSettings(integrator="dop853", rigid_rtol=1e-10,
                                                         fixed_point_rtol=1e-9, cache=False))
    for integ in sorted(INTEGRATORS):
        r = solve_field(m, rigid_part, cfg, SolverSettings(integrator=integ, cache=False))
        assert r.valid.all()
        assert np.abs(r.velocity[:, :2] - ref.velocity[:, :2]).max() < 1e-5
        assert np.abs(r.velocity[:, 2] - ref.velocity[:, 2]).max() < 1e-4


def test_rigid_solver_reports_agreement_of_several_initial_twists(rigid_part):
    m = suite_motion("RigidU1")
    cfg = [[0.02, 0.0, 0.7], [-0.03, 0.01, 2.5]]
    r = solve_field(m, rigid_part, cfg, SolverSettings(rigid_starts=3, cache=False))
    assert r.valid.all()
    assert (r.periods > 6).all()  # the extra starts were solved too

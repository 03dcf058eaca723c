"""The benchmark's independent fixed-step reference agrees with the solver where both are exact-ish."""

import numpy as np

from ppod_bench.fixed_step_reference import reference_average
from ppod_ros.physics import SolverSettings, solve_field
from tests.physics.physics_suite import suite_motion


def test_fixed_step_reference_agrees_with_the_closed_form_and_the_integrated_solver(point_part):
    for name, pts in (("LineSinkX", [(0.02, 0.0)]), ("Sink", [(0.04, 0.0)]), ("StickingHeavy", [(0.04, 0.0)])):
        m = suite_motion(name)
        r = solve_field(m, point_part, pts, SolverSettings(cache=False))
        for i, (x, y) in enumerate(pts):
            ref, periods = reference_average(m, point_part.mu, x, y, start=r.cycle_start[i])
            assert periods > 1
            assert np.abs(ref - r.velocity[i]).max() < 1.5e-6, name


def test_fixed_step_reference_reports_contact_loss(point_part):
    ref, periods = reference_average(suite_motion("LineSinkX"), point_part.mu, 0.099, 0.0)
    assert np.isnan(ref).all() and periods == 0

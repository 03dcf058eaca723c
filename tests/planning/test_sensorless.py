"""Sensorless mode: fixed points of the plate fields position and orient parts without a camera,
checked on the full dynamics (no asymptotic shortcut) from starts all over the plate."""

import math

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.parts import PointPart, published_rigid_part
from ppod_ros.planning import FieldSpec, design_field
from ppod_ros.planning.sensorless import SensorlessTask, field_fixed_point, plan_sensorless
from ppod_ros.planning.simulate import run_on_dynamics

GOAL = (0.02, -0.02)


def _play(parts, starts, plan):
    """Play the plan open loop on the full dynamics; the task is never shown a pose."""
    run = run_on_dynamics(SensorlessTask(plan), parts, starts, horizon_s=plan.total_s + 1.0)
    assert run.step.done
    return run.configurations, run.elapsed_s, run.motions


def test_the_sinks_fixed_point_is_moved_onto_the_goal_and_is_stable():
    part = PointPart(0.3)
    designed = design_field(FieldSpec.from_request("sink", [*GOAL, 0.3]), part).motion
    before = field_fixed_point(designed, part, GOAL)
    plan = plan_sensorless(part, (*GOAL, None))
    assert math.hypot(*(before.position_m - GOAL)) > 1e-5  # the design alone misses by a little
    assert math.hypot(*(plan.fixed_point.position_m - GOAL)) < 1e-6
    assert plan.fixed_point.stable and np.all(plan.fixed_point.eigenvalues.real < -0.2)
    assert plan.fixed_point.residual_mps < 1e-7
    assert [s.name for s in plan.stages] == ["positioning"] and plan.orientation_period_rad is None


def test_point_parts_from_all_over_the_plate_end_at_the_goal_without_a_camera():
    plan = plan_sensorless(PointPart(0.3), (*GOAL, None))
    starts = [[0.065, 0.0], [-0.05, -0.045], [0.0, 0.068], [-0.06, 0.03], [0.03, -0.06], list(GOAL)]
    final, t, motions = _play([PointPart(0.3)] * len(starts), starts, plan)
    assert t == pytest.approx(plan.total_s, abs=0.11) and motions == 1
    assert np.max(np.hypot(final[:, 0] - GOAL[0], final[:, 1] - GOAL[1])) <= 0.5e-3


@pytest.mark.slow
def test_the_rigid_part_is_positioned_and_oriented_modulo_a_half_turn_without_a_camera():
    part = published_rigid_part()
    plan = plan_sensorless(part, (*GOAL, 0.0))
    assert plan.stages[0].name == "positioning" and plan.stages[-1].name == "orienting"
    assert plan.orientation_period_rad == pytest.approx(math.pi)  # the bracket has no half-turn symmetry
    assert any("half a turn" in m for m in plan.messages)
    starts = [[0.06, 0.02, 1.2], [-0.05, -0.04, -0.7], [0.0, 0.06, 2.5], [0.03, -0.05, 1.5]]  # 1.5 rad: 4 deg
    final, _, _ = _play([part] * len(starts), starts, plan)                               # from unstable
    assert np.max(np.hypot(final[:, 0] - GOAL[0], final[:, 1] - GOAL[1])) <= 1e-3
    off = np.degrees((final[:, 2] + math.pi / 2) % math.pi - math.pi / 2)
    assert np.max(np.abs(off)) <= 2.0, off


def test_the_sensorless_task_changes_motion_only_between_stages_and_only_reports_poses():
    plan = plan_sensorless(PointPart(0.3), (*GOAL, None))
    task = SensorlessTask(plan)
    first = task.step(5.0, [[0.05, 0.0, 0.0]])
    assert first.motion is not None and first.phase == "positioning" and not first.done
    assert first.position_error_m == pytest.approx(math.hypot(0.03, 0.02))
    same = task.step(6.0)
    assert same.motion is None and math.isnan(same.position_error_m)
    end = task.step(5.0 + plan.total_s + 0.01, [[GOAL[0], GOAL[1], 0.0]])
    assert end.done and end.motion is None and end.position_error_m == pytest.approx(0.0)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"goal": (0.09, 0.0, None)}, "working disc"),
    ({"goal": (0.0, 0.0)}, "goal: expected"),
    ({"goal": (0.0, 0.0, None), "margin": 0.5}, "margin"),
    ({"goal": (0.0, 0.0, None), "coverage": 1.0}, "coverage"),
    ({"goal": (float("nan"), 0.0, None)}, "finite"),
])
def test_bad_sensorless_requests_are_errors_naming_the_argument(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        plan_sensorless(PointPart(0.3), **kwargs)

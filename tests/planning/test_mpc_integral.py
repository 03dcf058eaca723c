"""Integral action on a part's position near its goal (MpcSettings.integral_per_s).

One washer commanded alone to 1 mm (`ppod demo --part washer --goal 0.03 0.03`) circled its goal at
2-12 mm: under the weak refined fields near a goal, the model's friction (0.3 against the washer's
0.25) and the plant error shift the field's zero by more than the tolerance, and a velocity scale
cannot move a zero. The planner now aims the part at a point that moves by the gain times its
position error per second, as an integral term does. Model time only: no wall-clock assertions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.parts import PointPart, published_rigid_part
from ppod_ros.planning.mpc import MpcSettings, MultiTask, PartGoal

GOAL = (0.03, 0.03)


def _task(defaults: bool = False, alone: bool = False, **settings) -> MultiTask:
    """The washer (and the bracket unless ``alone``) commanded; the tests' own settings unless ``defaults``."""
    parts = [PointPart(0.3), published_rigid_part()]
    goals = [PartGoal(0, *GOAL, None, 1e-3, math.radians(2)), PartGoal(1, -0.02, 0.0, 0.0, 1e-3, math.radians(2))]
    base = {} if defaults else dict(integral_per_s=0.5, integral_within_m=0.005, integral_max_m=0.004,
                                    integral_after_s=0.0, integral_max_parts=2)
    return MultiTask(parts, goals[:1] if alone else goals, settings=MpcSettings(**{**base, **settings}))


def test_by_default_only_a_point_part_alone_after_five_seconds_near():
    several = _task(defaults=True)
    _frames(several, (0.002, 0.0), 100)
    assert several.state[0].aim == (0.0, 0.0)            # two parts commanded: off
    alone = _task(defaults=True, alone=True)
    s = alone.settings
    t = _frames(alone, (0.002, 0.0), int(round(s.integral_after_s / 0.1)))
    assert alone.state[0].aim == (0.0, 0.0)              # not yet near for integral_after_s
    _frames(alone, (0.002, 0.0), 11, t0=t)
    assert alone.state[0].aim[0] == pytest.approx(s.integral_per_s * -0.002 * 1.1)


def _frames(task: MultiTask, offset_m: tuple[float, float], n: int, t0: float = 0.0, dt: float = 0.1) -> float:
    """``n`` frames with the washer ``offset_m`` from its goal and the bracket 2 mm from its own."""
    poses = np.array([[GOAL[0] + offset_m[0], GOAL[1] + offset_m[1], 0.0], [-0.018, 0.0, 0.0]])
    for i in range(n):
        task._integrate_aims(t0 + i * dt, poses)
    return t0 + n * dt


def test_the_aim_integrates_the_error_and_the_waypoint_follows_it():
    task = _task()
    _frames(task, (0.002, 0.0), 11)                    # 2 mm off in x for 1 s (10 intervals)
    ax, ay = task.state[0].aim
    assert ax == pytest.approx(0.5 * -0.002 * 1.0) and ay == 0.0
    poses = np.array([[GOAL[0] + 0.002, GOAL[1], 0.0], [-0.018, 0.0, 0.0]])
    statuses = task._statuses(1.0, poses)
    way, _ = task._waypoints(poses, statuses)
    # The waypoint heads for the aim, 1 mm beyond the goal, not for the goal itself.
    plain = _task(integral_per_s=0.0)
    way0, _ = plain._waypoints(poses, plain._statuses(1.0, poses))
    assert way[0, 0] < way0[0, 0] and way[0, 1] == pytest.approx(way0[0, 1])


def test_the_aim_is_bounded_and_only_near_the_goal():
    task = _task()
    t = _frames(task, (0.006, 0.0), 30)                 # beyond integral_within_m: nothing
    assert task.state[0].aim == (0.0, 0.0)
    _frames(task, (0.0, -0.004), 2000, t0=t)            # long enough to pass integral_max_m
    assert math.hypot(*task.state[0].aim) == pytest.approx(0.004)
    assert task.state[0].aim[1] > 0                     # towards the part's error: the goal minus the pose


def test_it_waits_integral_after_s_and_point_parts_only_when_asked():
    task = _task(integral_after_s=2.0, integral_parts="point")
    t = _frames(task, (0.002, 0.0), 20)                 # near for 1.9 s: still waiting
    assert task.state[0].aim == (0.0, 0.0)
    _frames(task, (0.002, 0.0), 10, t0=t)
    assert task.state[0].aim[0] < 0
    assert task.state[1].aim == (0.0, 0.0)              # the bracket (rigid) is left alone

    off = _task(integral_per_s=0.0)
    _frames(off, (0.002, 0.0), 50)
    assert off.state[0].aim == (0.0, 0.0) and off._aimed(off.goals[0]) is off.goals[0]


@pytest.mark.parametrize("bad", [dict(integral_per_s=-1.0), dict(integral_max_m=math.nan),
                                 dict(integral_parts="rigid"), dict(integral_max_parts=-1)])
def test_bad_settings_are_refused(bad):
    with pytest.raises(ConfigError, match="integral_"):
        MpcSettings(**bad)

"""A rigid part far from its goal angle turned about its pivot (MpcSettings.pivot_from_rad).

The pivot is the fixed point of the rigid motion from the part's pose to its goal pose: turned about
it, the part arrives at its goal position and angle together. The spin moved to the pivot turns the
bracket about as fast as the spin in place and carries it along the circle, so the turn no longer
waits for the translation. Device time and model predictions only: no wall-clock assertions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ppod_ros.parts import published_rigid_part
from ppod_ros.planning import predict
from ppod_ros.planning.mpc import MpcSettings, MultiTask, PartGoal, pivot_point, template_motion

# Benchmark scene 16 of one bracket (seed 0): 24 mm from its goal, 151 deg off (the slowest scene: the
# bracket was carried home in 3 s without turning, then turned for 11 s at 10-13 deg/s).
START = np.array([[0.0037938, -0.0100548, -2.7296472]])
GOAL = PartGoal(0, 0.0240060, 0.0036306, 0.9155943)


def _turned(p, c, a):
    r = np.asarray(p[:2]) - c
    return c + np.array([math.cos(a) * r[0] - math.sin(a) * r[1], math.sin(a) * r[0] + math.cos(a) * r[1]])


@pytest.mark.parametrize("turn", [2.6, -2.6, 1.0, -1.2, math.pi])
def test_the_pivot_turns_the_pose_onto_the_goal_pose(turn):
    pose = np.array([0.01, -0.005, 0.3])
    goal = PartGoal(0, 0.03, 0.012, 0.3 + turn)
    c = pivot_point(pose, goal, turn)
    assert _turned(pose, c, turn) == pytest.approx([0.03, 0.012], abs=1e-12)
    assert pivot_point(pose, goal, 0.0) is None


def _known(task: MultiTask, scale: float = 1.0) -> MultiTask:
    """The part's velocity scale as estimated from a motion that moved it."""
    task.state[0].estimated, task.state[0].scale = True, scale
    return task


def test_the_waypoint_lies_on_the_circle_about_the_pivot_and_the_angle_weighs_in_full():
    part = published_rigid_part()
    on = _known(MultiTask([part], [GOAL]))
    off = _known(MultiTask([part], [GOAL], settings=MpcSettings(pivot_from_rad=0.0)))
    st = on._statuses(0.0, START)
    a = -float((START[0, 2] - GOAL.theta_rad + math.pi) % (2 * math.pi) - math.pi)
    c = on._pivot(GOAL, START[0])
    assert c is not None and off._pivot(GOAL, START[0]) is None
    way, _ = on._waypoints(START, st)
    turn = math.copysign(0.5, a)                       # max_turn_radps over the 1 s horizon
    assert way[0, :2] == pytest.approx(_turned(START[0], c, turn), abs=1e-12)
    assert way[0, 2] == pytest.approx(START[0, 2] + turn)
    assert on._angle_weights(st, START)[0] == pytest.approx(0.03)
    assert off._angle_weights(st, START)[0] == pytest.approx(0.03 * 0.01 / st[0].position_error_m)
    # Near its goal angle (within pivot_from_rad) the part is not pivoted.
    near = START.copy()
    near[0, 2] = GOAL.theta_rad - 0.5
    assert on._pivot(GOAL, near[0]) is None
    # Nor before its velocity scale is estimated, nor while the scale says high friction.
    assert MultiTask([part], [GOAL])._pivot(GOAL, START[0]) is None
    assert _known(MultiTask([part], [GOAL]), 0.6)._pivot(GOAL, START[0]) is None
    assert _known(MultiTask([part], [GOAL]), 0.8)._pivot(GOAL, START[0]) is not None
    # The template: the spin moved to the pivot, both ways (turning the bracket opposite ways).
    assert template_motion("pivot", MultiTask([part], [GOAL]), GOAL, START[0]) == []
    ms = template_motion("pivot", on, GOAL, START[0])
    v, ok = predict.predict_velocities(ms, part, START)
    assert len(ms) == 2 and ok.all() and v[0, 0, 2] * v[1, 0, 2] < 0


def test_the_bracket_is_turned_on_its_way_home():
    part = published_rigid_part()
    planned = {}
    for name, settings in (("on", MpcSettings()), ("off", MpcSettings(pivot_from_rad=0.0))):
        task = _known(MultiTask([part], [GOAL], settings=settings, timeout_s=30.0))
        task.step(0.0, START)
        v = task.last_prediction["velocity"][0]       # predicted, scaled: m/s and rad/s
        d0 = math.hypot(GOAL.x_m - START[0, 0], GOAL.y_m - START[0, 1])
        d1 = math.hypot(GOAL.x_m - START[0, 0] - v[0], GOAL.y_m - START[0, 1] - v[1])
        planned[name] = (math.degrees(v[2]), 1e3 * (d0 - d1))
    # Without the pivot the first motion carries the bracket home (mm/s closer) and hardly turns it;
    # with it the bracket turns the way home at the spin's rate and still closes in.
    turn_on, closer_on = planned["on"]
    turn_off, closer_off = planned["off"]
    a = GOAL.theta_rad - START[0, 2]
    a = (a + math.pi) % (2 * math.pi) - math.pi
    assert abs(turn_off) < 15.0 and closer_off > 10.0, planned
    assert math.copysign(1.0, turn_on) == math.copysign(1.0, a) and abs(turn_on) > 15.0, planned
    assert closer_on > 1.0, planned


def _scene16(settings: MpcSettings):
    """Benchmark scene 16 of one bracket as `ppod bench planner --sections multipart` runs it: the
    scene's bracket at friction 0.441 (the model says 0.3), the stack's plant error and tracker."""
    import dataclasses

    from ppod_ros.planning.simulate import ActuatorPlantError, run_on_dynamics
    from ppod_sim.ros_node import default_scene_path
    from ppod_sim.scene import load_scene

    bracket = next(p for p in load_scene(default_scene_path()).parts if p.label == "bracket").part
    true = dataclasses.replace(bracket, mu=np.full(len(bracket.mu), 0.4411153350400894), mu_static=None)
    goal = PartGoal(0, 0.024006020226564527, 0.0036305576587046706, 0.9155943430264353, 1e-3, math.radians(2))
    task = MultiTask([published_rigid_part()], [goal], settings=settings, timeout_s=30.0)
    start = [[0.0037938314183616866, -0.010054834568226624, -2.7296472176220012]]
    plant = ActuatorPlantError.random(np.random.default_rng(1023881567))
    run = run_on_dynamics(task, [true], start, horizon_s=31.0, ramp_s=0.5, latency_s=0.1, plant=plant,
                          seed=1023881567 % 1000, keep_steps=True)
    return run


def test_the_slowest_one_bracket_benchmark_scene_is_brought_in():
    # Without the pivot: carried home in 3 s, then turned 130 deg at 10-13 deg/s; time to goal 16.5 s
    # of device time here. With it, turned about its pivot whenever its velocity scale is at least
    # 0.75 (pivot_min_scale): 14.1 s on the thirteenth session's kernel, 17.3 s since the sticking
    # test's cone program is centred to 2e-10 (its values the same within 2.2e-16): this bracket's
    # friction (0.44) keeps its scale about the gate, and a last-bit change decides whether the pivot
    # is tried at all (now it is not in the first 3 s, as without it). So this is a closed-loop check
    # that both reach the goal, with room; the pivot's planning is checked above, its benefit over 40
    # benchmark scenes in docs/planner.md.
    for settings in (MpcSettings(), MpcSettings(pivot_from_rad=0.0)):
        run = _scene16(settings)
        assert run.step.done, run.step.text
        assert run.step.parts[0].time_to_goal_s < 25.0, run.step.text

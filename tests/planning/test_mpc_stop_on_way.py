"""Ranking a motion by stopping on its way (MpcSettings.stop_on_way).

One bracket's slowest benchmark scenes lost 5-7 s in the endgame: 0.1-0.7 mm from its goal and 4-8
deg off its angle, the planner ranked every motion by where it would leave the bracket after the 1 s
horizon. A turn that would bring it home in 0.4 s and overshoot by the horizon's end ranked below weak
motions that the model predicts badly, and a motion about to finish was switched away from. The
stop ahead (the plate stops at the frame from which the ramp down leaves every part within
stop_within of its tolerances) makes stopping on the way a real option: a motion whose predicted path
reaches such a frame costs at most that landing's distance from the goals. Device time and model
predictions only: no wall-clock assertions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion
from ppod_ros.parts import published_rigid_part
from ppod_ros.planning.mpc import MpcSettings, MultiTask, PartGoal
from ppod_ros.planning.simulate import ActuatorPlantError, run_on_dynamics

GOAL = PartGoal(0, 0.0, 0.0, 0.0, 1e-3, math.radians(2.0))
POSE = np.array([[2e-4, 0.0, math.radians(4.0)]])   # 0.2 mm and 4 deg from the goal


def test_settings_validate_the_stop_on_the_way():
    s = MpcSettings()
    assert s.stop_on_way and s.stop_on_way_frames == 2 and s.stop_on_way_playing_frames == 1
    for kw, name in ((dict(stop_on_way=1), "stop_on_way"), (dict(stop_on_way_frames=0), "stop_on_way_frames"),
                     (dict(stop_on_way_frames=11), "stop_on_way_frames"),
                     (dict(stop_on_way_playing_frames=True), "stop_on_way_playing_frames"),
                     (dict(stop_on_way_step_s=0.0), "stop_on_way_step_s"),
                     (dict(stop_on_way_step_s=float("nan")), "stop_on_way_step_s")):
        with pytest.raises(ConfigError, match=name):
            MpcSettings(**kw)


def _turning(*rates_degps: float):
    """Distinct non-zero motions (their keys differ) and model velocities turning the bracket in place
    at each rate (M, 1, 3)."""
    motions = [PlateMotion.from_phasors(30.0, [1], np.array([[0, 0, 0, 0, 0, 1.0 + i]], complex), name=f"m{i}")
               for i in range(len(rates_degps))]
    vel = np.zeros((len(rates_degps), 1, 3))
    vel[:, 0, 2] = np.radians(rates_degps)
    return motions, vel


def _finish(task: MultiTask, motions, vel) -> np.ndarray:
    task._v_current = np.zeros((1, 3))      # from rest
    return task._finish_costs(motions, vel, None, POSE)


def test_a_turn_that_passes_through_the_goal_can_stop_on_its_way():
    """From rest, 4 deg off: the linear ramp (0.5 s) and the stop's carry (the velocity then over half
    the ramp) land the bracket within 0.6 x 2 deg at 0.4-0.6 s turning home at 8 deg/s; at 60 deg/s
    only at the frame of 0.1 s (it lands 4.4 deg past the goal from the next); turning away, never."""
    task = MultiTask([published_rigid_part()], [GOAL])
    motions, vel = _turning(-8.0, 8.0, -60.0)
    cost = _finish(task, motions, vel)
    # The first frame within for two frames in a row: 0.5 s, where the 8 deg/s turn lands at 0.0 deg
    # (1.28 deg turned plus 1.6 deg of carry at 0.4 s; 2.0 + 2.0 at 0.5 s), 0.2 mm from the goal.
    assert cost[0] == pytest.approx((2e-4 / task.settings.max_speed_mps) ** 2, rel=1e-9)
    assert math.isinf(cost[1]) and math.isinf(cost[2])
    one = MultiTask([published_rigid_part()], [GOAL], settings=MpcSettings(stop_on_way_frames=1))
    fast = _finish(one, motions, vel)
    landed = math.radians(4.0 - 60.0 * (0.1 ** 2 / 1.0) - 60.0 * 0.2 * 0.25)   # 0.4 deg at 0.1 s
    expected = ((2e-4) ** 2 + (0.03 * landed) ** 2) / one.settings.max_speed_mps ** 2
    assert fast[2] == pytest.approx(expected, rel=1e-9)
    # The motion playing is judged on one frame: its prediction is learned under it.
    task.current = motions[2]
    assert _finish(task, motions, vel)[2] == pytest.approx(expected, rel=1e-9)


def test_the_ranking_takes_the_finish_only_where_it_is_cheaper_and_off_changes_nothing():
    task = MultiTask([published_rigid_part()], [GOAL])
    off = MultiTask([published_rigid_part()], [GOAL], settings=MpcSettings(stop_on_way=False))
    motions, vel = _turning(-8.0, 8.0, -60.0)
    for t in (task, off):
        t._v_current = np.zeros((1, 3))
    statuses = task._statuses(0.0, POSE)
    finish = _finish(task, motions, vel)
    task._velocities = off._velocities = lambda ms, poses, budget=False: (vel[:len(ms)], np.ones(len(ms), bool))
    r, _, _ = off._residuals(motions, POSE, statuses)
    plain = np.sum(r ** 2, axis=1)
    got_on, _ = task._costs(motions, POSE, statuses)
    got_off, _ = off._costs(motions, POSE, statuses)
    assert got_off == pytest.approx(plain, rel=1e-12)
    assert got_on == pytest.approx(np.minimum(plain, finish), rel=1e-12)
    assert got_on[0] < got_off[0]        # the turn home is worth more than its horizon's end says


def _bench_scene(seed: int, scene: int):
    """One bracket's benchmark scene (``ppod bench planner --sections multipart --counts 1``)."""
    import benchmarks.planner as bp

    templates, models = bp.multipart_models()
    rng = np.random.default_rng(1000 * seed + 1)
    for _ in range(scene + 1):
        sc = bp._multi_scene(1, rng, templates)
    true = [bp._true_part(templates["bracket"].part, sc["mu"][0])]
    goal = PartGoal(0, *sc["goals"][0], sc["goal_theta"], 1e-3, math.radians(2.0))
    return models["bracket"], true, sc, goal


@pytest.mark.slow
@pytest.mark.parametrize("seed, scene, off_s, on_s", [(0, 14, 15.6, 8.8), (2, 11, 18.5, 12.5)])
def test_benchmark_scenes_endgames(seed, scene, off_s, on_s):
    """One bracket's benchmark scenes (``ppod bench planner --sections multipart --counts 1``), in
    device time. Seed 0 scene 14 (friction 0.39, 135 deg off): within 0.3 mm at 8.5 s and 4-6 deg off;
    ranked by the horizon's end, the next 7 s went to weak motions that threw it 3.5 mm out and back
    (15.6 s); stopping on the way, the turn playing finished it (8.8 s). Seed 2 (scenes the settings
    were not tuned on) scene 11: 18.5 s against 12.5 s. Per scene the outcome is chaotic (a last-bit
    change moves it by seconds), so the bounds leave room; over 80 scenes: docs/planner.md."""
    from ppod_ros import physics

    model, true, sc, goal = _bench_scene(seed, scene)
    times = {}
    for on in (True, False):
        physics.WARM_STARTS.clear()   # the starts of a fresh process, as in the benchmark
        task = MultiTask([model], [goal], settings=MpcSettings(stop_on_way=on), timeout_s=30.0)
        plant = ActuatorPlantError.random(np.random.default_rng(sc["plant_seed"]))
        run = run_on_dynamics(task, true, sc["starts"], horizon_s=31.0, ramp_s=0.5, latency_s=0.1, plant=plant,
                              seed=sc["plant_seed"] % 1000)
        assert run.step is not None and run.step.done and run.step.failed_reason is None, run.step
        times[on] = run.step.parts[0].time_to_goal_s
    assert times[True] <= on_s + 2.0 and times[False] >= off_s - 2.0, times
    assert times[True] < times[False] - 4.0, times

"""The motion playing when the solver gives up on it (MpcSettings.hold_gave_up_m, hold_gave_up_rad).

A stick-slip cycle the planner solver's caps cut short ("not converged") at a pose near one where the
motion playing converged is predicted with that last prediction instead of ruling the motion out (an
infinite cost forced a switch away from a motion that works); contact lost is never held. Device time
and solver results only: no wall-clock assertions."""

from __future__ import annotations

import math

import numpy as np
import pytest

import ppod_ros.physics as physics
from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion
from ppod_ros.parts import PointPart, published_rigid_part
from ppod_ros.planning import predict
from ppod_ros.planning.mpc import MpcSettings, MultiTask, PartGoal, moved, spin_motion
from tests.support.scripted_solver import CODE, solver_result


def test_predict_tells_a_row_the_solver_gave_up_on_from_contact_lost():
    part = published_rigid_part()
    task = MultiTask([part], [PartGoal(0, 0.0, 0.0, 0.0)])
    spin = task._fitted(spin_motion(task.settings))
    stick_slip = moved(spin.scaled(0.9), 0.02, 0.0)     # needs hundreds of steps per period
    lifting = PlateMotion.single(30.0, [0, 0, 20.0, 0, 0, 0])  # 20 m/s^2 vertical: the part leaves the plate
    physics.WARM_STARTS.clear()
    v, ok, gave_up = predict.predict_velocities([stick_slip, lifting, PlateMotion.zero()], part,
                                                [[0.02, 0.0, 0.3]], predict.budgeted(12, 200), gave_up=True)
    assert not ok[0, 0] and gave_up[0, 0]          # out of the budget: the solver gave up
    assert not ok[1, 0] and not gave_up[1, 0]      # contact lost: a property of the motion
    assert ok[2, 0] and not gave_up[2, 0]
    assert set(predict.GAVE_UP_CODES) == {CODE["not converged"], CODE["not converged (step limit)"]}
    assert len(predict.predict_velocities([lifting], part, [[0.02, 0.0, 0.3]])) == 2  # the documented pair


class _Scripted:
    """A solve_fields whose rows of one motion are valid (velocity ``v``) or invalid with a reason."""

    def __init__(self, key: bytes, v: np.ndarray):
        self.key, self.v, self.reason = key, v, None

    def __call__(self, motions, part, configs, settings=None, **kw):
        m, n = len(motions), len(configs)
        velocity = np.full((m, n, 3), 0.001)
        valid = np.ones((m, n), bool)
        code = np.zeros((m, n), int)
        for i, motion in enumerate(motions):
            if motion.key == self.key:
                velocity[i] = self.v
                if self.reason is not None:
                    valid[i], code[i], velocity[i] = False, CODE[self.reason], np.nan
        return solver_result(velocity, valid, code)


def _playing(settings: MpcSettings | None = None):
    task = MultiTask([published_rigid_part()], [PartGoal(0, 0.0, 0.0, 0.0)], timeout_s=30.0, settings=settings)
    task.current = task._fitted(spin_motion(task.settings))
    return task


@pytest.mark.parametrize("reason, moved_m, turned_rad, settings, held", [
    ("not converged", 0.002, 0.05, None, True),
    ("not converged (step limit)", 0.004, -0.1, None, True),
    ("contact lost", 0.002, 0.05, None, False),                       # never held
    ("not converged", 0.008, 0.0, None, False),                       # too far from where it converged
    ("not converged", 0.001, 0.3, None, False),                       # turned too far
    ("not converged", 0.002, 0.05, MpcSettings(hold_gave_up_m=0.0), False),  # off
])
def test_the_motion_playing_keeps_its_last_prediction_when_the_solver_gives_up_nearby(
        monkeypatch, reason, moved_m, turned_rad, settings, held):
    task = _playing(settings)
    v0 = np.array([0.004, -0.002, 0.05])
    solver = _Scripted(task.current.key, v0)
    monkeypatch.setattr(physics, "solve_fields", solver)
    poses = np.array([[0.02, 0.01, 0.5]])
    task._hold_playing(poses)                       # converged here: remembered
    vel, ok = task._velocities([task.current], poses)
    assert ok[0] and np.allclose(vel[0, 0], v0) and task.held_predictions == 0
    solver.reason = reason
    near = poses + [[moved_m, 0.0, turned_rad]]
    task._hold_playing(near)
    vel, ok = task._velocities([task.current], near)
    assert bool(ok[0]) is held and task.held_predictions == int(held)
    statuses = task._statuses(0.0, near)
    cost, _ = task._costs([task.current], near, statuses)
    assert math.isfinite(float(cost[0])) is held
    if held:
        assert np.allclose(vel[0, 0], v0)           # the last converged prediction
        # Held from where it last converged, not from the held pose: far enough, and it is out.
        far = poses + [[0.006, 0.0, 0.0]]
        task._hold_playing(far)
        assert not task._velocities([task.current], far)[1][0]


def test_a_replanning_step_keeps_a_motion_the_solver_gave_up_on_in_play(monkeypatch):
    """Through MultiTask.step: the motion the first step chose, not converged at the next poses
    (3 mm on), is costed with its last prediction instead of being infinitely bad."""
    part = published_rigid_part()
    task = MultiTask([part], [PartGoal(0, 0.0, 0.0, 0.0)], timeout_s=30.0)
    start = np.array([[0.03, 0.02, 0.8]])
    first = task.step(0.0, start)
    assert first.motion is not None
    playing = task.current
    real = physics.solve_fields

    def solve_fields(motions, part_, configs, settings=None, **kw):
        r = real(motions, part_, configs, settings=settings, **kw)
        rows = [i for i, m in enumerate(motions) if m.key == playing.key]
        if rows:
            valid, code = np.asarray(r.valid).copy(), np.asarray(r.reason_code).copy()
            valid[rows], code[rows] = False, CODE["not converged"]

            class Result:
                pass

            out = Result()
            out.velocity, out.valid, out.reason_code = np.asarray(r.velocity), valid, code
            return out
        return r

    monkeypatch.setattr(physics, "solve_fields", solve_fields)
    nxt = start + [[-0.003, 0.0, 0.0]]
    task.step(0.5, nxt)
    assert task.held_predictions == 1
    statuses = task._statuses(0.5, nxt)
    cost, _ = task._costs([playing], nxt, statuses)
    assert math.isfinite(float(cost[0]))


@pytest.mark.parametrize("rest_dwell_s, restarts", [(0.5, True), (None, False)])
def test_from_the_plate_at_rest_the_next_motion_waits_only_for_the_ramp(rest_dwell_s, restarts):
    """A part out of tolerance after the plate stopped (the ramp down carried it back out) gets its
    next motion once the ramp is over (MpcSettings.rest_dwell_s), not after min_dwell_s."""
    task = MultiTask([PointPart(0.3)], [PartGoal(0, 0.0, 0.0)], timeout_s=30.0,
                     settings=MpcSettings(rest_dwell_s=rest_dwell_s))
    poses = [[0.03, 0.01, 0.0]]
    assert task.step(0.0, poses).motion is not None
    task.plate_stopped(0.2, poses)
    assert task.current.is_zero() and task.t_switch == 0.2
    assert task.step(0.3, poses).motion is None          # the ramp down still playing
    step = task.step(0.8, poses)                         # 0.6 s after the stop: min_dwell_s (1 s) not over
    assert (step.motion is not None) is restarts
    if restarts:
        assert not step.motion.is_zero()


def test_rest_dwell_is_validated():
    with pytest.raises(ConfigError, match="rest_dwell_s"):
        MpcSettings(rest_dwell_s=-0.1)
    with pytest.raises(ConfigError, match="hold_gave_up_m"):
        MpcSettings(hold_gave_up_m=math.nan)

"""Fitted candidates the solver gave up on (MpcSettings.gave_up_max_steps_per_period, gave_up_max_periods,
gave_up_near_m).

A fitted candidate (a template kind for a goal, by name) the solver gave up on at the planner's caps
("not converged", a stick-slip cycle) is solved on the smaller give-up budget at the next steps while
each part it gave up at is within gave_up_near_m / hold_gave_up_rad of its pose there; the pose is not
re-recorded on the budget (the budget cannot follow the part along its path), and a candidate that
converges or loses contact is forgotten. Device time and solver results only: no wall-clock
assertions."""

from __future__ import annotations

import numpy as np
import pytest

import ppod_ros.physics as physics
from ppod_ros.errors import ConfigError
from ppod_ros.parts import PointPart, published_rigid_part
from ppod_ros.planning import predict
from ppod_ros.planning.mpc import MpcSettings, MultiTask, PartGoal, moved, spin_motion
from tests.support.scripted_solver import CODE, solver_result


class _Scripted:
    """A solve_fields that records the step cap each motion was solved with, and answers the rigid rows
    of the motion named ``name`` with ``reason`` (None: valid)."""

    def __init__(self, name: str):
        self.name, self.reason, self.caps = name, "not converged (step limit)", []

    def __call__(self, motions, part, configs, settings=None, **kw):
        m, n = len(motions), len(configs)
        dim = np.asarray(configs).shape[1]
        velocity, valid, code = np.full((m, n, dim), 0.001), np.ones((m, n), bool), np.zeros((m, n), int)
        for i, motion in enumerate(motions):
            if motion.name == self.name and dim == 3:
                self.caps.append(settings.max_steps_per_period)
                if self.reason is not None:
                    valid[i], code[i], velocity[i] = False, CODE[self.reason], np.nan
        return solver_result(velocity, valid, code)


ON = MpcSettings(gave_up_max_steps_per_period=800, gave_up_max_periods=12)   # the values measured (an option)


def _task(settings: MpcSettings = ON):
    # A bracket and a washer: the washer's row never gives up, so only the bracket's pose matters.
    return MultiTask([published_rigid_part(), PointPart(0.3)],
                     [PartGoal(0, 0.0, 0.0, 0.0), PartGoal(1, -0.035, 0.03)], settings=settings)


def _solve(task, name: str, poses: np.ndarray):
    """One replanning step's fitted-candidate evaluation of the spin named ``name`` at ``poses``, as
    MultiTask._plan does it."""
    spin = moved(task._fitted(spin_motion(task.settings)).scaled(0.85), *poses[0, :2], name=name)
    vel, ok = task._velocities([spin], poses, task._suspects([spin], poses))
    task._note_gave_up([spin], poses)
    return bool(ok[0])


def test_a_fitted_candidate_the_solver_gave_up_on_is_solved_on_the_budget_near_where_it_did(monkeypatch):
    task = _task()
    solver = _Scripted("spin+@0")
    monkeypatch.setattr(physics, "solve_fields", solver)
    full, budget = predict.PLANNER_SOLVER.max_steps_per_period, task.settings.gave_up_max_steps_per_period
    p0 = np.array([[0.02, 0.01, 0.5], [0.0, 0.03, 0.0]])
    assert not _solve(task, "spin+@0", p0)                          # gave up at the full caps: recorded
    far_washer = p0 + [[0.004, 0.0, 0.1], [0.03, 0.0, 0.0]]          # the washer's pose does not matter
    assert not _solve(task, "spin+@0", far_washer)
    assert _solve(task, "spin-@0", far_washer) and "spin-@0" not in task._gave_up_at   # by name
    # 9 mm from where it last gave up at full caps (not re-recorded on the budget: 5 mm from the last try).
    assert not _solve(task, "spin+@0", p0 + [[0.009, 0.0, 0.0], [0.0, 0.0, 0.0]])
    assert not _solve(task, "spin+@0", p0 + [[0.0, 0.0, 0.2], [0.0, 0.0, 0.0]])   # turned 11 deg: full again
    assert not _solve(task, "spin+@0", p0 + [[0.011, 0.0, 0.0], [0.0, 0.0, 0.0]])  # 11 mm from there: full
    assert solver.caps == [full, budget, budget, full, full]
    # Converged (within the budget, 1 mm from the last record): forgotten, so solved at full caps next.
    solver.reason, solver.caps = None, []
    p1 = p0 + [[0.012, 0.0, 0.0], [0.0, 0.0, 0.0]]
    assert _solve(task, "spin+@0", p1) and "spin+@0" not in task._gave_up_at
    assert _solve(task, "spin+@0", p1 + [[0.001, 0.0, 0.0], [0.0, 0.0, 0.0]])
    assert solver.caps == [budget, full]
    # Contact lost is a property of the motion, not of the solver's caps: never solved on the budget.
    solver.reason, solver.caps = "contact lost", []
    assert not _solve(task, "spin+@0", p1)
    assert not _solve(task, "spin+@0", p1 + [[0.001, 0.0, 0.0], [0.0, 0.0, 0.0]])
    assert solver.caps == [full, full]


def test_the_give_up_budget_is_off_by_default(monkeypatch):
    task = _task(MpcSettings())
    solver = _Scripted("spin+@0")
    monkeypatch.setattr(physics, "solve_fields", solver)
    p0 = np.array([[0.02, 0.01, 0.5], [0.0, 0.03, 0.0]])
    for i in range(3):
        assert not _solve(task, "spin+@0", p0 + [[0.001 * i, 0.0, 0.0], [0.0, 0.0, 0.0]])
    assert solver.caps == [predict.PLANNER_SOLVER.max_steps_per_period] * 3


def test_a_suspect_that_converges_within_the_budget_has_its_full_result():
    """The real solver, the bracket 20 mm off the centre: the fitted spin at 0.9 of its amplitude
    converges within the give-up budget (800 steps per period) to the same twist as at the planner's
    caps (from the same start); at 0.8 it needs more (the budget's price: out where it would
    converge); at 0.7 the solver gives up either way."""
    part = published_rigid_part()
    task = MultiTask([part], [PartGoal(0, 0.0, 0.0, 0.0)], settings=ON)
    spin = task._fitted(spin_motion(task.settings))
    motions = [moved(spin.scaled(a), 0.02, 0.0, name=f"spin{a}") for a in (0.9, 0.8, 0.7)]
    poses = np.array([[0.02, 0.0, 0.3]])
    physics.WARM_STARTS.clear()
    v, ok = task._velocities(motions, poses)
    task._memo_poses = None
    physics.WARM_STARTS.clear()
    vb, okb = task._velocities(motions, poses, frozenset(m.key for m in motions))
    assert ok.tolist() == [True, True, False] and okb.tolist() == [True, False, False]
    assert np.array_equal(v[0], vb[0])
    for m in motions[1:]:
        assert task._memo[m.key][2:] == (True, True)   # budgeted, given up on (not contact lost)


def test_settings_validate_the_give_up_budget():
    s = MpcSettings()
    assert (s.gave_up_max_steps_per_period, s.gave_up_max_periods, s.gave_up_near_m) == (0, 0, 0.01)
    for bad in (-1, 2.5):
        with pytest.raises(ConfigError, match="gave_up_max_steps_per_period"):
            MpcSettings(gave_up_max_steps_per_period=bad)
    with pytest.raises(ConfigError, match="gave_up_near_m"):
        MpcSettings(gave_up_near_m=-0.001)

"""The replanning step's solver work (ppod_ros/planning/predict.py budgeted, MultiTask._refine).

The Gauss-Newton probes and line-search trials are solved on a smaller, deterministic budget
(MpcSettings.probe_max_periods, probe_max_steps_per_period) than the candidates: a row converges
within it to the same result, or is out. Device time and solver counts only: no wall-clock
assertions."""

from __future__ import annotations

import math

import numpy as np
import pytest

import ppod_ros.physics as physics
from ppod_ros.errors import ConfigError
from ppod_ros.parts import PointPart, published_rigid_part
from ppod_ros.planning import predict
from ppod_ros.planning.mpc import MpcSettings, MultiTask, PartGoal, moved, spin_motion


def test_budgeted_settings_cap_the_work_and_keep_the_results_of_rows_that_converge():
    budget = predict.budgeted(12, 200)
    assert (budget.max_periods, budget.max_steps_per_period) == (12, 200)
    assert budget.replace(max_periods=40, max_steps_per_period=1500) == predict.PLANNER_SOLVER
    assert predict.budgeted(0, 0) == predict.PLANNER_SOLVER            # 0: unchanged
    assert predict.budgeted(100, 5000) == predict.PLANNER_SOLVER       # never above the planner's caps
    with pytest.raises(ConfigError, match="max_steps_per_period"):
        predict.budgeted(12, -1)
    part = published_rigid_part()
    task = MultiTask([part], [PartGoal(0, 0.0, 0.0, 0.0)])
    spin = task._fitted(spin_motion(task.settings))
    cfg = [[0.02, 0.0, 0.3]]
    # The spin at full amplitude converges within the budget: from the same start, the same twist bit
    # for bit. At 0.9
    # of it the bracket's contacts stick and slip in turn: the planner's caps solve it (hundreds of
    # steps per period), the budget gives up on it.
    full = [moved(spin, 0.02, 0.0), moved(spin.scaled(0.9), 0.02, 0.0)]
    physics.WARM_STARTS.clear()   # the same starts for both
    v, ok = predict.predict_velocities(full, part, cfg)
    physics.WARM_STARTS.clear()
    vb, okb = predict.predict_velocities(full, part, cfg, budget)
    assert ok.all() and okb[0].all() and not okb[1].any()
    assert np.array_equal(v[0], vb[0]) and np.all(np.isnan(vb[1]))


def test_settings_validate_the_probe_budget():
    assert MpcSettings().probe_max_steps_per_period == 200 and MpcSettings().probe_max_periods == 12
    for bad in (-1, 2.5, "200"):
        with pytest.raises(ConfigError, match="probe_max_steps_per_period"):
            MpcSettings(probe_max_steps_per_period=bad)


def _recording(monkeypatch):
    calls = []
    real = physics.solve_fields

    def solve_fields(motions, part, configs, settings=None, **kw):
        r = real(motions, part, configs, settings=settings, **kw)
        calls.append((settings, [m.key for m in motions], np.asarray(r.valid).copy(), np.asarray(r.periods).copy()))
        return r

    monkeypatch.setattr(physics, "solve_fields", solve_fields)
    return calls


def test_a_replanning_step_bounds_the_solver_work_of_its_probes_and_trials(monkeypatch):
    calls = _recording(monkeypatch)
    part = published_rigid_part()
    task = MultiTask([part], [PartGoal(0, 0.02, -0.02, 0.0)], timeout_s=30.0)
    refine_keys = []
    real_refine = task._refine

    def refine(start, poses, statuses):
        before = len(calls)
        out = real_refine(start, poses, statuses)
        refine_keys.extend(calls[before:])
        return out

    task._refine = refine
    step = task.step(0.0, [[0.04, 0.03, 1.2]])
    assert step.motion is not None and step.plan_ms > 0
    assert refine_keys, "the step ran no Gauss-Newton probes"
    for settings, _keys, _valid, periods in refine_keys:
        assert settings.max_steps_per_period == 200 and settings.max_periods == 12
        assert periods.max() <= 12
    # Without a budget the probes run on the planner's caps.
    calls.clear()
    plain = MultiTask([part], [PartGoal(0, 0.02, -0.02, 0.0)], timeout_s=30.0,
                      settings=MpcSettings(probe_max_steps_per_period=0, probe_max_periods=0))
    plain.step(0.0, [[0.04, 0.03, 1.2]])
    assert {c[0].max_steps_per_period for c in calls} == {predict.PLANNER_SOLVER.max_steps_per_period}


def test_a_motion_out_of_the_budget_is_solved_again_without_it_and_others_are_not(monkeypatch):
    part = published_rigid_part()
    task = MultiTask([part], [PartGoal(0, 0.0, 0.0, 0.0)], timeout_s=30.0)
    spin = task._fitted(spin_motion(task.settings))
    fast, slow = moved(spin, 0.02, 0.0), moved(spin.scaled(0.9), 0.02, 0.0)
    poses = np.array([[0.02, 0.0, 0.3]])
    calls = _recording(monkeypatch)
    v, ok = task._velocities([fast, slow], poses, budget=True)
    assert list(ok) == [True, False] and np.all(v[1] == 0.0)
    v2, ok2 = task._velocities([fast, slow], poses)            # the candidates' caps
    assert list(ok2) == [True, True] and np.array_equal(v2[0], v[0])
    assert [len(c[1]) for c in calls] == [2, 1]                 # only the one out of the budget again
    assert calls[1][1] == [slow.key] and calls[1][0] == predict.PLANNER_SOLVER


@pytest.mark.parametrize("poses", [[[0.04, 0.03, 0.0], [-0.03, -0.02, 0.0]], [[-0.05, 0.0, 0.0], [0.0, 0.045, 0.0]]])
def test_the_budget_changes_nothing_where_every_probe_converges_within_it(poses):
    """Point parts (washers) converge in a few steps: the budgeted plan is the plan without it. (Not
    with the pair rotations, swap_from_rad: from the first poses the Gauss-Newton search starts at the
    rotation about a point between the washers, and one of its probes needs more than the budget.)"""
    goals = [PartGoal(0, 0.02, -0.02), PartGoal(1, -0.03, 0.03)]
    parts = [PointPart(0.3), PointPart(0.25)]
    plans = []
    for settings in (MpcSettings(swap_from_rad=0.0),
                     MpcSettings(swap_from_rad=0.0, probe_max_steps_per_period=0, probe_max_periods=0)):
        physics.WARM_STARTS.clear()   # the same warm starts for both
        task = MultiTask(parts, goals, timeout_s=30.0, settings=settings)
        step = task.step(0.0, poses)
        plans.append(step.motion)
    assert plans[0] is not None and plans[0].key == plans[1].key
    assert math.isfinite(float(np.abs(plans[0].phasor_table(1)).max()))


def test_budgeted_calls_share_the_warm_starts_of_the_unbudgeted_ones(monkeypatch):
    """A probe starts from the limit cycle the candidates found at the same configuration (the
    work caps are in the solver's warm-start key, the limit cycle does not depend on them)."""
    calls = _recording(monkeypatch)
    part = published_rigid_part()
    task = MultiTask([part], [PartGoal(0, 0.0, 0.0, 0.0)])
    spin = moved(task._fitted(spin_motion(task.settings)), 0.02, 0.0)
    cfg = [[0.02, 0.0, 0.3]]
    physics.WARM_STARTS.clear()
    predict.predict_velocities([spin], part, cfg)                          # cold: several periods
    predict.predict_velocities([spin], part, cfg, predict.budgeted(12, 200))
    cold, warm = calls[0][3].max(), calls[1][3].max()
    assert warm < cold
    assert len(physics.WARM_STARTS) == 1                                   # one entry, not one per budget


def test_the_fitted_candidates_are_budgeted_only_when_asked():
    part = published_rigid_part()
    for on in (False, True):
        task = MultiTask([part], [PartGoal(0, 0.02, -0.02, 0.0)], timeout_s=30.0,
                         settings=MpcSettings(budget_fitted=on))
        fitted, costs = [], []
        real_fitted, real_costs = task._fitted_many, task._costs

        def spy_fitted(motions, _out=fitted, _real=real_fitted):
            out = _real(motions)
            _out.extend(m.key for m in out)
            return out

        def spy_costs(motions, poses, statuses, budget=False, ramped=False, _out=costs, _real=real_costs):
            _out.append(([m.key for m in motions], budget))
            return _real(motions, poses, statuses, budget, ramped)

        task._fitted_many, task._costs = spy_fitted, spy_costs
        task.step(0.0, [[0.04, 0.03, 1.2]])
        ranked = [budget for keys, budget in costs if len(keys) > 1 and set(keys) <= set(fitted)]
        assert ranked == [on]

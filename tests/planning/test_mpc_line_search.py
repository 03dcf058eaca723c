"""The Gauss-Newton search's line search (MpcSettings.line_search, MultiTask._refine).

"best" fits and solves all three step lengths (1, 1/2, 1/4) and takes the cheapest if it lowers the
cost; "first" fits and solves them one at a time, longest first, and takes the first that lowers it.
Model predictions and the envelope only: no wall-clock assertions."""

from __future__ import annotations

import numpy as np
import pytest

import ppod_ros.planning.mpc as mpc
from ppod_ros.errors import ConfigError
from ppod_ros.parts import PointPart, published_rigid_part
from ppod_ros.planning.mpc import MpcSettings, MultiTask, PartGoal

PARTS = [published_rigid_part(), PointPart(0.3), PointPart(0.3)]
GOALS = [PartGoal(0, 0.02, -0.02, 0.0, 2e-3, np.radians(3)), PartGoal(1, -0.03, 0.02, None, 2e-3),
         PartGoal(2, 0.03, 0.03, None, 2e-3)]
POSES = [[-0.03, 0.03, 1.0], [0.035, -0.01, 0.0], [0.0, -0.04, 0.0]]


def test_settings_validate_the_line_search():
    assert MpcSettings().line_search == "first"
    with pytest.raises(ConfigError, match="line_search"):
        MpcSettings(line_search="armijo")


def _refine_record(monkeypatch, line_search: str):
    """One planning step from POSES; per Gauss-Newton step of its search, the trial batches fitted
    and their costs, and the cost before the step."""
    task = MultiTask(PARTS, GOALS, timeout_s=30.0, settings=MpcSettings(line_search=line_search))
    batches = []
    real_fit = mpc.fit_envelope_many

    def fit(motions, *a, **k):
        out = real_fit(motions, *a, **k)
        batches.append([m for m, _ in out])
        return out

    real_costs = task._costs
    costs_of = {}

    def costs(motions, poses, statuses, budget=False):
        c, v = real_costs(motions, poses, statuses, budget)
        for m, x in zip(motions, c):
            costs_of[m.key] = float(x)
        return c, v

    real_refine = task._refine
    seen = {}

    def refine(start, poses, statuses):
        batches.clear()
        monkeypatch.setattr(mpc, "fit_envelope_many", fit)
        task._costs = costs
        try:
            out = real_refine(start, poses, statuses)
        finally:
            monkeypatch.setattr(mpc, "fit_envelope_many", real_fit)
            task._costs = real_costs
        seen.update(start=costs_of[start.key], out=out, batches=[list(b) for b in batches])
        return out

    task._refine = refine
    step = task.step(0.0, POSES)
    assert step.motion is not None and seen, "the step ran no Gauss-Newton search"
    return seen, costs_of


@pytest.mark.parametrize("line_search", ["best", "first"])
def test_the_search_takes_only_steps_that_lower_the_cost_and_fits_every_trial(monkeypatch, line_search):
    seen, costs_of = _refine_record(monkeypatch, line_search)
    refined, refined_cost = seen["out"]
    batches = seen["batches"]
    assert batches, "no trial was fitted"
    assert {len(b) for b in batches} == ({3} if line_search == "best" else {1})
    assert refined is not None and refined_cost < seen["start"]   # from these poses the search helps
    assert refined.key in {m.key for b in batches for m in b}     # a fitted trial, as fitted
    assert refined_cost == costs_of[refined.key]


def test_first_takes_the_longest_step_that_lowers_the_cost(monkeypatch):
    seen, costs_of = _refine_record(monkeypatch, "first")
    best = seen["start"]
    tried = [b[0] for b in seen["batches"]]
    # The trials of each Gauss-Newton step come in threes at most, longest first: every trial not
    # taken did not lower the cost below the best so far; each one taken did, and ends its step.
    i = 0
    while i < len(tried):
        step = []
        while i < len(tried) and len(step) < 3:
            step.append(tried[i])
            i += 1
            if costs_of[step[-1].key] < best:
                break
        *rejected, last = step
        assert all(costs_of[m.key] >= best for m in rejected)
        if costs_of[last.key] < best:
            best = costs_of[last.key]
        else:
            assert i == len(tried)   # a step none of whose trials helped ends the search
    assert seen["out"][0] is not None and seen["out"][1] == best

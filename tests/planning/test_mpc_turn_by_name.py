"""A part's turn scale per motion name (MpcSettings.turn_scale_by_name).

A bracket of high friction turns at about 0.3 of the model under the refined motions ("mpc") and
0.6 under the spin moved to it ("spin-@0"): one turn scale for every motion not playing ranks them
as the model does, and the planner kept refined motions that turned it at 7 deg/s where the spin
turned it at 11-18 deg/s (benchmark one-bracket scenes 3 and 16, seed 0). With the setting, each
name keeps its own scale, learned while a motion of that name played. Model scales only: no
wall-clock assertions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ppod_ros.parts import published_rigid_part
from ppod_ros.planning.mpc import MpcSettings, MultiTask, PartGoal, spin_motion
from tests.support.named_motions import named_motions


def _task(on: bool) -> MultiTask:
    return MultiTask([published_rigid_part()], [PartGoal(0, 0.0, 0.0, 0.0, 1e-3, math.radians(2))],
                     settings=MpcSettings(turn_scale_by_name=on))


def _learn(task: MultiTask, motion, ratio: float, times: int = 12) -> None:
    st = task.state[0]
    for _ in range(times):
        task._estimate_turn(st, motion.key, motion.name, 0.1, 0.1 * ratio)


@pytest.mark.parametrize("on", [True, False])
def test_each_name_keeps_the_turn_scale_learned_under_it(on):
    task = _task(on)
    spin = spin_motion(task.settings)
    spin_here, spin_there, refined, other = named_motions(spin, "spin-@0", "sink@0")
    _learn(task, spin_here, 0.6)
    _learn(task, refined, 0.3)       # the refined motion plays last
    st = task.state[0]
    scales = task._axis_scales([spin_there, refined, other])[:, 0, 2]
    assert scales[1] == pytest.approx(0.3, abs=0.01)      # the motion playing: its own (turn_now)
    if on:
        assert st.turn_by_name == pytest.approx({"spin-@0": 0.6, "mpc": 0.3}, abs=0.01)
        # Another spin moved elsewhere (another key) is ranked with the spin's scale; a name never
        # played with the part's scale over every motion.
        assert scales[0] == pytest.approx(0.6, abs=0.01)
        assert scales[2] == st.turn
    else:
        assert st.turn_by_name == {}
        assert scales[0] == scales[2] == st.turn
    # The translation's scale is not touched by the turn's.
    assert np.all(task._axis_scales([spin_there, refined, other])[:, 0, :2] == st.scale)

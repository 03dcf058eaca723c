"""A part's translation scale per motion name (MpcSettings.scale_by_name), as the turn's.

Friction slows a weak motion more than a strong one, and the refined motions ("mpc") are the weak
ones near a goal: one translation scale learned over every motion ranks a template whose scale is
0.9 with the 0.4 a refined motion taught, or the other way round. With the setting each name keeps
its own, learned while a motion of that name played. Model scales only: no wall-clock
assertions."""

from __future__ import annotations

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.parts import PointPart, published_rigid_part
from ppod_ros.planning.mpc import MpcSettings, MultiTask, PartGoal, _Segment
from tests.support.named_motions import named_motions


def _task(by_name: str, rigid: bool = False) -> MultiTask:
    part = published_rigid_part() if rigid else PointPart(0.3)
    return MultiTask([part], [PartGoal(0, 0.0, 0.0)], settings=MpcSettings(scale_by_name=by_name))


def _learn(task: MultiTask, motion, ratio: float, times: int = 12) -> None:
    """``motion`` plays; over each 0.5 s segment the washer moves ``ratio`` times its predicted 1 mm."""
    task.current = motion
    v = np.array([[0.002, 0.0, 0.0]])
    t = 0.0
    for _ in range(times):
        start = np.array([[0.02, 0.01, 0.0]])
        task.segment = _Segment(t, start, v, v, motion.key)
        task._estimate(t + 0.5, start + np.array([[0.5 * 0.002 * ratio, 0.0, 0.0]]))
        t += 0.5


@pytest.mark.parametrize("by_name, rigid", [("all", False), ("rigid", True), ("rigid", False), ("off", True)])
def test_each_name_keeps_the_translation_scale_learned_under_it(by_name, rigid):
    task = _task(by_name, rigid)
    on = by_name == "all" or (by_name == "rigid" and rigid)
    sink = task._base("sink")
    sink_here, sink_there, refined, other = named_motions(sink, "sink@0", "carry@0")
    _learn(task, sink_here, 0.9)
    _learn(task, refined, 0.4)       # the refined motion plays last
    st = task.state[0]
    scales = task._axis_scales([sink_there, refined, other])[:, 0, :]
    assert st.scale == pytest.approx(0.4, abs=0.01)   # the part's: the last motions taught it
    if on:
        assert st.scale_by_name == pytest.approx({"sink@0": 0.9, "mpc": 0.4}, abs=0.01)
        # Another sink moved elsewhere (another key) is ranked with the sink's scale; a name never
        # played with the part's. Without a goal angle theta follows the translation.
        np.testing.assert_allclose(scales[0], 0.9, atol=0.01)
        np.testing.assert_allclose(scales[1], 0.4, atol=0.01)
        np.testing.assert_allclose(scales[2], st.scale)
        # The motion playing: its own name's scale.
        np.testing.assert_allclose(task._axis_scales()[0, :2], st.scale_by_name["mpc"])
    else:
        assert st.scale_by_name == {}
        np.testing.assert_allclose(scales, st.scale)
    with pytest.raises(ConfigError, match="scale_by_name"):
        MpcSettings(scale_by_name="yes")

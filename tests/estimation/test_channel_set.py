"""The feedback's channel set: persistent evidence only, clean restart of learning, dead data stops it."""

import numpy as np
import pytest

from ppod_ros.control.online import FeedbackLoop, OnlineSettings
from ppod_ros.device import default_device_config
from ppod_ros.estimation import EstimationError
from ppod_ros.estimation.channel_set import ChannelSet, ChannelSetSettings
from ppod_ros.motion import PlateMotion

NAMES = [f"c{i}" for i in range(4)]


def _status(bad=()):
    return {n: ("flat" if n in bad else "ok") for n in NAMES}


def test_a_channel_leaves_only_after_persistent_drops_and_returns_only_after_a_longer_good_run():
    cs = ChannelSet(NAMES, ChannelSetSettings(drop_after=3, restore_after=5))
    assert cs.observe(_status({"c1"})) is None and cs.observe(_status({"c1"})) is None
    change = cs.observe(_status({"c1"}))
    assert list(change.removed) == ["c1"] and "3 consecutive estimates: flat" in change.removed["c1"]
    assert cs.active == ("c0", "c2", "c3")
    for _ in range(4):
        assert cs.observe(_status()) is None
    assert cs.observe(_status()).restored == ("c1",)
    assert cs.active == tuple(NAMES)


def test_a_flickering_channel_never_changes_the_set():
    cs = ChannelSet(NAMES, ChannelSetSettings(drop_after=3, restore_after=5))
    for i in range(40):
        assert cs.observe(_status({"c2"} if i % 3 else set())) is None
    assert cs.active == tuple(NAMES)


def test_bad_settings_are_refused():
    with pytest.raises(Exception, match="drop_after"):
        ChannelSetSettings(drop_after=0)


GOAL = PlateMotion(30, [1], [[8, 0, 0, 0, 60, 0]], [[0, 0, 0, 0, 1.0, 0]], name="sinkish")


def _summaries(loop, n, broken=None, seed=0):
    """Noisy first-order summaries of GOAL on the loop's layout (phasors (K=6, C))."""
    rng = np.random.default_rng(seed)
    layout = loop.estimator.layout
    H = layout.measurement_matrix()
    U = GOAL.phasor_table(6)
    for _ in range(n):
        P = U @ H.T + (rng.normal(0, 0.01, (6, 12)) + 1j * rng.normal(0, 0.01, (6, 12)))
        if broken is not None:
            P[:, broken] = 0.0
        yield np.arange(1, 7), P


def test_the_loop_restarts_learning_once_when_a_channel_leaves_and_stops_on_a_dead_acquisition():
    loop = FeedbackLoop(default_device_config(), OnlineSettings(summaries_per_estimate=1, settle_s=0.0),
                        channel_set=ChannelSetSettings(drop_after=2, restore_after=5))
    loop.set_goal(GOAL, 0.0)
    now = 1.0
    outs = []
    for k, P in _summaries(loop, 3):
        outs.append(loop.on_summary(k, P, 30.0, 200, now))
        now += 1.0
    assert all(o.channel_change is None and o.step is not None for o in outs)
    assert loop.controller.iteration == 3
    changes = []
    NAME3 = loop.estimator.layout.names[3]
    for k, P in _summaries(loop, 4, broken=3, seed=1):
        out = loop.on_summary(k, P, 30.0, 200, now)
        now += 1.0
        assert NAME3 in out.estimate.dropped or NAME3 not in out.estimate.channels
        changes.append(out.channel_change)
    assert [c is not None for c in changes] == [False, True, False, False]
    assert list(changes[1].removed) == [NAME3]
    assert loop.controller.iteration == 2  # restarted at the change, two updates since
    with pytest.raises(EstimationError, match="dead acquisition"):
        loop.on_summary(np.arange(1, 7), np.zeros((6, 12), complex), 30.0, 200, now)

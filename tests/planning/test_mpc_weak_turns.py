"""Weak turns pooled per motion name (MpcSettings.weak_turn_pool_gain).

In the demo's scene (the ROS-free loop on the plant with the drive's third harmonic) a bracket sat
3-7 deg off its goal angle for 20-35 s: refined motions were ranked with a turn scale of 1.9-2.9
learned under strong turns, the bracket turned at 0-0.4 deg/s, and each segment's predicted turn
(0.6-0.9 deg) was under min_predicted_turn_rad, so nothing corrected the scale. Weak segments of one
motion name are pooled until their predicted turns reach that threshold together, and their
least-squares ratio moves the turn scales at a fraction of scale_gain (one noisy weak ratio at the
full gain swung a scale to its floor and back). Model scales only: no wall-clock assertions."""

from __future__ import annotations

import math

import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.parts import published_rigid_part
from ppod_ros.planning.mpc import MpcSettings, MultiTask, PartGoal, spin_motion
from tests.support.named_motions import named_motions

WEAK = math.radians(0.6)      # a segment's predicted turn: under the 1 deg threshold; three reach it


def _task(**settings) -> MultiTask:
    return MultiTask([published_rigid_part()], [PartGoal(0, 0.0, 0.0, 0.0, 1e-3, math.radians(2))],
                     settings=MpcSettings(**settings))


def _motions(task: MultiTask):
    spin_here, _, refined, _ = named_motions(spin_motion(task.settings), "spin-@0", "sink@0")
    return spin_here, refined


def test_weak_segments_teach_only_together_and_slowly():
    task = _task()
    s, st = task.settings, task.state[0]
    _, refined = _motions(task)
    task._estimate_turn(st, refined.key, refined.name, 0.1, 0.25)    # a strong turn: scale 2.5 learned
    learned = st.turn_by_name["mpc"]
    assert learned > 2.0 and st.turn_now == (refined.key, learned)
    turned = [0.1 * WEAK, 0.0, 0.2 * WEAK]                           # the part hardly turns
    for k, t in enumerate(turned[:2]):
        task._estimate_turn(st, refined.key, refined.name, WEAK, t)
        assert st.turn_by_name["mpc"] == learned                      # not yet: under the threshold together
        assert st.weak_turns["mpc"][1] == pytest.approx((k + 1) * WEAK ** 2)
    task._estimate_turn(st, refined.key, refined.name, WEAK, turned[2])
    ratio = sum(turned) * WEAK / (3 * WEAK ** 2)                     # the pool's least-squares ratio
    gain = s.weak_turn_pool_gain * s.scale_gain
    assert st.turn_by_name["mpc"] == pytest.approx(learned + gain * (ratio - learned))
    assert st.turn_now == (refined.key, pytest.approx(learned + gain * (ratio - learned)))
    assert "mpc" not in st.weak_turns                                 # the pool starts again


def test_pools_are_per_motion_name_and_off_at_zero():
    task = _task()
    st = task.state[0]
    spin, refined = _motions(task)
    for _ in range(2):
        task._estimate_turn(st, refined.key, refined.name, WEAK, 0.0)
        task._estimate_turn(st, spin.key, spin.name, WEAK, 0.0)
    assert st.turn == 1.0 and st.turn_by_name == {}                  # two of each: neither pool is full
    task._estimate_turn(st, spin.key, spin.name, WEAK, 0.0)
    assert set(st.turn_by_name) == {"spin-@0"} and st.turn < 1.0

    off = _task(weak_turn_pool_gain=0.0)
    st = off.state[0]
    for _ in range(10):
        off._estimate_turn(st, refined.key, refined.name, WEAK, 0.0)
    assert st.turn == 1.0 and st.turn_now is None and st.turn_by_name == {} and st.weak_turns == {}


def test_non_finite_turns_teach_nothing():
    task = _task()
    st = task.state[0]
    _, refined = _motions(task)
    for bad in (math.nan, math.inf):
        task._estimate_turn(st, refined.key, refined.name, WEAK, bad)
        task._estimate_turn(st, refined.key, refined.name, bad, 0.0)
    assert st.weak_turns == {} and st.turn == 1.0 and st.turn_now is None


@pytest.mark.parametrize("bad", [-0.1, math.nan, 2.0])
def test_a_gain_that_would_overshoot_is_refused(bad):
    with pytest.raises(ConfigError, match="weak_turn_pool_gain"):
        MpcSettings(weak_turn_pool_gain=bad)      # 2.0 x scale_gain 0.6 > 1: each update past the ratio

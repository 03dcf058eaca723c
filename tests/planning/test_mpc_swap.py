"""Two parts that have to pass each other (MpcSettings.swap_from_rad): the pair rotation.

No sink, transport or line sink turns the segment between two parts: a part parked on another's goal
and the other parked on its goal stay in each other's way (benchmark scene 1 of three parts, seed 0:
the bracket and the washer traded places for 60 s). The rotation about the fixed point of the rigid
motion that turns the pair's segment as the goals' lie moves both towards their goals at once; for a
swap it is the rotation about their midpoint. Model predictions only: no wall-clock assertions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.parts import PointPart, published_rigid_part
from ppod_ros.planning import predict
from ppod_ros.planning.mpc import MpcSettings, MultiTask, PartGoal, base_kinds, pair_rotation


def _turned(p, c, a):
    r = np.asarray(p[:2], float) - c
    return c + np.array([math.cos(a) * r[0] - math.sin(a) * r[1], math.sin(a) * r[0] + math.cos(a) * r[1]])


def test_a_swap_is_half_a_turn_about_the_midpoint():
    c, angle = pair_rotation([-0.02, 0.01], [0.02, 0.03], [0.02, 0.03], [-0.02, 0.01])
    assert abs(angle) == pytest.approx(math.pi)
    assert c == pytest.approx([0.0, 0.02], abs=1e-12)
    # Parallel segments: no turn, no centre.
    c, angle = pair_rotation([0.0, 0.0], [0.01, 0.0], [0.02, 0.01], [0.035, 0.01])
    assert c is None and angle == pytest.approx(0.0)


@pytest.mark.parametrize("turn, shift", [(2.0, (0.01, -0.005)), (-1.3, (0.0, 0.02)), (0.7, (-0.015, 0.0))])
def test_the_pair_rotation_carries_a_congruent_pair_onto_its_goals(turn, shift):
    pa, pb = np.array([0.012, -0.004]), np.array([-0.01, 0.018])
    # Goals: the pair turned by ``turn`` about its midpoint and shifted (the same distance apart).
    m = 0.5 * (pa + pb)
    ga, gb = (_turned(p, m, turn) + np.array(shift) for p in (pa, pb))
    c, angle = pair_rotation(pa, pb, ga, gb)
    assert angle == pytest.approx(turn)
    assert _turned(pa, c, angle) == pytest.approx(ga, abs=1e-12)
    assert _turned(pb, c, angle) == pytest.approx(gb, abs=1e-12)


# A bracket and a washer each on the other's goal (scene 1's deadlock), a hex elsewhere.
POSES = np.array([[0.015, -0.025, 0.3], [-0.009, 0.002, 0.0], [0.05, 0.02, 0.0]])
GOALS = [PartGoal(0, -0.010, 0.010, 0.0, 2e-3, math.radians(3)), PartGoal(1, 0.018, -0.022, None, 2e-3),
         PartGoal(2, 0.048, 0.016, None, 2e-3)]


def _task(**settings) -> MultiTask:
    washer = PointPart(0.3)
    task = MultiTask([published_rigid_part(), washer, washer], GOALS, settings=MpcSettings(**settings))
    task.t0 = 0.0   # as its first step sets it (statuses time a part within tolerance from it)
    return task


def test_the_pair_rotations_are_offered_for_the_parts_in_each_others_way():
    assert _task(swap_from_rad=0.0)._pair_rotations(POSES, _task()._statuses(0.0, POSES)) == []
    task = _task(swap_from_rad=1.0)
    motions = task._pair_rotations(POSES, task._statuses(0.0, POSES))
    # Bracket and washer: their segment turns about half a turn. The hex is 4.5 mm from its goal,
    # its segments to the others turn less than 1 rad (no candidate for those pairs).
    assert sorted(m.name for m in motions) == ["swap+@0,1", "swap-@0,1"]
    c, angle = pair_rotation(POSES[0], POSES[1], (GOALS[0].x_m, GOALS[0].y_m), (GOALS[1].x_m, GOALS[1].y_m))
    assert abs(angle) > 2.5
    # Both predicted as the rotation about that point: each part moves across its radius from it,
    # the two opposite ways, and the two motions turn opposite ways.
    washer = PointPart(0.3)
    v, ok = predict.predict_velocities(motions, washer, POSES[:2, :2])
    assert ok.all()
    turn = []
    for k in range(2):
        r = POSES[:2, :2] - c
        cos = np.sum(v[k, :, :2] * r, axis=1) / (np.linalg.norm(v[k, :, :2], axis=1) * np.linalg.norm(r, axis=1))
        # Within 27 deg of the tangent (the rotation design is the optimiser's, whose local optimum
        # moves with the machine's floating point: 0.37 on one machine, under 0.35 on another).
        assert np.all(np.abs(cos) < 0.45), cos
        assert float(v[k, 0, :2] @ v[k, 1, :2]) < 0.0
        turn.append(np.sign(r[:, 0] * v[k, :, 1] - r[:, 1] * v[k, :, 0]))
        assert turn[-1][0] == turn[-1][1]
    assert turn[0][0] == -turn[1][0]
    # A part within its tolerance is held, not swapped: no pair with it.
    held = POSES.copy()
    held[1, :2] = GOALS[1].x_m + 5e-4, GOALS[1].y_m
    assert task._pair_rotations(held, task._statuses(0.0, held)) == []


def test_the_search_tries_them_and_the_setting_is_checked():
    task = _task(swap_from_rad=1.0)
    tried = []
    costs = task._costs

    def spy(motions, *a, **k):
        tried.extend(m.name for m in motions)
        return costs(motions, *a, **k)

    task._costs = spy
    task.step(0.0, POSES)
    assert {"swap+@0,1", "swap-@0,1"} <= set(tried)
    assert "rotation" in base_kinds(MpcSettings(templates=("sink",), swap_from_rad=1.0))
    with pytest.raises(ConfigError, match="swap_from_rad"):
        MpcSettings(swap_from_rad=-1.0)

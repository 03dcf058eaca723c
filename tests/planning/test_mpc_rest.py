"""The plate at rest holds every part (``MpcSettings.rest_average_after_s``, ``hold_at_rest``).

Regression (``ppod bench planner --sections multipart``, one bracket, seed 1, scene 8, 17.9 s): the
bracket came to rest 0.95 mm from its goal (tolerance 1 mm). The tracker read it at 0.86-1.08 mm,
so it was never within tolerance for the settle time; a weak motion restarted the plate 0.1 s short
of it, the next stop's ramp down carried the bracket back out by 0.3 mm, and that went on four
times. At rest the planner now averages a part's poses and does not restart the plate while every
part is within tolerance.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.parts import PointPart
from ppod_ros.planning.mpc import MpcSettings, MultiTask, PartGoal

GOAL = (0.01, -0.005)
TRUE_ERROR_M = 0.85e-3   # tolerance 1 mm (the plate is held at rest within 0.9 of it)
NOISE_M = 0.2e-3         # the tracker's reading alternates this far out and in


def _noisy_at_rest(task: MultiTask, seconds: float, fps: float = 10.0):
    """Frames of a point part at rest TRUE_ERROR_M from its goal (along x), read alternately
    NOISE_M nearer and farther (nearer first); returns the steps."""
    steps = []
    for i in range(int(round(seconds * fps))):
        if task.finished is not None:
            break
        e = TRUE_ERROR_M + (-NOISE_M if i % 2 == 0 else NOISE_M)
        steps.append(task.step(i / fps, np.array([[GOAL[0] + e, GOAL[1], 0.0]])))
    return steps


def _task(**changes) -> MultiTask:
    settings = MpcSettings(**changes)
    return MultiTask([PointPart(0.3)], [PartGoal(0, *GOAL)], timeout_s=10.0, settings=settings)


def test_a_part_at_rest_within_tolerance_is_averaged_and_reached_without_a_motion():
    task = _task()
    steps = _noisy_at_rest(task, 3.0)
    assert task.finished is not None and task.finished.done
    assert all(s.motion is None for s in steps)          # the plate never started
    assert task.switches == 0
    # Every other frame reads 1.05 mm: only the average keeps the part within its 1 mm.
    assert task.finished.parts[0].reached
    assert task.finished.parts[0].position_error_m == pytest.approx(TRUE_ERROR_M, abs=0.05e-3)


def test_without_the_average_the_noise_keeps_the_part_from_settling():
    task = _task(rest_average_after_s=None, hold_at_rest=False)
    steps = _noisy_at_rest(task, 1.5)
    # Never within for settle_s: the planner restarts the plate (or would never finish).
    assert any(s.motion is not None for s in steps) or task.finished is None


def test_hold_at_rest_waits_out_the_settle_time_for_a_part_within_tolerance():
    pose = np.array([[GOAL[0] + 0.8e-3, GOAL[1], 0.0]])   # within 1 mm, not within stop_within (0.6)
    held, moved = _task(), _task(hold_at_rest=False)
    for i in range(10):
        if held.finished is None:
            assert held.step(i / 10.0, pose).motion is None
        if moved.switches == 0:
            moved.step(i / 10.0, pose)
    assert held.finished is not None and held.finished.done and held.switches == 0
    assert moved.switches >= 1          # without it a motion that brings the part nearer is tried


def test_angles_are_averaged_on_the_part_symmetry_circle():
    task = _task()
    task.symmetry[0] = math.pi / 2    # a part with four-fold symmetry
    poses = [np.array([[GOAL[0], GOAL[1], a]]) for a in (math.pi / 4 - 0.01, -math.pi / 4 + 0.01)]
    task._at_rest(0.0, poses[0])
    out = task._at_rest(0.1, poses[1])
    # -pi/4 + 0.01 and pi/4 - 0.01 are 0.02 rad apart on the circle of period pi/2: their mean
    # is pi/4 (= -pi/4), given on the branch of the latest reading.
    assert out[0, 2] == pytest.approx(-math.pi / 4, abs=1e-9)


def test_a_part_held_only_with_a_margin_for_the_tracker():
    """At 0.95 of its tolerance a part is not held: the planner may move it nearer (a tracker 0.04 mm
    off put a demo's washer at 2.03 mm by ground truth, held at 1.99 mm, tolerance 2 mm)."""
    pose = np.array([[GOAL[0] + 0.95e-3, GOAL[1], 0.0]])
    task = _task()
    task.step(0.0, pose)
    assert task.switches == 1 and not task.current.is_zero()
    held = _task(rest_hold_within=1.0)
    held.step(0.0, pose)
    assert held.switches == 0


def test_rest_settings_validated():
    with pytest.raises(ConfigError, match="rest_average_after_s"):
        MpcSettings(rest_average_after_s=-0.1)
    with pytest.raises(ConfigError, match="rest_hold_within"):
        MpcSettings(rest_hold_within=0.0)

"""The planner teaching the feedback first (``MpcSettings.teach_amplitude``): the task's first
motion plays as a quiet copy of itself for ``teach_s``, then at full amplitude, which the
accelerometer feedback's plant learner then starts learned (tests/planning/test_plant_learning_loop.py
for the learner). Device time only: no wall-clock assertions."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ppod_ros.device import default_device_config
from ppod_ros.errors import ConfigError
from ppod_ros.parts import published_rigid_part
from ppod_ros.planning.mpc import MpcSettings, MultiTask, PartGoal
from ppod_ros.planning.simulate import ActuatorPlantError, run_on_dynamics

SCALE = np.array([1.0, 1.0, 1.0, 0.1, 0.1, 0.1])   # angular axes at 0.1 m, as the feedback bench


def _start_error(plant: ActuatorPlantError, motion, number: int) -> float:
    X = motion.phasors()[0]
    Y = plant.played(motion, 0.0, number).phasors()[0]
    return float(np.linalg.norm((Y - X) * SCALE) / np.linalg.norm(X * SCALE))


@pytest.mark.parametrize("bad", [dict(teach_amplitude=0.0), dict(teach_amplitude=1.2),
                                 dict(teach_amplitude=float("nan")), dict(teach_s=-1.0)])
def test_teach_settings_are_validated(bad):
    with pytest.raises(ConfigError, match="teach"):
        MpcSettings(**bad)


def test_the_first_motion_plays_its_quiet_copy_then_starts_learned():
    model = published_rigid_part()
    true = dataclasses.replace(model, mu=np.full(3, 0.35), mu_static=None)
    settings = MpcSettings(teach_amplitude=0.4, teach_s=1.5)
    task = MultiTask([model], [PartGoal(0, 0.02, -0.02, 0.0)], timeout_s=20.0, settings=settings)
    device = default_device_config()
    plant = ActuatorPlantError.random(np.random.default_rng(3), device, learning="learner")
    first_frames = {}   # motion number: the relative error of the first frame it played
    played = plant.played

    def spy(motion, since_s, number, frame_s=0.0):
        out = played(motion, since_s, number, frame_s)
        if motion is not None and not motion.is_zero() and number not in first_frames:
            X, Y = motion.phasors()[0], out.phasors()[0]
            first_frames[number] = float(np.linalg.norm((Y - X) * SCALE) / np.linalg.norm(X * SCALE))
        return out

    plant.played = spy
    run = run_on_dynamics(task, [true], [[0.04, 0.03, 1.0]], horizon_s=20.0, ramp_s=0.5, latency_s=0.1,
                          plant=plant, seed=3, keep_steps=True)
    motions = [s.motion for s in run.steps if s.motion is not None]
    quiet, full = motions[0], motions[1]
    assert np.allclose(quiet.phasors(), 0.4 * full.phasors())
    assert run.switch_times[1] - run.switch_times[0] == pytest.approx(1.5)
    # The quiet copy plays the fresh plant's error; the full motion (its ramp from the quiet copy is
    # the same current direction) starts from what the quiet copy taught.
    assert first_frames[1] > 0.1
    assert first_frames[2] < 0.04
    # Without the quiet copy the first motion starts as far off as the quiet copy did.
    plain = ActuatorPlantError.random(np.random.default_rng(3), device, learning="learner")
    assert _start_error(plain, full, 1) == pytest.approx(first_frames[1], rel=0.05)

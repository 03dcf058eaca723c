"""Run a planning task against the full part dynamics (no asymptotic shortcut, no ROS, no camera):
what the planner's tests and ``ppod bench planner`` use to check that plans work on the physics.

The plate plays each motion exactly (no plant mismatch); a pose the task sees is the true one plus
Gaussian noise standing in for the tracker. A part that loses contact lands where it is, at rest
(as on the simulated device). Parts do not touch each other here (the simulated device keeps them
apart; ppod_sim.scene).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ppod_ros.parts import PointPart, RigidPart
from ppod_ros.physics import PartDynamics
from ppod_ros.planning.sensorless import SensorlessTask
from ppod_ros.planning.task import Task, TaskStep


@dataclass(frozen=True)
class SimulatedRun:
    step: TaskStep | None        # the task's last step
    configurations: np.ndarray  # (N, 3) final [x, y, theta]
    elapsed_s: float            # device time from the first step to the end
    hops: int                   # contact losses (parts put back at rest)
    motions: int                # motions the task asked for
    trajectory: np.ndarray      # (T, N, 3) the true configurations at every step, then the final ones


def run_on_dynamics(task: Task | SensorlessTask, parts: Sequence[PointPart | RigidPart], starts, *,
                    horizon_s: float = 60.0, dt_s: float = 0.1, position_noise_m: float = 5e-5,
                    angle_noise_rad: float = math.radians(0.1), seed: int = 0) -> SimulatedRun:
    """Step ``task`` every ``dt_s`` on the parts' poses until it ends or ``horizon_s`` passes.
    A SensorlessTask is shown no poses."""
    rng = np.random.default_rng(seed)
    dyn = PartDynamics(list(parts), np.array(starts, dtype=float))
    sensorless = isinstance(task, SensorlessTask)
    motion, t, step, hops, motions = None, 0.0, None, 0, 0
    path = []
    while t < horizon_s + 1e-9:
        path.append(dyn.state.configurations)
        poses = None
        if not sensorless:
            poses = dyn.state.configurations.copy()
            poses[:, :2] += rng.normal(0.0, position_noise_m, (len(parts), 2))
            poses[:, 2] += rng.normal(0.0, angle_noise_rad, len(parts))
        step = task.step(t, poses)
        if step.motion is not None:
            motion, motions = step.motion, motions + 1
        if step.done or step.failed_reason:
            break
        if motion is not None:
            state = dyn.advance(motion, t, dt_s)
            for i in np.flatnonzero(state.status != 0):
                dyn.set_part(int(i), state.configurations[i])
                hops += 1
        t += dt_s
    final = dyn.state.configurations
    return SimulatedRun(step, final, t, hops, motions, np.array(path + [final]))


__all__ = ["SimulatedRun", "run_on_dynamics"]

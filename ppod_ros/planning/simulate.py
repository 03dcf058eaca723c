"""Run a planning task against the full part dynamics (no asymptotic shortcut, no ROS, no camera):
what the planner's tests and ``ppod bench planner`` use to check that plans work on the physics.

By default the plate plays each motion exactly (no plant mismatch) and switches at once; a pose
the task sees is the true one plus Gaussian noise standing in for the tracker. A part that loses
contact lands where it is, at rest (as on the simulated device). Optionally, as the stack does:

- ``latency_s``: the task sees the poses of that long ago (the tracker's latency);
- ``ramp_s``: every switch is the generator's ramp (a linear crossfade of the phasors; across
  frequencies, down then up);
- ``plant``: a :class:`PlantError` (gain, phase and coupling errors of the played motion) that
  starts with each new motion and decays as the accelerometer feedback's transient does;
- ``separate``: a callback that keeps parts out of each other after each step (the simulated
  device's ppod_sim.scene.separate; ppod_ros does not import the simulator).

Parts do not touch each other unless ``separate`` is given.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ppod_ros.motion import PlateMotion
from ppod_ros.parts import PointPart, RigidPart
from ppod_ros.physics import PartDynamics
from ppod_ros.planning.sensorless import SensorlessTask
from ppod_ros.planning.task import Task, TaskStep


@dataclass(frozen=True)
class PlantError:
    """The played motion is (I + E) X for a goal X, with E = diag(gain e^(i phase)) - I + coupling,
    scaled by ``first_fraction`` for the first ``unlearned_goals`` motions and ``learned_fraction``
    after (the feedback's learned plant predicts the start), decaying as exp(-t / decay_s)."""

    E: np.ndarray                         # (6, 6) complex
    decay_s: float = 0.3
    unlearned_goals: int = 2
    learned_fraction: float = 0.25

    @classmethod
    def random(cls, rng: np.random.Generator, gain: float = 0.15, phase_deg: float = 10.0, coupling: float = 0.05,
               **kwargs) -> PlantError:
        g = 1.0 + rng.uniform(-gain, gain, 6)
        ph = np.radians(rng.uniform(-phase_deg, phase_deg, 6))
        C = rng.uniform(-coupling, coupling, (6, 6))
        np.fill_diagonal(C, 0.0)
        # Coupling relative to each axis's typical scale (m/s^2 and rad/s^2 differ by 10x).
        scale = np.array([10.0, 10.0, 10.0, 100.0, 100.0, 100.0])
        C = C * scale[:, None] / scale[None, :]
        return cls(np.diag(g * np.exp(1j * ph)) - np.eye(6) + C, **kwargs)

    def played(self, motion, since_switch_s: float, goal_number: int):
        if motion is None or motion.is_zero():
            return motion
        frac = 1.0 if goal_number <= self.unlearned_goals else self.learned_fraction
        f = frac * math.exp(-max(0.0, since_switch_s) / self.decay_s)
        if f < 1e-4:
            return motion
        X = motion.phasors()
        X = X + f * (X @ self.E.T)
        return PlateMotion.from_phasors(motion.frequency_hz, motion.k, X, name=motion.name)


def _blend(old, new, a: float):
    """The generator's ramp from ``old`` to ``new`` at fraction ``a`` (0..1)."""
    if a >= 1.0 or old is None:
        return new.scaled(a) if old is None and a < 1.0 else new
    if new.is_zero() or old.is_zero() or abs(new.frequency_hz - old.frequency_hz) > 1e-9:
        if new.is_zero() and not old.is_zero():
            return old.scaled(1.0 - a)
        if old.is_zero():
            return new.scaled(a)
        return old.scaled(1.0 - 2 * a) if a < 0.5 else new.scaled(2 * a - 1.0)
    k = sorted(set(old.k.tolist()) | set(new.k.tolist()))
    Xo, Xn = old.phasor_table(max(k)), new.phasor_table(max(k))
    X = (1 - a) * Xo + a * Xn
    return PlateMotion.from_phasors(new.frequency_hz, np.arange(1, max(k) + 1), X, name=new.name)


@dataclass(frozen=True)
class SimulatedRun:
    step: TaskStep | None        # the task's last step
    configurations: np.ndarray  # (N, 3) final [x, y, theta]
    elapsed_s: float            # device time from the first step to the end
    hops: int                   # contact losses (parts put back at rest)
    motions: int                # motions the task asked for
    trajectory: np.ndarray      # (T, N, 3) the true configurations at every step, then the final ones
    times: np.ndarray | None = None          # (T,) device time of each trajectory row
    steps: list | None = None                 # every step the task returned
    switch_times: tuple[float, ...] = ()      # device time of each motion switch


def run_on_dynamics(task: Task | SensorlessTask, parts: Sequence[PointPart | RigidPart], starts, *,
                    horizon_s: float = 60.0, dt_s: float = 0.1, position_noise_m: float = 5e-5,
                    angle_noise_rad: float = math.radians(0.1), seed: int = 0, latency_s: float = 0.0,
                    ramp_s: float = 0.0, plant: PlantError | None = None,
                    separate: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
                    keep_steps: bool = False) -> SimulatedRun:
    """Step ``task`` every ``dt_s`` on the parts' poses until it ends or ``horizon_s`` passes.
    A SensorlessTask is shown no poses. ``separate(configurations, twists)`` modifies both in
    place and returns the indices it moved."""
    rng = np.random.default_rng(seed)
    dyn = PartDynamics(list(parts), np.array(starts, dtype=float))
    sensorless = isinstance(task, SensorlessTask)
    motion, t, step, hops, motions = None, 0.0, None, 0, 0
    previous, switched_at = None, 0.0
    path, times, steps, switches = [], [], [], []
    lag = max(0, int(round(latency_s / dt_s)))
    while t < horizon_s + 1e-9:
        path.append(dyn.state.configurations)
        times.append(t)
        poses = None
        if not sensorless:
            poses = path[max(0, len(path) - 1 - lag)].copy()
            poses[:, :2] += rng.normal(0.0, position_noise_m, (len(parts), 2))
            poses[:, 2] += rng.normal(0.0, angle_noise_rad, len(parts))
        step = task.step(t, poses)
        if keep_steps:
            steps.append(step)
        if step.motion is not None:
            previous = _blend(previous, motion, min(1.0, (t - switched_at) / ramp_s)) if ramp_s > 0 and motion \
                is not None else motion
            motion, motions, switched_at = step.motion, motions + 1, t
            switches.append(t)
        if step.done or step.failed_reason:
            break
        if motion is not None:
            since = t - switched_at
            played = motion
            if ramp_s > 0 and since < ramp_s:
                played = _blend(previous, motion, min(1.0, (since + 0.5 * dt_s) / ramp_s))
            if plant is not None:
                played = plant.played(played, since, motions)
            if played is not None:
                state = dyn.advance(played, t, dt_s)
                for i in np.flatnonzero(state.status != 0):
                    dyn.set_part(int(i), state.configurations[i])
                    hops += 1
                if separate is not None:
                    st = dyn.state
                    cfg, tw = st.configurations.copy(), st.twists.copy()
                    moved = separate(cfg, tw)
                    if len(moved):
                        dyn.set_parts(np.asarray(moved, dtype=int), cfg[moved], tw[moved])
        t += dt_s
    final = dyn.state.configurations
    return SimulatedRun(step, final, t, hops, motions, np.array(path + [final]), np.array(times + [t]),
                        steps if keep_steps else None, tuple(switches))


__all__ = ["PlantError", "SimulatedRun", "run_on_dynamics"]

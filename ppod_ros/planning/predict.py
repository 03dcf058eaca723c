"""Candidate evaluation for the model-predictive planner: the one seam to the solver.

:func:`predict_velocities` returns the asymptotic velocity (point part) or twist (rigid part) of
one part model under M candidate plate motions at N configurations, as arrays (M, N, dim) and a
validity mask (M, N). It calls the batched solver ``ppod_ros.physics.solve_fields`` when the
physics package provides it (the performance issue's compiled, stall-free API) and otherwise
loops the existing :func:`ppod_ros.physics.solve_field`, one call per motion, on a single numba
thread: the planner's calls are small (a few configurations), where a parallel call costs more
in thread start-up and stalls than it saves.

The planner's solver settings (:data:`PLANNER_SOLVER`) are the ``fast`` preset, capped at 40 periods and
5000 steps per period (a stick-slip candidate is given up on, not integrated for seconds), without the
result cache (every candidate is new) on one thread.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion
from ppod_ros.parts import PointPart, RigidPart
from ppod_ros.physics import PRESETS, SolverSettings, solve_field

#: Solver settings of the planner's small calls: the fast preset, no cache, one thread.
PLANNER_SOLVER: SolverSettings = PRESETS["fast"].replace(cache=False, threads=1, max_periods=40,
                                                         max_steps_per_period=5000)


def predict_velocities(motions: Sequence[PlateMotion], part: PointPart | RigidPart, configs,
                       settings: SolverSettings | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Velocities (M, N, dim) (NaN where invalid) and validity (M, N) of ``part`` at ``configs``
    ((N, dim): [x, y] or [x, y, theta]) under each of ``motions``."""
    motions = list(motions)
    if not motions:
        raise ConfigError("motions: expected at least one plate motion")
    settings = settings or PLANNER_SOLVER
    cfg = np.asarray(configs, dtype=float)
    dim = 3 if isinstance(part, RigidPart) else 2
    if cfg.ndim != 2 or cfg.shape[1] != dim:
        raise ConfigError(f"configs: expected shape (N, {dim}) for a {part.kind} part, got {cfg.shape}")
    batched = _batched_solver()
    if batched is not None:
        r = batched(motions, part, cfg, settings=settings)
        return np.asarray(r.velocity, float), np.asarray(r.valid, bool)
    vel = np.full((len(motions), cfg.shape[0], dim), np.nan)
    valid = np.zeros((len(motions), cfg.shape[0]), bool)
    for m, motion in enumerate(motions):
        if motion.is_zero():  # a plate at rest holds every part
            vel[m], valid[m] = 0.0, True
            continue
        r = solve_field(motion, part, cfg, settings)
        vel[m], valid[m] = r.velocity, r.valid
    return vel, valid


def _batched_solver():
    import ppod_ros.physics as physics

    return getattr(physics, "solve_fields", None)


__all__ = ["PLANNER_SOLVER", "predict_velocities"]

"""Candidate evaluation for the model-predictive planner: the one seam to the solver.

:func:`predict_velocities` returns the asymptotic velocity (point part) or twist (rigid part) of
one part model under M candidate plate motions at N configurations, as arrays (M, N, dim) and a
validity mask (M, N), from ONE call of the batched solver ``ppod_ros.physics.solve_fields`` (all
motions at all configurations in one compiled call; the planner's calls are small, so the solver
runs them serially on the calling thread: no parallel-call thread wake-up stalls on a busy
machine). A plate at rest (a zero motion) holds every part: velocity 0, valid, without the solver.

The planner's solver settings (:data:`PLANNER_SOLVER`) are the ``fast`` preset, capped at 40 periods and
1500 steps per period (a stick-slip candidate is given up on, not integrated for seconds), without the
result cache (every candidate is new) on one thread. The Gauss-Newton probes and trials run on a smaller
budget (:func:`budgeted`): the same settings with fewer periods and steps per period, so that a row
either converges within it, to the same result from the same start, or is reported not converged;
they start from the limit cycles the candidates found (the solver keys warm starts without the work
caps: ``SolverSettings.warm_key``).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import numpy as np

import ppod_ros.physics as physics  # solve_fields looked up per call: tests substitute it
from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion
from ppod_ros.parts import PointPart, RigidPart
from ppod_ros.physics import PRESETS, REASONS, SolverSettings

#: Solver settings of the planner's small calls: the fast preset, no cache, one thread.
PLANNER_SOLVER: SolverSettings = PRESETS["fast"].replace(cache=False, threads=1, max_periods=40,
                                                         max_steps_per_period=1500)


def budgeted(max_periods: int, max_steps_per_period: int,
             settings: SolverSettings | None = None) -> SolverSettings:
    """``settings`` (default :data:`PLANNER_SOLVER`) with at most ``max_periods`` periods and
    ``max_steps_per_period`` attempted steps per period (each only where lower; 0: unchanged): a
    deterministic bound on the solver's work per row. A row that converges within the budget gives
    the same result as without it from the same start; one that does not is invalid ("not
    converged"). Budgeted calls share the warm starts of unbudgeted ones (``SolverSettings.warm_key``)."""
    for name, v in (("max_periods", max_periods), ("max_steps_per_period", max_steps_per_period)):
        if not (isinstance(v, int) and v >= 0):
            raise ConfigError(f"{name}: expected an integer >= 0 (0: unchanged), got {v!r}")
    return _capped(settings or PLANNER_SOLVER, max_periods, max_steps_per_period)


@lru_cache(maxsize=32)
def _capped(base: SolverSettings, max_periods: int, max_steps_per_period: int) -> SolverSettings:
    """:func:`budgeted`'s settings, made once per base and caps (the solver derives its keys and
    settings vector once per settings object; the planner asks for the same budget every step)."""
    return base.replace(max_periods=min(base.max_periods, max_periods or base.max_periods),
                        max_steps_per_period=min(base.max_steps_per_period,
                                                 max_steps_per_period or base.max_steps_per_period))


#: Reason codes of a row the solver gave up on under its work caps (not a property of the motion).
GAVE_UP_CODES: tuple[int, ...] = tuple(c for c, text in REASONS.items() if text and text.startswith("not converged"))


def predict_velocities(motions: Sequence[PlateMotion], part: PointPart | RigidPart, configs,
                       settings: SolverSettings | None = None, *, gave_up: bool = False):
    """Velocities (M, N, dim) (NaN where invalid) and validity (M, N) of ``part`` at ``configs``
    ((N, dim): [x, y] or [x, y, theta]) under each of ``motions``. ``gave_up``: a third array (M, N),
    true where a row is invalid only because the solver gave up under its caps ("not converged",
    :data:`GAVE_UP_CODES`), not because contact is lost."""
    motions = list(motions)
    if not motions:
        raise ConfigError("motions: expected at least one plate motion")
    settings = settings or PLANNER_SOLVER
    cfg = np.asarray(configs, dtype=float)
    dim = 3 if isinstance(part, RigidPart) else 2
    if cfg.ndim != 2 or cfg.shape[1] != dim:
        raise ConfigError(f"configs: expected shape (N, {dim}) for a {part.kind} part, got {cfg.shape}")
    vel = np.zeros((len(motions), cfg.shape[0], dim))
    valid = np.ones((len(motions), cfg.shape[0]), bool)
    unconverged = np.zeros((len(motions), cfg.shape[0]), bool)
    moving = [m for m, motion in enumerate(motions) if not motion.is_zero()]
    if moving:
        r = physics.solve_fields([motions[m] for m in moving], part, cfg, settings=settings)
        vel[moving] = np.asarray(r.velocity, float)
        valid[moving] = np.asarray(r.valid, bool)
        vel[moving] = np.where(valid[moving][..., None], vel[moving], np.nan)
        codes = getattr(r, "reason_code", None)   # (tests substitute a solve_fields without it)
        if codes is not None:
            codes = np.asarray(codes)
            gave = np.zeros(codes.shape, bool)
            for c in GAVE_UP_CODES:   # np.isin without its per-call overhead
                gave |= codes == c
            unconverged[moving] = ~valid[moving] & gave
    return (vel, valid, unconverged) if gave_up else (vel, valid)


__all__ = ["GAVE_UP_CODES", "PLANNER_SOLVER", "budgeted", "predict_velocities"]

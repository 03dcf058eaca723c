"""The limit cycle itself at one configuration, sampled over a period (for plots and checks).

:func:`solve_field` returns the cycle average and the velocity at the cycle start; this module
integrates one more period from that start, with the configuration held fixed, and samples it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ppod_ros.errors import ConfigError, SolverError
from ppod_ros.motion import PlateMotion
from ppod_ros.parts import PointPart, RigidPart
from ppod_ros.physics import _layout as lay
from ppod_ros.physics._advance import advance, point_init, point_speed_limits, rigid_init, zero_tolerance
from ppod_ros.physics._contact import rigid_geometry
from ppod_ros.physics._params import check_configs, point_rows, rigid_rows
from ppod_ros.physics._rk import INTEGRATORS
from ppod_ros.physics._solve import rigid_scales
from ppod_ros.physics.field import solve_field
from ppod_ros.physics.plate import motion_table, point_velocity_scale
from ppod_ros.physics.settings import REASONS, SolverSettings


def limit_cycle(motion: PlateMotion, part: PointPart | RigidPart, config: Any, n_samples: int = 256,
                settings: SolverSettings | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Samples of the limit cycle at one configuration.

    Parameters
    ----------
    config : array_like, shape (2,) or (3,)
        [x, y] (m) or [x, y, theta] (m, m, rad).
    n_samples : int
        Samples over one period, at t = k T / n_samples.

    Returns
    -------
    t : ndarray, shape (n_samples,)
        Times in the cycle (s), cycle start t = 0.
    velocity : ndarray, shape (n_samples, 2) or (n_samples, 3)
        The part's velocity (point) or twist (rigid) on the limit cycle.

    Raises
    ------
    SolverError
        If the configuration is invalid (contact lost, not converged, ...).
    """
    if not isinstance(n_samples, int) or n_samples < 1:
        raise ConfigError(f"n_samples: must be an integer >= 1, got {n_samples!r}")
    settings = settings or SolverSettings()
    cfg = check_configs(config, part, "config")
    if cfg.shape[0] != 1:
        raise ConfigError(f"config: expected one configuration, got {cfg.shape[0]}")
    res = solve_field(motion, part, cfg, settings)
    if not res.valid[0]:
        raise SolverError(f"no limit cycle at {cfg[0].tolist()}: {REASONS[int(res.reason_code[0])]}")
    kind = 0 if isinstance(part, PointPart) else 1
    dim = cfg.shape[1]
    n = 2 * dim
    mc = motion_table(motion, prune=settings.prune_harmonics)
    tab = INTEGRATORS[settings.integrator]
    S = settings.vector(part.kind)
    rtol = settings.step_rtol(part.kind)
    T = motion.period_s
    W = np.zeros(lay.W_SIZE)
    sc = np.zeros(n)
    if kind == 0:
        P = point_rows(part, cfg)[0]
        vscale = point_velocity_scale(mc, cfg[0, 0], cfg[0, 1])
        P[lay.PP_VSCALE] = vscale
        sc[2:] = rtol * vscale + settings.atol_mps
        point_speed_limits(P, S, sc[2], T)
    else:
        P = rigid_rows(part, cfg, settings.friction_eps_mps)[0]
        rigid_geometry(P, cfg[0, 2], W)
        vscale, wscale = rigid_scales(mc, P, cfg[0, 0], cfg[0, 1], W)
        P[lay.RP_VSCALE] = vscale
        P[lay.RP_WSCALE] = wscale
        sc[3:5] = rtol * vscale + settings.atol_mps
        sc[5] = rtol * wscale + settings.atol_radps
    zero_tol = zero_tolerance(S, vscale)
    if kind == 1:
        P[lay.RP_ZTOL] = max(zero_tol, 100.0 * sc[3])
    y = np.zeros(n)
    y[dim:] = res.cycle_start[0]
    aux = np.zeros(lay.AX_SIZE)
    if kind == 0:
        point_init(mc, P, aux, 0.0, y, W, zero_tol)
    else:
        rigid_init(mc, P, aux, 0.0, y, W, settings.stick_capture)
    K = np.zeros((tab.stages + 1, n))
    work = [np.zeros(n) for _ in range(3)]
    stats = np.zeros(4)
    t = np.arange(n_samples) * (T / n_samples)
    out = np.zeros((n_samples, dim))
    h = T / 16.0
    out[0] = y[dim:]
    for k in range(1, n_samples):
        status, h = advance(kind, mc, P, aux, t[k - 1], t[k], y, h, T, tab.A, tab.B, tab.C, tab.E, tab.E3, S,
                            K, work[0], work[1], work[2], W, sc, n, settings.max_steps_per_period, zero_tol,
                            stats)
        if status != lay.OK:
            raise SolverError(f"limit cycle at {cfg[0].tolist()}: {REASONS[int(status)]} at t = {t[k]:.6g} s")
        out[k] = y[dim:]
    return t, out


__all__ = ["limit_cycle"]

"""Compiled full dynamics: many parts, configurations evolving, advanced over one time interval.

Each part is integrated by the same event-driven stepper as the asymptotic solver
(``_advance.advance``) with its configuration in the state (``P[EVOLVE] = 1``); parts run in
parallel. A part whose contact is lost (or whose contact system turns singular) keeps its last
state and status and is not integrated again.
"""

from __future__ import annotations

import math

import numpy as np

from ppod_ros.physics._advance import advance, point_init, point_speed_limits, rigid_init, zero_tolerance
from ppod_ros.physics._contact import rigid_geometry
from ppod_ros.physics._jit import njit, prange
from ppod_ros.physics._layout import (
    AX_READY,
    AX_SIZE,
    OK,
    PP_CANSTICK,
    PP_EVOLVE,
    PP_VSCALE,
    PP_X,
    RP_CANSTICK,
    RP_EVOLVE,
    RP_VSCALE,
    RP_WSCALE,
    RP_X,
    RP_ZTOL,
    S_ATOL_V,
    S_ATOL_W,
    S_CAPTURE,
    S_MAX_STEPS,
    S_RTOL,
    W_SIZE,
)
from ppod_ros.physics._solve import rigid_scales
from ppod_ros.physics.plate import point_velocity_scale

AUX_READY = AX_READY


@njit(cache=True, error_model="numpy")
def advance_part(i, kind, mc, Pall, Y, AUX, H, t0, t1, T, kmax, A, B, C, E, E3, S, status, stick_time, steps,
                 max_steps):
    """Advance part i from local time t0 to t1 in place (see :func:`advance_group`)."""
    dim = 2 if kind == 0 else 3
    n = 2 * dim
    K = np.zeros((B.shape[0] + 1, n))
    ytmp = np.zeros(n)
    ynew = np.zeros(n)
    ybest = np.zeros(n)
    W = np.zeros(W_SIZE)
    sc = np.zeros(n)
    stats = np.zeros(4)
    P = Pall[i]
    y = Y[i]
    aux = AUX[i]
    if kind == 0:
        vscale = point_velocity_scale(mc, y[0], y[1])
        P[PP_VSCALE] = vscale
        P[PP_CANSTICK] = 1.0
        sc[2] = S[S_RTOL] * vscale + S[S_ATOL_V]
        sc[3] = sc[2]
        point_speed_limits(P, S, sc[2], T)
    else:
        rigid_geometry(P, y[2], W)
        vscale, wscale = rigid_scales(mc, P, y[0], y[1], W)
        P[RP_VSCALE] = vscale
        P[RP_WSCALE] = wscale
        P[RP_CANSTICK] = 1.0
        sc[3] = S[S_RTOL] * vscale + S[S_ATOL_V]
        sc[4] = sc[3]
        sc[5] = S[S_RTOL] * wscale + S[S_ATOL_W]
    zero_tol = zero_tolerance(S, vscale)
    if kind == 1:
        P[RP_ZTOL] = max(zero_tol, 100.0 * sc[3])
    if aux[AUX_READY] == 0.0:
        if kind == 0:
            point_init(mc, P, aux, t0, y, W, zero_tol)
        else:
            rigid_init(mc, P, aux, t0, y, W, S[S_CAPTURE])
        aux[AUX_READY] = 1.0
    h = H[i] if H[i] > 0.0 else T / (8.0 * kmax)
    st, h = advance(kind, mc, P, aux, t0, t1, y, h, T, A, B, C, E, E3, S, K, ytmp, ynew, ybest, W, sc, n,
                    max_steps, zero_tol, stats)
    status[i] = st
    H[i] = h
    stick_time[i] += stats[0]
    steps[i] += stats[1]


@njit(cache=True, error_model="numpy", parallel=True, nogil=True)
def advance_group(kind, mc, Pall, Y, AUX, H, t0, t1, T, kmax, A, B, C, E, E3, S, status, stick_time, steps):
    """Advance every part of one kind from local time t0 to t1 in place, in parallel over parts.

    Y (n, 2 dim): configuration then velocity/twist; AUX (n, AX_SIZE): mode memory; H (n,): step
    sizes carried between calls; status (n,): 0 while in contact; stick_time, steps accumulate.
    """
    periods = max(1.0, math.ceil((t1 - t0) / T))
    max_steps = int(S[S_MAX_STEPS] * periods)
    for i in prange(Pall.shape[0]):
        if status[i] == OK:
            advance_part(i, kind, mc, Pall, Y, AUX, H, t0, t1, T, kmax, A, B, C, E, E3, S, status, stick_time,
                         steps, max_steps)


@njit(cache=True, error_model="numpy", nogil=True)
def advance_group_serial(kind, mc, Pall, Y, AUX, H, t0, t1, T, kmax, A, B, C, E, E3, S, status, stick_time,
                         steps):
    """:func:`advance_group` on the calling thread only (same results, no thread wake-up stall)."""
    periods = max(1.0, math.ceil((t1 - t0) / T))
    max_steps = int(S[S_MAX_STEPS] * periods)
    for i in range(Pall.shape[0]):
        if status[i] == OK:
            advance_part(i, kind, mc, Pall, Y, AUX, H, t0, t1, T, kmax, A, B, C, E, E3, S, status, stick_time,
                         steps, max_steps)


def warm_up(kind, mc, P, dim, tab, S, period_s, kernels) -> None:
    """Compile (or load) the ``kernels`` (:func:`advance_group` and/or its serial variant) on a tiny
    problem."""
    P = np.array(P, copy=True)
    P[:, PP_EVOLVE if kind == 0 else RP_EVOLVE] = 1.0
    n = P.shape[0]
    Y = np.zeros((n, 2 * dim))
    Y[:, :dim] = P[:, PP_X:PP_X + 2] if kind == 0 else P[:, RP_X:RP_X + 3]
    status = np.zeros(n, np.int64)
    for kernel in kernels:
        kernel(kind, mc, P.copy(), Y.copy(), np.zeros((n, AX_SIZE)), np.zeros(n), 0.0, 0.1 * period_s, period_s,
               1, tab.A, tab.B, tab.C, tab.E, tab.E3, S, status.copy(), np.zeros(n), np.zeros(n, np.int64))

"""Event-driven integration of one part over a time interval (compiled).

Modes and events (PHYSICS.md):

point, sliding   event ``(s - v_h) . d = 0`` (d: sliding direction at the step's start). Located
                 by re-stepping (Illinois false position). If |w| is then below the zero
                 tolerance, w has reached zero: the part sticks when |a_h| <= mu_s n, else it
                 passes through and slides along -a_h. Otherwise w only swung round (2-D), and d
                 is updated.
point, sticking  event ``mu_s n - |a_h| = 0``: break-away along -a_h.
rigid, sliding   regularised Coulomb friction; after each step, if every contact's speed is below
                 ``capture * eps`` and the sticking test passes, the part sticks.
rigid, sticking  event ``1 - ratio = 0`` (ratio from the cone program): break-away.

The same code integrates a configuration held fixed (asymptotic solver; q accumulates the
velocity's integral) and an evolving one (full dynamics).
"""

from __future__ import annotations

import math

from numba import njit

from ppod_ros.physics._contact import (
    contact_velocities,
    geometry_for,
    plate_twist,
    point_plate,
    stick_forces,
    stick_ratio,
)
from ppod_ros.physics._layout import (
    AX_BAND,
    AX_DX,
    AX_DY,
    AX_MODE,
    AX_RD,
    OK,
    PP_CANSTICK,
    PP_EVOLVE,
    PP_MUS,
    PP_X,
    PP_Y,
    RP_CANSTICK,
    RP_EPS,
    S_CAPTURE,
    S_ERRKIND,
    S_EXPONENT,
    SLIDE,
    STEP_LIMIT,
    STICK,
    W_E,
    W_S,
    W_U,
    W_V,
)
from ppod_ros.physics._rk import rk_step
from ppod_ros.physics.plate import plate_eval

# ------------------------------------------------------------------ point part


@njit(cache=True)
def _point_xy(P, y):
    if P[PP_EVOLVE] > 0.0:
        return y[0], y[1]
    return P[PP_X], P[PP_Y]


@njit(cache=True)
def point_at_zero(P, aux, ahx, ahy, n):
    """w = 0: stick if the static friction can hold the part, else slide along -a_h."""
    a = math.hypot(ahx, ahy)
    if P[PP_CANSTICK] > 0.0 and a <= P[PP_MUS] * n:
        aux[AX_MODE] = STICK
        return
    aux[AX_MODE] = SLIDE
    if a > 0.0:
        aux[AX_DX] = -ahx / a
        aux[AX_DY] = -ahy / a


@njit(cache=True)
def point_init(mc, P, aux, t, y, W, zero_tol):
    """Choose the mode for state y at time t (used at a period's start and when a part is placed)."""
    x, yy = _point_xy(P, y)
    ahx, ahy, n, vhx, vhy = point_plate(mc, P, t, x, yy, W)
    wx = y[2] - vhx
    wy = y[3] - vhy
    nw = math.hypot(wx, wy)
    if nw <= zero_tol:
        y[2] = vhx
        y[3] = vhy
        point_at_zero(P, aux, ahx, ahy, n)
    else:
        aux[AX_MODE] = SLIDE
        aux[AX_DX] = wx / nw
        aux[AX_DY] = wy / nw


# ------------------------------------------------------------------ rigid part


@njit(cache=True)
def _rigid_contacts(mc, P, aux, t, y, W, after_event):
    """Refresh each contact's band flag (|u_i| < eps) and reference direction d_i at (t, y).

    After an event, a contact at the band edge changes side (the event located its crossing) and a
    contact outside the band whose direction swung past 90 degrees gets its new direction.
    """
    plate_eval(mc, t, W, W_U, W_V)
    sx, sy, _ = geometry_for(P, y, W)
    contact_velocities(sx, sy, y[3], y[4], y[5], W)
    eps = P[RP_EPS]
    for i in range(3):
        ux = W[W_E + 2 * i]
        uy = W[W_E + 2 * i + 1]
        nu = math.hypot(ux, uy)
        if not after_event:
            inside = nu < eps
        elif aux[AX_BAND + i] > 0.0:
            inside = nu < eps * (1.0 - 1e-6)
        else:
            inside = nu <= eps * (1.0 + 1e-6)
        aux[AX_BAND + i] = 1.0 if inside else 0.0
        if nu > 0.0:
            aux[AX_RD + 2 * i] = ux / nu
            aux[AX_RD + 2 * i + 1] = uy / nu


@njit(cache=True)
def rigid_init(mc, P, aux, t, y, W, capture):
    """Choose the mode for state y at time t: sticking if the part rests on the plate and can stay."""
    aux[AX_MODE] = SLIDE
    if not rigid_try_stick(mc, P, aux, t, y, W, capture):
        _rigid_contacts(mc, P, aux, t, y, W, False)


@njit(cache=True)
def rigid_try_stick(mc, P, aux, t, y, W, capture):
    """Enter sticking if every contact is (nearly) at rest on the plate and the cone program says the
    needed forces fit; the twist is then set to the plate's. Returns True if the part now sticks."""
    if P[RP_CANSTICK] <= 0.0:
        return False
    plate_eval(mc, t, W, W_U, W_V)
    sx, sy, _ = geometry_for(P, y, W)
    umax = contact_velocities(sx, sy, y[3], y[4], y[5], W)
    if umax > capture * P[RP_EPS]:
        return False
    fx, fy, tz, nmin = stick_forces(P, sx, sy, W, W_U)
    if nmin <= 0.0 or stick_ratio(P, fx, fy, tz, W) > 1.0:
        return False
    aux[AX_MODE] = STICK
    vx, vy, wz = plate_twist(sx, sy, W)
    y[3] = vx
    y[4] = vy
    y[5] = wz
    return True


# ------------------------------------------------------------------ events


@njit(cache=True)
def event_value(kind, mc, P, aux, t, y, W):
    """The mode's event function; an event occurs where it falls to <= 0. +1 when none applies."""
    if kind == 0:
        x, yy = _point_xy(P, y)
        ahx, ahy, n, vhx, vhy = point_plate(mc, P, t, x, yy, W)
        if aux[AX_MODE] == SLIDE:
            # w . d < 0: w turned by more than 90 degrees within the step (through or near zero).
            W[W_S] = y[2] - vhx
            W[W_S + 1] = y[3] - vhy
            return W[W_S] * aux[AX_DX] + W[W_S + 1] * aux[AX_DY]
        return P[PP_MUS] * n - math.hypot(ahx, ahy)
    plate_eval(mc, t, W, W_U, W_V)
    sx, sy, _ = geometry_for(P, y, W)
    if aux[AX_MODE] == SLIDE:
        # Band edges |u_i| = eps are kinks of the regularised law: steps stop there. Outside the
        # band, u_i . d_i = 0 catches a contact velocity that swings past (or through) zero
        # within one step; the first zero of the minimum is then the band entry, if any.
        contact_velocities(sx, sy, y[3], y[4], y[5], W)
        eps = P[RP_EPS]
        g = 1e300
        for i in range(3):
            ux = W[W_E + 2 * i]
            uy = W[W_E + 2 * i + 1]
            nu = math.hypot(ux, uy)
            if aux[AX_BAND + i] > 0.0:
                g = min(g, eps - nu)
            else:
                swing = ux * aux[AX_RD + 2 * i] + uy * aux[AX_RD + 2 * i + 1]
                g = min(g, nu - eps, swing)
        return g
    fx, fy, tz, nmin = stick_forces(P, sx, sy, W, W_U)
    if nmin <= 0.0:
        return -1.0
    return 1.0 - stick_ratio(P, fx, fy, tz, W)


@njit(cache=True)
def on_event(kind, mc, P, aux, t, y, W, zero_tol, force_zero):
    """Apply the event located at (t, y)."""
    if kind == 1:
        if aux[AX_MODE] == STICK:
            # Break-away: the regularised law takes the part off from the plate twist (u = 0).
            aux[AX_MODE] = SLIDE
            for i in range(3):
                aux[AX_BAND + i] = 1.0
        else:
            _rigid_contacts(mc, P, aux, t, y, W, True)
        return
    x, yy = _point_xy(P, y)
    ahx, ahy, n, vhx, vhy = point_plate(mc, P, t, x, yy, W)
    if aux[AX_MODE] == STICK:
        aux[AX_MODE] = SLIDE
        a = math.hypot(ahx, ahy)
        if a > 0.0:
            aux[AX_DX] = -ahx / a
            aux[AX_DY] = -ahy / a
        return
    wx = y[2] - vhx
    wy = y[3] - vhy
    nw = math.hypot(wx, wy)
    if nw <= zero_tol or force_zero:
        y[2] = vhx
        y[3] = vhy
        point_at_zero(P, aux, ahx, ahy, n)
    else:
        aux[AX_DX] = wx / nw
        aux[AX_DY] = wy / nw


@njit(cache=True)
def _directions_from_end(kind, P, aux, W, zero_tol):
    """After an accepted sliding step: the reference directions become those at the step's end
    (left in W by event_value), so the next step's continuation and swing test start from there."""
    if kind == 0:
        nw = math.hypot(W[W_S], W[W_S + 1])
        if nw > zero_tol:
            aux[AX_DX] = W[W_S] / nw
            aux[AX_DY] = W[W_S + 1] / nw
        return
    for i in range(3):
        if aux[AX_BAND + i] == 0.0:
            ux = W[W_E + 2 * i]
            uy = W[W_E + 2 * i + 1]
            nu = math.hypot(ux, uy)
            if nu > 0.0:
                aux[AX_RD + 2 * i] = ux / nu
                aux[AX_RD + 2 * i + 1] = uy / nu


@njit(cache=True)
def _point_w(mc, P, t, y, W):
    x, yy = _point_xy(P, y)
    _, _, _, vhx, vhy = point_plate(mc, P, t, x, yy, W)
    return math.hypot(y[2] - vhx, y[3] - vhy)


@njit(cache=True)
def _locate(kind, mc, P, aux, t, y, hh, g0, g1, err1, A, B, C, E, E3, combined, K, ytmp, ynew, ybest, W, sc,
            n):
    """Illinois false position for the event inside the step (t, t + hh]; the state just past the
    event is left in ``ynew``. Returns its offset from t and the error norm of the step to it.
    K[0] must hold f(t, y)."""
    a = 0.0
    fa = g0
    b = hh
    fb = g1
    errb = err1
    for j in range(n):
        ybest[j] = ynew[j]
    side = 0
    for _ in range(80):
        if b - a <= 1e-13 * hh or fb == 0.0:
            break
        c = b - fb * (b - a) / (fb - fa) if fb != fa else 0.5 * (a + b)
        if not (a < c < b):
            c = 0.5 * (a + b)
        errc, _ = rk_step(kind, mc, P, aux, t, y, c, A, B, C, E, E3, combined, K, True, ytmp, ynew, W, sc, n)
        fc = event_value(kind, mc, P, aux, t + c, ynew, W)
        if fc <= 0.0:
            b = c
            fb = fc
            errb = errc
            for j in range(n):
                ybest[j] = ynew[j]
            if side == -1:
                fa *= 0.5
            side = -1
        else:
            a = c
            fa = fc
            if side == 1:
                fb *= 0.5
            side = 1
    for j in range(n):
        ynew[j] = ybest[j]
    return b, errb


@njit(cache=True)
def advance(kind, mc, P, aux, t0, t1, y, h, period, A, B, C, E, E3, S, K, ytmp, ynew, ybest, W, sc, n,
            max_steps, zero_tol, stats):
    """Integrate from t0 to t1 in place (y, aux); returns (status, next step size).

    stats: [0] += time spent sticking, [1] += attempted steps, [2] += events.
    """
    combined = S[S_ERRKIND] > 0.0
    expo = S[S_EXPONENT]
    capture = S[S_CAPTURE]
    ns = B.shape[0]
    t = t0
    reuse = False
    steps = 0
    zeno = 0
    h_status_min = 1e-7 * period
    span = t1 - t0
    while t1 - t > 1e-14 * span:
        if steps >= max_steps:
            stats[1] += steps
            return STEP_LIMIT, h
        hh = h if h < t1 - t else t1 - t
        err, st = rk_step(kind, mc, P, aux, t, y, hh, A, B, C, E, E3, combined, K, reuse, ytmp, ynew, W, sc,
                          n)
        reuse = True  # K[0] = f(t, y) stays valid until y or aux change
        steps += 1
        if st != OK:
            # Contact lost or singular somewhere in the step: shrink to find when, then report it.
            if hh > h_status_min:
                h = 0.25 * hh
                continue
            stats[1] += steps
            return st, h
        # Events first: a step across an event straddles a kink of the right-hand side, so its
        # error estimate says nothing about the step up to the event.
        g1 = event_value(kind, mc, P, aux, t + hh, ynew, W)
        if g1 <= 0.0:
            g0 = event_value(kind, mc, P, aux, t, y, W)
            if g0 > 0.0:
                tau, err_tau = _locate(kind, mc, P, aux, t, y, hh, g0, g1, err, A, B, C, E, E3, combined, K,
                                       ytmp, ynew, ybest, W, sc, n)
            else:
                tau, err_tau = hh, err
            if not (err_tau <= 1.0):
                # The event lies beyond one accurate step: step towards it first.
                fac = 0.2 if not math.isfinite(err_tau) else max(0.2, 0.9 * err_tau ** expo)
                h = min(tau, hh) * fac
                continue
            if kind == 0 and aux[AX_MODE] == SLIDE and tau > 1e-12 * period \
                    and _point_w(mc, P, t + tau, ynew, W) > zero_tol:
                # w swung round faster than one step but missed zero: resolve it with shorter steps
                # (the continued direction is only smooth through zero itself).
                h = 0.5 * min(tau, hh)
                continue
            if aux[AX_MODE] == STICK:
                stats[0] += tau
            t += tau
            for j in range(n):
                y[j] = ynew[j]
            zeno = zeno + 1 if tau < 1e-6 * period else 0
            on_event(kind, mc, P, aux, t, y, W, zero_tol, zeno > 4 or kind == 0)
            if zeno > 4:
                zeno = 0
            stats[2] += 1
            reuse = False
            continue
        if not (err <= 1.0):
            fac = 0.2 if not math.isfinite(err) else max(0.2, 0.9 * err ** expo)
            h = hh * fac
            continue
        fac = 5.0 if err == 0.0 else min(5.0, max(0.2, 0.9 * err ** expo))
        if aux[AX_MODE] == STICK:
            stats[0] += hh
        else:
            _directions_from_end(kind, P, aux, W, zero_tol)
        t += hh
        for j in range(n):
            y[j] = ynew[j]
            K[0, j] = K[ns, j]
        if kind == 1 and aux[AX_MODE] == SLIDE and rigid_try_stick(mc, P, aux, t, y, W, capture):
            reuse = False
            stats[2] += 1
        h = max(h, hh * fac) if hh < h else hh * fac
    stats[1] += steps
    return OK, h

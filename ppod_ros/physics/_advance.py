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

import numpy as np

from ppod_ros.physics._contact import (
    contact_velocities,
    geometry_for,
    plate_twist,
    point_plate,
    sliding_accelerations,
    stick_forces,
    stick_ratio,
)
from ppod_ros.physics._jit import njit
from ppod_ros.physics._layout import (
    AX_BAND,
    AX_DEPART,
    AX_DX,
    AX_DY,
    AX_MODE,
    AX_RD,
    OK,
    PP_CANSTICK,
    PP_CAPTURE_M,
    PP_EVOLVE,
    PP_KAPPA,
    PP_KAPPA_DEPART,
    PP_LAG_MAX,
    PP_MU,
    PP_MUS,
    PP_X,
    PP_Y,
    RP_CANSTICK,
    RP_EPS,
    RP_EVOLVE,
    RP_X,
    RP_Y,
    RP_ZTOL,
    S_ATOL_V,
    S_CAPTURE,
    S_ERRKIND,
    S_EVENT_ERR_MAX,
    S_EXPONENT,
    S_KAPPA,
    S_KAPPA_DEPART,
    S_LAG_MAX,
    S_MIN_STEPS,
    S_RTOL,
    S_ZERO_PER_RTOL,
    S_ZERO_RTOL,
    SLIDE,
    STEP_LIMIT,
    STICK,
    W_E,
    W_H,
    W_RX,
    W_RY,
    W_S,
    W_U,
    W_V,
)
from ppod_ros.physics._rk import rk_step
from ppod_ros.physics.plate import G, plate_eval

#: Relative speeds below this many times rtol x the velocity scale (plus ``zero_velocity_rtol``)
#: count as zero (``S_ZERO_PER_RTOL``, :func:`zero_tolerance`).
ZERO_PER_RTOL = 10.0
#: Relative speeds below this many velocity step tolerances are "just leaving zero" or "about to
#: stick" (``PP_KAPPA``): following w / |w| there would take ever shorter steps for a change in
#: velocity below it. Without a departure from zero (AX_DEPART) this band also catches a slip that
#: only swings past zero (nearly collinear motions) and turns its friction to -a_h before the
#: reversal: an error of order the band per reversal. At 100 tolerances LineSinkXPlant was off by
#: up to 2.3e-6 m/s against the fixed-step reference, at 10 by 4.3e-7, in fewer steps (S_KAPPA).
KAPPA_PER_STEP_TOL = 10.0
#: After a departure from w = 0 (a break-away, a pass through zero), the slip slides along -a_h,
#: turned by its first-order lag (``_contact.point_rhs``), up to this many step tolerances
#: (``PP_KAPPA_DEPART``); a slip about to stick may be captured up to the same speed
#: (:func:`_point_capture`). w / |w| makes that phase stiff (rate |a_h| / |w|), so it took most of
#: the steps of a period with long sticking (Stick2D: 70 of 167 at 100 tolerances). Along -a_h
#: alone 1000 was the limit (1e4 was off by 9.3e-7 m/s on Stick2D); with the lag 1e4 stays within
#: 1.2e-8 m/s of the fixed-step reference (3e4: 5.4e-8, 1e5: 1.7e-6) in 97 instead of 122 steps per
#: period (docs/solver.md).
KAPPA_DEPART_PER_STEP_TOL = 1e4
#: A trial step whose error norm exceeds this is shrunk at once, without looking for an event in it
#: (``S_EVENT_ERR_MAX``): no event location on a step this far off. Lower values were measured and
#: not taken (10: LineSinkXPlant 141 -> 123 steps and re-steps per period, Stick2D 129 -> 137).
EVENT_ERR_MAX = 1e3
#: Largest lag (rad) of a slip leaving zero behind -a_h taken from the first-order slow manifold
#: (``_contact.point_rhs``; ``PP_LAG_MAX``): the expansion is in |w| psi' / |a_h|, far below this in
#: the departure band. 0 slides along -a_h itself (the tests compare).
LAG_MAX_RAD = 0.1


@njit(cache=True, error_model="numpy")
def point_speed_limits(P, S, step_tol, period):
    """Set a point part's PP_KAPPA and PP_KAPPA_DEPART (m/s) from its velocity step tolerance (m/s)
    and S (``S_KAPPA``, ``S_KAPPA_DEPART``: KAPPA_PER_STEP_TOL and KAPPA_DEPART_PER_STEP_TOL from
    ``SolverSettings.vector``), PP_LAG_MAX (rad, ``S_LAG_MAX``: LAG_MAX_RAD), and PP_CAPTURE_M: the
    position error (m) an early capture may make, one step tolerance of the period's average
    velocity (see :func:`_point_capture`)."""
    P[PP_KAPPA] = S[S_KAPPA] * step_tol
    P[PP_KAPPA_DEPART] = S[S_KAPPA_DEPART] * step_tol
    P[PP_LAG_MAX] = S[S_LAG_MAX]
    P[PP_CAPTURE_M] = step_tol * period


@njit(cache=True, error_model="numpy")
def zero_tolerance(S, vscale):
    """Relative speeds below this count as zero (m/s): below what the integration can resolve
    (10 rtol times the velocity scale), so that numerical noise off an exactly symmetric motion
    is not mistaken for a slide past zero that must be resolved step by step."""
    return (S[S_ZERO_RTOL] + S[S_ZERO_PER_RTOL] * S[S_RTOL]) * vscale + 1e-3 * S[S_ATOL_V]


# ------------------------------------------------------------------ point part


@njit(cache=True, error_model="numpy")
def _point_xy(P, y):
    if P[PP_EVOLVE] > 0.0:
        return y[0], y[1]
    return P[PP_X], P[PP_Y]


@njit(cache=True, error_model="numpy")
def point_at_zero(P, aux, ahx, ahy, n):
    """w = 0: stick if the static friction can hold the part, else slide along -a_h."""
    a = math.hypot(ahx, ahy)
    if P[PP_CANSTICK] > 0.0 and a <= P[PP_MUS] * n:
        aux[AX_MODE] = STICK
        return
    aux[AX_MODE] = SLIDE
    aux[AX_DEPART] = 1.0
    if a > 0.0:
        aux[AX_DX] = -ahx / a
        aux[AX_DY] = -ahy / a


@njit(cache=True, error_model="numpy")
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
        aux[AX_DEPART] = 0.0
        aux[AX_DX] = wx / nw
        aux[AX_DY] = wy / nw


# ------------------------------------------------------------------ rigid part


@njit(cache=True, error_model="numpy")
def _rigid_refresh(mc, P, t, y, W):
    """Plate motion (W_U, W_V), geometry and contact sliding velocities (W_E) at (t, y)."""
    plate_eval(mc, t, W, W_U, W_V)
    sx, sy, _ = geometry_for(P, y, W)
    contact_velocities(sx, sy, y[3], y[4], y[5], W)
    return sx, sy


@njit(cache=True, error_model="numpy")
def rigid_init(mc, P, aux, t, y, W, capture):
    """Choose the mode for state y at time t: sticking if the part rests on the plate and can stay;
    otherwise each contact slides along its velocity, or, at rest, starts in the band (the
    regularised law then picks its direction)."""
    aux[AX_MODE] = SLIDE
    if rigid_try_stick(mc, P, aux, t, y, W, capture):
        return
    _rigid_refresh(mc, P, t, y, W)
    for i in range(3):
        ux = W[W_E + 2 * i]
        uy = W[W_E + 2 * i + 1]
        nu = math.hypot(ux, uy)
        if nu <= P[RP_ZTOL]:
            aux[AX_BAND + i] = 1.0
        else:
            aux[AX_BAND + i] = 0.0
            aux[AX_RD + 2 * i] = ux / nu
            aux[AX_RD + 2 * i + 1] = uy / nu


@njit(cache=True, error_model="numpy")
def _rigid_contact_event(mc, P, aux, t, y, W, capture):
    """A contact event at (t, y): band exits, swings, and zeros of contact velocities.

    A contact whose velocity reached zero passes through (its friction reverses) if, with the
    reversed friction, its velocity keeps growing the new way; otherwise it pivots (stays at rest on
    the plate): it enters the band, where the regularised law holds it. If every contact is at
    rest, the sticking test decides first.
    """
    sx, sy = _rigid_refresh(mc, P, t, y, W)
    ztol = P[RP_ZTOL]
    eps = P[RP_EPS]
    zero = np.zeros(3, np.bool_)
    nzero = 0
    for i in range(3):
        ux = W[W_E + 2 * i]
        uy = W[W_E + 2 * i + 1]
        nu = math.hypot(ux, uy)
        if aux[AX_BAND + i] > 0.0:
            if nu >= eps - ztol:
                aux[AX_BAND + i] = 0.0
                aux[AX_RD + 2 * i] = ux / nu
                aux[AX_RD + 2 * i + 1] = uy / nu
        elif nu <= ztol:
            zero[i] = True
            nzero += 1
        elif ux * aux[AX_RD + 2 * i] + uy * aux[AX_RD + 2 * i + 1] <= ztol:
            aux[AX_RD + 2 * i] = ux / nu
            aux[AX_RD + 2 * i + 1] = uy / nu
    if nzero == 0:
        return
    if rigid_try_stick(mc, P, aux, t, y, W, capture):
        return
    for i in range(3):
        if zero[i]:
            aux[AX_RD + 2 * i] = -aux[AX_RD + 2 * i]
            aux[AX_RD + 2 * i + 1] = -aux[AX_RD + 2 * i + 1]
    Kt = np.zeros((1, 6))
    sliding_accelerations(P, aux, sx, sy, y[3], y[4], y[5], W, Kt, 0)
    h = W[W_H]
    for i in range(3):
        if zero[i]:
            rx = W[W_RX + i]
            ry = W[W_RY + i]
            dux = Kt[0, 3] - h * W[W_U + 4] - Kt[0, 5] * ry - (W[W_U + 0] - W[W_U + 5] * (sy + ry))
            duy = Kt[0, 4] + h * W[W_U + 3] + Kt[0, 5] * rx - (W[W_U + 1] + W[W_U + 5] * (sx + rx))
            if dux * aux[AX_RD + 2 * i] + duy * aux[AX_RD + 2 * i + 1] <= 0.0:
                aux[AX_BAND + i] = 1.0


@njit(cache=True, error_model="numpy")
def rigid_try_stick(mc, P, aux, t, y, W, capture):
    """Enter sticking if every contact is (nearly) at rest on the plate and the cone program says the
    needed forces fit; the twist is then set to the plate's. Returns True if the part now sticks."""
    if P[RP_CANSTICK] <= 0.0:
        return False
    plate_eval(mc, t, W, W_U, W_V)
    sx, sy, _ = geometry_for(P, y, W)
    umax = contact_velocities(sx, sy, y[3], y[4], y[5], W)
    if umax > max(capture * P[RP_EPS], P[RP_ZTOL]):
        return False
    fx, fy, tz, nmin = stick_forces(P, sx, sy, W, W_U)
    if nmin <= 0.0 or stick_ratio(P, fx, fy, tz, W, True) > 1.0:
        return False
    aux[AX_MODE] = STICK
    vx, vy, wz = plate_twist(sx, sy, W)
    y[3] = vx
    y[4] = vy
    y[5] = wz
    return True


# ------------------------------------------------------------------ events


@njit(cache=True, error_model="numpy")
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
        # Per contact: u_i . d_i = 0 (a zero, or a swing past 90 degrees within one step, as for
        # point parts); for a contact in the band, leaving it (|u_i| = eps, a kink of the law).
        contact_velocities(sx, sy, y[3], y[4], y[5], W)
        eps = P[RP_EPS]
        g = 1e300
        for i in range(3):
            ux = W[W_E + 2 * i]
            uy = W[W_E + 2 * i + 1]
            if aux[AX_BAND + i] > 0.0:
                g = min(g, eps - math.hypot(ux, uy))
            else:
                g = min(g, ux * aux[AX_RD + 2 * i] + uy * aux[AX_RD + 2 * i + 1])
        return g
    fx, fy, tz, nmin = stick_forces(P, sx, sy, W, W_U)
    if nmin <= 0.0:
        return -1.0
    return 1.0 - stick_ratio(P, fx, fy, tz, W, False)


@njit(cache=True, error_model="numpy")
def on_event(kind, mc, P, aux, t, y, W, zero_tol, force_zero, capture):
    """Apply the event located at (t, y)."""
    if kind == 1:
        if aux[AX_MODE] == STICK:
            # Break-away: the regularised law takes the part off from the plate twist (u = 0).
            aux[AX_MODE] = SLIDE
            for i in range(3):
                aux[AX_BAND + i] = 1.0
        else:
            _rigid_contact_event(mc, P, aux, t, y, W, capture)
        return
    x, yy = _point_xy(P, y)
    ahx, ahy, n, vhx, vhy = point_plate(mc, P, t, x, yy, W)
    if aux[AX_MODE] == STICK:
        aux[AX_MODE] = SLIDE
        aux[AX_DEPART] = 1.0
        y[2] = vhx  # leave exactly from the plate's velocity (no drift of the sticking phase)
        y[3] = vhy
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
        aux[AX_DEPART] = 0.0  # w only swung round: no departure from zero
        aux[AX_DX] = wx / nw
        aux[AX_DY] = wy / nw


@njit(cache=True, error_model="numpy")
def _point_capture(P, aux, y, W, capture):
    """After a sliding step (W holding the step end's w and plate motion, from event_value): a part
    whose relative speed is below ``capture`` while kinetic friction still decelerates it
    (mu n > |a_h|) and static friction can hold it, would stick within a time of order
    capture / (mu n - |a_h|); stick now. Resolving that last approach would need steps ever
    shorter near the singularity of w/|w| at w = 0 (in 2-D w turns ever faster as it shrinks).
    Up to PP_KAPPA_DEPART too when the position this skips, at most |w|^2 / (2 (mu n - |a_h|)) as
    |w| falls at least that fast, stays below PP_CAPTURE_M."""
    nw = math.hypot(W[W_S], W[W_S + 1])
    if P[PP_CANSTICK] <= 0.0 or nw > max(capture, P[PP_KAPPA_DEPART]):
        return False
    x, yy = _point_xy(P, y)
    ahx = W[W_U + 0] - W[W_U + 5] * yy
    ahy = W[W_U + 1] + W[W_U + 5] * x
    n = G + W[W_U + 2] + W[W_U + 3] * yy - W[W_U + 4] * x
    a = math.hypot(ahx, ahy)
    if a >= P[PP_MU] * n or a > P[PP_MUS] * n:
        return False
    if nw > capture and nw * nw > 2.0 * (P[PP_MU] * n - a) * P[PP_CAPTURE_M]:
        return False
    y[2] -= W[W_S]
    y[3] -= W[W_S + 1]
    aux[AX_MODE] = STICK
    return True


@njit(cache=True, error_model="numpy")
def _directions_from_end(kind, P, aux, W, zero_tol):
    """After an accepted sliding step: the reference directions become those at the step's end
    (left in W by event_value), so the next step's continuation and swing test start from there."""
    if kind == 0:
        nw = math.hypot(W[W_S], W[W_S + 1])
        if nw > P[PP_KAPPA_DEPART]:
            aux[AX_DEPART] = 0.0
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


@njit(cache=True, error_model="numpy")
def _locate(kind, mc, P, aux, t, y, hh, g0, g1, err1, A, B, C, E, E3, combined, K, ytmp, ynew, ybest, W, sc,
            n):
    """The event inside the step (t, t + hh], by re-stepping from t: the state just past it is left in
    ``ynew``. Returns its offset from t, the error norm of the step to it, and the re-steps used.

    Steps that stop before the event are smooth and accurate; steps past it straddle a kink and may
    give poor values (their sign is still right). So: false position (Illinois) while the point past
    the event comes from an accurate step, secant through the two last points before it otherwise
    (aimed a little past, the aim growing while the iterates fall short), bisection as a safeguard.
    If a step that stops before the event is itself inaccurate, the event lies beyond one accurate
    step: that step's offset and error are returned at once (the caller shortens the step).
    K[0] must hold f(t, y).
    """
    a = 0.0
    fa = g0
    ap = -1.0
    fap = 0.0
    b = hh
    fb = g1
    errb = err1
    trusted = err1 <= 1.0
    side = 0
    for j in range(n):
        ybest[j] = ynew[j]
    tol = 1e-12 * hh
    push = 0.5 * tol
    it = 0
    for it in range(100):
        if b - a <= tol:
            break
        if trusted:
            c = b - fb * (b - a) / (fb - fa) if fb != fa else 0.5 * (a + b)
        elif ap >= 0.0 and fap != fa:
            c = a - fa * (a - ap) / (fa - fap) + push
        elif it == 0:
            c = b * g0 / (g0 - g1) if g0 != g1 else 0.5 * b
        else:
            c = 0.5 * (a + b)
        if not (a < c < b):
            c = 0.5 * (a + b)
        errc, _ = rk_step(kind, mc, P, aux, t, y, c, A, B, C, E, E3, combined, K, True, ytmp, ynew, W, sc, n)
        fc = event_value(kind, mc, P, aux, t + c, ynew, W)
        if fc <= 0.0:
            b = c
            fb = fc
            errb = errc
            trusted = errc <= 1.0
            for j in range(n):
                ybest[j] = ynew[j]
            push = 0.5 * tol
            if side == -1:
                fa *= 0.5
            side = -1
        else:
            if not (errc <= 1.0):
                return c, errc, it + 1
            ap = a
            fap = fa
            a = c
            fa = fc
            push *= 16.0
            if side == 1:
                fb *= 0.5
            side = 1
    for j in range(n):
        ynew[j] = ybest[j]
    return b, errb, it


@njit(cache=True, error_model="numpy")
def advance(kind, mc, P, aux, t0, t1, y, h, period, A, B, C, E, E3, S, K, ytmp, ynew, ybest, W, sc, n,
            max_steps, zero_tol, stats):
    """Integrate from t0 to t1 in place (y, aux); returns (status, next step size).

    stats: [0] += time spent sticking, [1] += attempted steps, [2] += events, [3] += extra steps
    taken to locate events.
    """
    combined = S[S_ERRKIND] > 0.0
    expo = S[S_EXPONENT]
    capture = S[S_CAPTURE]
    ns = B.shape[0]
    t = t0
    reuse = False
    steps = 0
    zeno = 0
    wmax = 0.0
    for r in range(mc.shape[0]):
        wmax = max(wmax, mc[r, 0])
    hmax = period / S[S_MIN_STEPS]
    if wmax > 0.0:
        hmax = min(hmax, 2.0 * math.pi / wmax / S[S_MIN_STEPS])
    if h > hmax:
        h = hmax
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
        if err > S[S_EVENT_ERR_MAX]:
            # Far off (a stiff band entered with a long step, say): no event location on garbage.
            h = 0.2 * hh
            continue
        g1 = event_value(kind, mc, P, aux, t + hh, ynew, W)
        if g1 <= 0.0:
            g0 = event_value(kind, mc, P, aux, t, y, W)
            if 0.0 < g0 <= zero_tol and aux[AX_MODE] == SLIDE:
                # The event is where we stand (a second contact reaching its band edge with the
                # first, say): apply it without stepping.
                on_event(kind, mc, P, aux, t, y, W, zero_tol, False, capture)
                stats[2] += 1
                reuse = False
                continue
            if g0 > 0.0:
                tau, err_tau, its = _locate(kind, mc, P, aux, t, y, hh, g0, g1, err, A, B, C, E, E3, combined,
                                            K, ytmp, ynew, ybest, W, sc, n)
                stats[3] += its
            else:
                tau, err_tau = hh, err
            if not (err_tau <= 1.0):
                # The event lies beyond one accurate step: step towards it first.
                fac = 0.2 if not math.isfinite(err_tau) else max(0.2, 0.9 * err_tau ** expo)
                h = min(tau, hh) * fac
                continue
            if aux[AX_MODE] == STICK:
                stats[0] += tau
            t += tau
            for j in range(n):
                y[j] = ynew[j]
            zeno = zeno + 1 if tau < 1e-6 * period else 0
            on_event(kind, mc, P, aux, t, y, W, zero_tol, zeno > 4, capture)
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
        if kind == 0 and aux[AX_MODE] == STICK:
            # A sticking point part moves exactly with the plate (event_value left v at t in W).
            x, yy = _point_xy(P, y)
            y[2] = W[W_V + 0] - W[W_V + 5] * yy
            y[3] = W[W_V + 1] + W[W_V + 5] * x
            K[0, 0] = y[2]
            K[0, 1] = y[3]
            K[0, 2] = W[W_U + 0] - W[W_U + 5] * yy
            K[0, 3] = W[W_U + 1] + W[W_U + 5] * x
        if kind == 1 and aux[AX_MODE] == STICK:
            # A sticking rigid part moves exactly with the plate, like the point part above
            # (event_value left the plate at t and the geometry at y in W). Integrating the plate's
            # acceleration instead lets the twist drift off the plate's when the configuration
            # evolves (the full dynamics: the convective term is not in the stick rhs); at the
            # break-away the regularised law would then see a slip of many eps and answer with
            # friction far beyond Coulomb's, and a spurious contact loss.
            vx, vy, wz = plate_twist(y[0] if P[RP_EVOLVE] > 0.0 else P[RP_X],
                                     y[1] if P[RP_EVOLVE] > 0.0 else P[RP_Y], W)
            y[3] = vx
            y[4] = vy
            y[5] = wz
            K[0, 0] = vx
            K[0, 1] = vy
            K[0, 2] = wz
        if kind == 0 and aux[AX_MODE] == SLIDE and _point_capture(P, aux, y, W, P[PP_KAPPA]):
            reuse = False
            stats[2] += 1
        if kind == 1 and aux[AX_MODE] == SLIDE and aux[AX_BAND] + aux[AX_BAND + 1] + aux[AX_BAND + 2] > 0.0 \
                and rigid_try_stick(mc, P, aux, t, y, W, capture):
            # Contacts held by the regularised law may all have come to rest: stick if allowed.
            reuse = False
            stats[2] += 1
        h = max(h, hh * fac) if hh < h else hh * fac
        if h > hmax:
            h = hmax
    stats[1] += steps
    return OK, h

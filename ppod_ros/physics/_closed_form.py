"""Closed-form limit cycle of a point part where the plate's horizontal motion is collinear.

If every harmonic of a_h at the point r is parallel to one unit vector e (translations along a
line, rotations about z, line sinks...), a part starting on the line through 0 along e stays on
it, and the problem is scalar: with lambda = e . s, alpha = e . a_h, lambda_v = e . v_h,

    sliding  (sigma = sign(lambda - lambda_v)):   lambda(t) = lambda(t0) - sigma mu (N(t) - N(t0))
    sticking:                                      lambda(t) = lambda_v(t)

where N(t) = g t + integral of a_n is known in closed form; so are the cycle integrals. The only
numerical work is locating events: zeros of F = lambda - lambda_v (stick or reversal) and of
G = mu_s^2 n^2 - alpha^2 (break-away), by scanning plus safeguarded Newton, checking interior
minima so that a double crossing between two samples is not missed. The one-period map has an
exact derivative (a product of the reversal factors (alpha - sigma mu n)/(alpha + sigma mu n), zero
after any sticking), so Newton's method converges quadratically.
"""

from __future__ import annotations

import math

import numpy as np

from ppod_ros.physics._jit import njit
from ppod_ros.physics._layout import NOT_CONVERGED, OK, STEP_LIMIT
from ppod_ros.physics.plate import G


@njit(cache=True, error_model="numpy")
def principal_direction(mc, x, y):
    """(is_collinear, ex, ey, across): the principal direction e of a_h at (x, y) over the cycle,
    the fraction ``across`` of a_h's energy perpendicular to it (0 <= across <= 0.5), and whether
    that is below (1e-10)^2 (collinear: a_h keeps one direction for all t)."""
    gxx = 0.0
    gxy = 0.0
    gyy = 0.0
    for r in range(mc.shape[0]):
        for off in (1, 7):
            ax = mc[r, off + 0] - mc[r, off + 5] * y
            ay = mc[r, off + 1] + mc[r, off + 5] * x
            gxx += ax * ax
            gxy += ax * ay
            gyy += ay * ay
    tr = gxx + gyy
    if tr == 0.0:
        return True, 1.0, 0.0, 0.0
    ang = 0.5 * math.atan2(2.0 * gxy, gxx - gyy)
    ex = math.cos(ang)
    ey = math.sin(ang)
    # Energy across the principal direction, summed directly (the determinant of the Gram matrix
    # would lose it to cancellation): collinear if below (1e-10)^2 of the total.
    perp = 0.0
    for r in range(mc.shape[0]):
        for off in (1, 7):
            ax = mc[r, off + 0] - mc[r, off + 5] * y
            ay = mc[r, off + 1] + mc[r, off + 5] * x
            perp += (ex * ay - ey * ax) ** 2
    if perp > 1e-20 * tr:
        return False, ex, ey, perp / tr
    return True, ex, ey, perp / tr


@njit(cache=True, error_model="numpy")
def line_table(mc, x, y, ex, ey):
    """Coefficients along e at (x, y): rows [w, alpha(s,c), lambda_v(s,c), Lambda_v(s,c), a_n(s,c),
    v_n(s,c), d_n(s,c), a_perp(s,c), v_perp(s,c)] (17 columns; perp: along (-ey, ex), used by
    :func:`line_perp` only)."""
    K = mc.shape[0]
    c1 = np.zeros((K, 17))
    for r in range(K):
        c1[r, 0] = mc[r, 0]
        for q, off in enumerate((1, 7, 13, 19, 25, 31)):
            hx = mc[r, off + 0] - mc[r, off + 5] * y
            hy = mc[r, off + 1] + mc[r, off + 5] * x
            nn = mc[r, off + 2] + mc[r, off + 3] * y - mc[r, off + 4] * x
            # off 1/7: acceleration sin/cos; 13/19: velocity; 25/31: displacement
            grp = q // 2
            sc = q % 2
            c1[r, 1 + 2 * grp + sc] = ex * hx + ey * hy
            c1[r, 7 + 2 * grp + sc] = nn
            if grp < 2:
                c1[r, 13 + 2 * grp + sc] = ex * hy - ey * hx
    return c1


@njit(cache=True, error_model="numpy")
def eval_line(c1, t):
    """(alpha, alpha', lambda_v, Lambda_v, n, n', N, M) at t."""
    al = 0.0
    dal = 0.0
    lv = 0.0
    Lv = 0.0
    n = G
    dn = 0.0
    N = G * t
    M = 0.5 * G * t * t
    for r in range(c1.shape[0]):
        w = c1[r, 0]
        s = math.sin(w * t)
        c = math.cos(w * t)
        al += c1[r, 1] * s + c1[r, 2] * c
        dal += w * (c1[r, 1] * c - c1[r, 2] * s)
        lv += c1[r, 3] * s + c1[r, 4] * c
        Lv += c1[r, 5] * s + c1[r, 6] * c
        n += c1[r, 7] * s + c1[r, 8] * c
        dn += w * (c1[r, 7] * c - c1[r, 8] * s)
        N += c1[r, 9] * s + c1[r, 10] * c
        M += c1[r, 11] * s + c1[r, 12] * c
    return al, dal, lv, Lv, n, dn, N, M


@njit(cache=True, error_model="numpy")
def _phi(c1, which, t, lam0, sig, mu, mus, N0):
    """Event function and its derivative: which 0 = sigma F (sliding), 1 = G (sticking)."""
    al, dal, lv, Lv, n, dn, N, M = eval_line(c1, t)
    if which == 0:
        F = lam0 - sig * mu * (N - N0) - lv
        dF = -sig * mu * n - al
        return sig * F, sig * dF
    return mus * mus * n * n - al * al, 2.0 * (mus * mus * n * dn - al * dal)


@njit(cache=True, error_model="numpy")
def first_event(c1, which, t0, t1, dt, lam0, sig, mu, mus, N0, ftol):
    """First t in (t0, t1] where phi falls to <= -ftol (phi > 0 just after t0), or -1 if none.

    Sliding starts at a zero of F (phi(t0) = 0); at a break-away with mu_s = mu even phi'(t0) = 0,
    and rounding must not turn that start into an event: hence ftol > 0 for sliding. Sticking may
    end at once (phi(t0) = 0 and falling): then t0 is returned.
    """
    fa, da = _phi(c1, which, t0, lam0, sig, mu, mus, N0)
    if which == 1 and fa <= 0.0 and da < 0.0:
        return t0
    ta = t0
    while ta < t1:
        tb = min(ta + dt, t1)
        fb, db = _phi(c1, which, tb, lam0, sig, mu, mus, N0)
        lo = -1.0
        hi = -1.0
        if fb <= -ftol:
            lo, hi = ta, tb
        elif da < 0.0 < db:
            # Interior minimum: find it (bisection on phi'), then test its sign.
            a, b = ta, tb
            for _ in range(60):
                m = 0.5 * (a + b)
                fm, dm = _phi(c1, which, m, lam0, sig, mu, mus, N0)
                if dm < 0.0:
                    a = m
                else:
                    b = m
                if b - a < 1e-15 * (1.0 + abs(t1)):
                    break
            fm, dm = _phi(c1, which, 0.5 * (a + b), lam0, sig, mu, mus, N0)
            if fm <= -ftol:
                lo, hi = ta, 0.5 * (a + b)
        if hi >= 0.0:
            return _refine(c1, which, lo, hi, lam0, sig, mu, mus, N0)
        ta = tb
        fa = fb
        da = db
    return -1.0


@njit(cache=True, error_model="numpy")
def _refine(c1, which, lo, hi, lam0, sig, mu, mus, N0):
    """Safeguarded Newton for the first root in [lo, hi] with phi(lo) >= 0 (or lo = t0), phi(hi) <= 0."""
    t = hi
    for _ in range(100):
        f, d = _phi(c1, which, t, lam0, sig, mu, mus, N0)
        if f <= 0.0:
            hi = t
        else:
            lo = t
        if hi - lo <= 4e-16 * (1.0 + abs(hi)):
            break
        tn = t - f / d if d != 0.0 else 0.5 * (lo + hi)
        if not (lo < tn < hi):
            tn = 0.5 * (lo + hi)
        t = tn
    return hi


@njit(cache=True, error_model="numpy")
def line_period(c1, mu, mus, can_stick, T, lam0, dt, zero_tol, stats, seg, mu_arrive):
    """One period from lambda(0) = lam0: returns (lambda(T), integral of lambda, d lambda(T)/d lam0,
    ok, sliding phases). stats[0] += time sticking, stats[2] += events. ok is False if the events did
    not advance (more than 10000 in the period). The sliding phases are written to ``seg`` (rows
    [t start, t end, sigma, lambda at the start, N at the start, 1 if it starts at an event]) while
    they fit; the count returned may exceed its rows (then they are not all there).

    A slip reaching zero within the period sticks where |alpha| <= mu_arrive n: ``mus`` for an
    exactly collinear motion (the slip passes exactly through zero, where static friction holds);
    ``mu`` for the nearly-collinear expansion (the slip swings past zero with its small transverse
    part and never reaches it, so a part only comes to rest while kinetic friction decelerates it:
    with mu_static > mu the collinear limit is not the limit of nearly-collinear motions)."""
    al, dal, lv, Lv, n, dn, N, M = eval_line(c1, 0.0)
    t = 0.0
    lam = lam0
    dP = 1.0
    integ = 0.0
    sig = 1.0
    F0 = lam0 - lv
    stick = False
    nseg = 0
    from_event = 0.0
    if abs(F0) <= zero_tol:
        from_event = 1.0
        lam = lv
        if can_stick and al * al <= mus * mus * n * n:
            stick = True
            dP = 0.0
        else:
            sig = -1.0 if al > 0.0 else 1.0
    else:
        sig = 1.0 if F0 > 0.0 else -1.0
    for _ in range(10000):
        if stick:
            tb = first_event(c1, 1, t, T, dt, 0.0, 0.0, mu, mus, 0.0, 0.0)
            te = T if tb < 0.0 else tb
            al, dal, lv, Lv1, n, dn, N, M = eval_line(c1, te)
            Lv0 = eval_line(c1, t)[3]
            integ += Lv1 - Lv0
            stats[0] += te - t
            t = te
            lam = lv
            if tb < 0.0:
                break
            stick = False
            sig = -1.0 if al > 0.0 else 1.0
            stats[2] += 1
        else:
            N0 = eval_line(c1, t)[6]
            M0 = eval_line(c1, t)[7]
            tc = first_event(c1, 0, t, T, dt, lam, sig, mu, mus, N0, zero_tol)
            te = T if tc < 0.0 else tc
            al, dal, lv, Lv, n, dn, N, M = eval_line(c1, te)
            integ += lam * (te - t) - sig * mu * (M - M0 - N0 * (te - t))
            if nseg < seg.shape[0]:
                seg[nseg, 0] = t
                seg[nseg, 1] = te
                seg[nseg, 2] = sig
                seg[nseg, 3] = lam
                seg[nseg, 4] = N0
                seg[nseg, 5] = from_event
            nseg += 1
            from_event = 1.0
            if tc < 0.0:
                lam = lam - sig * mu * (N - N0)
                t = T
                break
            t = te
            lam = lv
            stats[2] += 1
            if can_stick and al * al <= mu_arrive * mu_arrive * n * n:
                stick = True
                dP = 0.0
            else:
                dP *= (al - sig * mu * n) / (al + sig * mu * n)
                sig = -1.0 if al > 0.0 else 1.0
        if t >= T:
            return lam, integ, dP, True, nseg
    return lam, integ, dP, t >= T, nseg


@njit(cache=True, error_model="numpy")
def line_solve(c1, mu, mus, can_stick, T, lam0, dt, zero_tol, tol, max_periods, stats, seg, mu_arrive):
    """Newton on the one-period map. Returns (status, average lambda, lambda at the cycle start,
    periods used, sliding phases of the last period, written to ``seg`` as by :func:`line_period`,
    which also says what ``mu_arrive`` is); stats[0] ends as the sticking time of the last period."""
    best = 1e300
    for it in range(max_periods):
        stats[0] = 0.0
        lamT, integ, dP, ok, nseg = line_period(c1, mu, mus, can_stick, T, lam0, dt, zero_tol, stats, seg,
                                                mu_arrive)
        if not ok:
            return STEP_LIMIT, 0.0, lam0, it + 1, nseg
        r = lamT - lam0
        if abs(r) <= tol * (1.0 - min(dP, 0.95)):  # lam0 is within |r| / (1 - dP) of the cycle
            return OK, integ / T, lam0, it + 1, nseg
        # Newton while it makes progress; plain iteration otherwise (the map contracts).
        lam0 = lam0 + r / (1.0 - dP) if abs(r) < best and dP < 0.999 else lamT
        best = min(best, abs(r))
    return NOT_CONVERGED, 0.0, lam0, max_periods, 0


# ------------------------------------------------------------------ nearly collinear: first order


@njit(cache=True, error_model="numpy")
def _eval_perp(c1, t):
    """(lambda_v, n, N, a_perp, v_perp) at t."""
    lv = 0.0
    n = G
    N = G * t
    ap = 0.0
    vp = 0.0
    for r in range(c1.shape[0]):
        w = c1[r, 0]
        s = math.sin(w * t)
        c = math.cos(w * t)
        lv += c1[r, 3] * s + c1[r, 4] * c
        n += c1[r, 7] * s + c1[r, 8] * c
        N += c1[r, 9] * s + c1[r, 10] * c
        ap += c1[r, 13] * s + c1[r, 14] * c
        vp += c1[r, 15] * s + c1[r, 16] * c
    return lv, n, N, ap, vp


@njit(cache=True, error_model="numpy")
def _perp_phase(c1, mu, ta, tb, sig, lam_a, N_a, nodes, span, t_at):
    """First-order transverse slip over one sliding phase from an event at ta to one at tb.

    w_perp' = -a_perp - mu n w_perp / s with s = |lambda - lambda_v| the collinear slip (zero at
    both ends): its coefficient is singular there, and the only solution that stays bounded starts
    from w_perp = 0 at ta. In xi with t = tm + hh tanh(xi), |xi| <= span, the coefficient
    (dt/dxi) mu n / s stays bounded; exponential trapezoid steps on ``nodes`` intervals and on half
    as many, combined by Richardson extrapolation. Returns (integral of w_perp over the phase,
    w_perp at t_at if ta < t_at < tb, else 0)."""
    tm = 0.5 * (ta + tb)
    hh = 0.5 * (tb - ta)
    d = 2.0 * span / nodes
    w1 = 0.0
    w2 = 0.0
    i1 = 0.0
    i2 = 0.0
    w_at = 0.0
    kp = 0.0
    fp = 0.0
    gp = 0.0
    wp = 0.0
    tp = ta
    k2 = 0.0
    f2 = 0.0
    g2 = 0.0
    for i in range(nodes + 1):
        th = math.tanh(-span + i * d)
        t = tm + hh * th
        dtd = hh * (1.0 - th) * (1.0 + th)
        lv, n, N, ap, _ = _eval_perp(c1, t)
        s = sig * (lam_a - sig * mu * (N - N_a) - lv)
        k = dtd * mu * n / s if s > 0.0 else 1e300
        f = -dtd * ap
        if i == 0:
            # The bounded solution near the start: w_perp = -a_perp tau / (1 + mu n tau / s).
            tau = hh * (1.0 + th)
            w1 = -ap * tau / (1.0 + (mu * n * tau / s if s > 0.0 else 1e300))
            w2 = w1
        else:
            e = math.exp(-0.5 * d * (kp + k))
            w1 = w1 * e + 0.5 * d * (fp * e + f)
            i1 += 0.5 * d * (wp * gp + w1 * dtd)
            if i % 2 == 0:
                e2 = math.exp(-d * (k2 + k))
                wo = w2
                w2 = w2 * e2 + d * (f2 * e2 + f)
                i2 += d * (wo * g2 + w2 * dtd)
            if tp <= t_at < t:
                w_at = wp + (w1 - wp) * (t_at - tp) / (t - tp)
        if i % 2 == 0:
            k2 = k
            f2 = f
            g2 = dtd
        kp = k
        fp = f
        gp = dtd
        wp = w1
        tp = t
    return (4.0 * i1 - i2) / 3.0, w_at


@njit(cache=True, error_model="numpy")
def line_perp(c1, mu, T, seg, nseg, nodes, span):
    """First-order transverse part of a nearly-collinear limit cycle whose collinear part (along e)
    :func:`line_solve` found, with the sliding phases ``seg[:nseg]`` of its converged period: returns
    (ok, average transverse velocity, transverse velocity at t = 0). Every sliding phase starts with
    w_perp = 0 at its event (the bounded solution, :func:`_perp_phase`); sticking holds w_perp = 0.
    A phase running through the cycle start (t = 0 inside it) is integrated whole, from its event in
    the previous period. Not ok (use the stepped path) without an event in the period or with more
    phases than ``seg`` holds."""
    vp0 = _eval_perp(c1, 0.0)[4]
    if nseg > seg.shape[0]:
        return False, 0.0, 0.0
    if nseg == 0:
        return True, 0.0, vp0  # sticking all the time
    total = 0.0
    w0 = 0.0
    first = 0
    if seg[0, 5] == 0.0:
        # The cycle starts while sliding: that phase began at the period's last event.
        last = nseg - 1
        if last == 0 or seg[last, 1] < T:
            return False, 0.0, 0.0  # sliding all period long (or no event before T)
        integ, w0 = _perp_phase(c1, mu, seg[last, 0], seg[0, 1] + T, seg[last, 2], seg[last, 3], seg[last, 4],
                                nodes, span, T)
        total += integ
        first = 1
        nseg = last
    for j in range(first, nseg):
        integ, _ = _perp_phase(c1, mu, seg[j, 0], seg[j, 1], seg[j, 2], seg[j, 3], seg[j, 4], nodes, span, -1.0)
        total += integ
    return True, total / T, w0 + vp0

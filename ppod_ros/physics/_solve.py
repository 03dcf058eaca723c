"""The asymptotic solver's compiled driver: per configuration checks, the fixed point of the
one-period map, and the parallel loop over configurations.

For each configuration (in parallel over chunks of configurations; inside a chunk the previous
configuration's limit cycle is the next one's starting guess when ``warm`` is on):

1. checks that need no integration: contact loss (min over the cycle of g + a_n <= 0: flagged,
   never integrated), the velocity scale for tolerances, and whether sticking is provably
   impossible (a sampled lower bound plus a Lipschitz bound: if sticking cannot happen anywhere
   in the cycle, its logic is skipped);
2. point parts whose a_h is collinear: the closed form (``_closed_form.py``);
3. otherwise the fixed point x* = P(x*) of the one-period map P (x: velocity or twist at the
   cycle start), by Anderson acceleration of the iteration (depth 0: plain iteration; the map
   contracts), each period integrated by ``_advance.advance``. Converged when |P(x) - x| is below
   the fixed-point tolerance; the cycle average is that period's integral / T.
"""

from __future__ import annotations

import math

import numpy as np

from ppod_ros.physics._advance import advance, point_init, point_speed_limits, rigid_init, zero_tolerance
from ppod_ros.physics._closed_form import line_perp, line_solve, line_table, principal_direction
from ppod_ros.physics._contact import gauss_solve, point_plate, rigid_geometry, stick_forces
from ppod_ros.physics._jit import njit, prange
from ppod_ros.physics._layout import (
    AX_SIZE,
    CONTACT_LOST,
    NOT_CONVERGED,
    OK,
    PP_CANSTICK,
    PP_MU,
    PP_MUS,
    PP_VSCALE,
    PP_X,
    PP_Y,
    RP_CANSTICK,
    RP_MUS,
    RP_R,
    RP_TH,
    RP_VSCALE,
    RP_WSCALE,
    RP_X,
    RP_Y,
    RP_ZTOL,
    S_ATOL_V,
    S_ATOL_W,
    S_CAPTURE,
    S_CHUNK,
    S_CLOSED_FORM,
    S_DEPTH,
    S_FP_ATOL_V,
    S_FP_ATOL_W,
    S_FP_RTOL,
    S_LONG,
    S_MAX_PERIODS,
    S_MAX_STEPS,
    S_NSCAN,
    S_RTOL,
    S_SKIP_STICK,
    S_STARTS,
    S_WARM,
    S_ZERO_RTOL,
    STARTS_DISAGREE,
    W_H,
    W_N,
    W_S,
    W_SIZE,
    W_U,
)
from ppod_ros.physics.plate import min_normal_accel, plate_eval, point_velocity_scale

#: A neighbour's (or a previous call's) contraction rate times this is the first period's rate
#: estimate; never below RATE_PRIOR_MIN (a map that contracted to nothing there may not here).
RATE_PRIOR_SAFETY = 2.0
RATE_PRIOR_MIN = 0.1
#: Point parts whose a_h is collinear up to this fraction of its energy start the integrated
#: fixed point from the closed form along the principal direction (the nearly-collinear case).
NEAR_COLLINEAR_ENERGY = 1e-2
#: Point parts whose energy fraction of a_h across the principal direction is below this times
#: ``fixed_point_rtol`` take the first-order expansion about the closed form
#: (``_closed_form.line_perp``) instead of the stepped path. Its error is of second order in the
#: transverse component: about 2 x that fraction x the velocity scale (measured against the
#: fixed-step reference on LineSinkX with a transverse a_y of 0.1 % to 3 %), so within the
#: fixed-point tolerance below the threshold.
NEAR_PERTURB_PER_FP_RTOL = 0.5
#: ``line_perp``: intervals per sliding phase, the half-width of its tanh map, and the most sliding
#: phases per period it handles (more: the stepped path).
PERTURB_NODES = 32
PERTURB_SPAN = 6.5
PERTURB_MAX_PHASES = 32

#: Warm starts along a chunk: the next limit-cycle start is extrapolated from up to this many
#: converged neighbours on an evenly spaced line (a grid row), by the polynomial through them
#: (weights per number of points, newest first; one point: the neighbour's start itself). Cubic
#: extrapolation lands within about 0.3 fixed-point tolerances of Sink's cycle start on a
#: 101 x 101 grid (linear: 16), so that one period, with the neighbour's rate prior, often proves
#: convergence.
EXTRAP_POINTS = 4
#: Scattered configurations (small chunks, off any evenly spaced line): the start is the nearest
#: converged configuration's of the chunk, moved along the plane through the three nearest when
#: their triangle is not too flat (the sine of its angle at the nearest above this), and the first
#: steps use that configuration's secant differences.
SCATTER_PLANE_SIN = 0.2
EXTRAP_WEIGHTS = np.array([[1.0, 0.0, 0.0, 0.0], [2.0, -1.0, 0.0, 0.0], [3.0, -3.0, 1.0, 0.0],
                           [4.0, -6.0, 4.0, -1.0]])

# ------------------------------------------------------------------ checks before integrating


@njit(cache=True, error_model="numpy")
def point_can_stick(mc, P, x, y, T, ns, W):
    """False only if mu_s n(t) < |a_h(t)| for every t (proved: sampled maximum + Lipschitz bound)."""
    mus = P[PP_MUS]
    ln = 0.0
    lax = 0.0
    lay = 0.0
    for r in range(mc.shape[0]):
        w = mc[r, 0]
        ln += w * math.hypot(mc[r, 3] + mc[r, 4] * y - mc[r, 5] * x, mc[r, 9] + mc[r, 10] * y - mc[r, 11] * x)
        lax += w * math.hypot(mc[r, 1] - mc[r, 6] * y, mc[r, 7] - mc[r, 12] * y)
        lay += w * math.hypot(mc[r, 2] + mc[r, 6] * x, mc[r, 8] + mc[r, 12] * x)
    lip = mus * ln + lax + lay
    dt = T / ns
    gmax = -1e300
    for i in range(ns):
        ahx, ahy, n, _, _ = point_plate(mc, P, i * dt, x, y, W)
        gmax = max(gmax, mus * n - math.hypot(ahx, ahy))
    return gmax + 0.5 * lip * dt >= 0.0


@njit(cache=True, error_model="numpy")
def rigid_can_stick(mc, P, sx, sy, T, ns, W):
    """False only if sum_i mu_s,i N_i(t) < |m A_stick(t)| for every t (a necessary condition for
    sticking), proved as in :func:`point_can_stick`; the normal forces are those of the stuck part."""
    for j in range(6):
        W[W_S + j] = 0.0
    stick_forces(P, sx, sy, W, W_S)
    n0 = W[W_N:W_N + 3].copy()
    ns_ = np.zeros(3)
    nc_ = np.zeros(3)
    lip = 0.0
    for r in range(mc.shape[0]):
        for j in range(6):
            W[W_S + j] = mc[r, 1 + j]
        fxs, fys, _, _ = stick_forces(P, sx, sy, W, W_S)
        for i in range(3):
            ns_[i] = W[W_N + i] - n0[i]
        for j in range(6):
            W[W_S + j] = mc[r, 7 + j]
        fxc, fyc, _, _ = stick_forces(P, sx, sy, W, W_S)
        for i in range(3):
            nc_[i] = W[W_N + i] - n0[i]
        acc = math.sqrt(fxs * fxs + fys * fys + fxc * fxc + fyc * fyc)
        for i in range(3):
            acc += P[RP_MUS + i] * math.hypot(ns_[i], nc_[i])
        lip += mc[r, 0] * acc
    dt = T / ns
    gmax = -1e300
    for k in range(ns):
        t = k * dt
        plate_eval(mc, t, W, W_S, W_U)  # acceleration into the scratch slot
        fx, fy, _, _ = stick_forces(P, sx, sy, W, W_S)
        cap = 0.0
        for i in range(3):
            cap += P[RP_MUS + i] * W[W_N + i]
        gmax = max(gmax, cap - math.hypot(fx, fy))
    return gmax + 0.5 * lip * dt >= 0.0


@njit(cache=True, error_model="numpy")
def rigid_scales(mc, P, sx, sy, W):
    """(velocity scale m/s, yaw-rate scale rad/s): bounds on the plate's twist at the configuration."""
    h = W[W_H]
    lpart = 0.0
    for i in range(3):
        lpart = max(lpart, math.hypot(P[RP_R + 3 * i], P[RP_R + 3 * i + 1]))
    lpart = max(lpart, 1e-6)
    vs = 0.0
    for r in range(mc.shape[0]):
        acc = 0.0
        for off in (13, 19):
            vx = mc[r, off] - mc[r, off + 5] * sy + h * mc[r, off + 4]
            vy = mc[r, off + 1] + mc[r, off + 5] * sx - h * mc[r, off + 3]
            acc += vx * vx + vy * vy
        vs += math.sqrt(acc) + lpart * math.hypot(mc[r, 18], mc[r, 24])
    return vs, vs / lpart


# ------------------------------------------------------------------ fixed point of the period map


@njit(cache=True, error_model="numpy")
def fixed_point(kind, mc, P, x0, T, h, A, B, C, E, E3, S, K, ytmp, ynew, ybest, W, sc, n, dim, tolv,
                zero_tol, vlim, wlim, out_v, out_x, stats, prior, CX, CF, carry):
    """Returns (status, periods, sticking fraction of the final period, step size).

    ``prior[0]`` is a prior estimate of the map's contraction rate (from a neighbouring
    configuration or a previous call; >= 1: none) used for the first period's convergence test,
    and ends as the rate estimated here (a prior for the next configuration).

    ``CX``, ``CF`` (rows ``carry[0]``, at most ``depth``) are secant differences (dx, dP(x) - dx)
    of the previous configuration's map, newest last: when present the first step is Anderson's
    with them (a quasi-Newton step with the neighbour's Jacobian) instead of the plain step. They
    end as the newest differences of this configuration's map (older ones kept while fewer)."""
    depth = int(S[S_DEPTH])
    maxp = int(S[S_MAX_PERIODS])
    max_steps = int(S[S_MAX_STEPS])
    aux = np.zeros(AX_SIZE)
    y = np.zeros(n)
    x = x0.copy()
    Xh = np.zeros((depth + 1, dim))
    Fh = np.zeros((depth + 1, dim))
    f = np.zeros(dim)
    q = 0
    prev = 1e300
    best = 1e300
    since = 0
    carried = False
    more = False
    for it in range(maxp):
        for j in range(n):
            y[j] = 0.0
        for j in range(dim):
            y[dim + j] = x[j]
        if kind == 0:
            point_init(mc, P, aux, 0.0, y, W, zero_tol)
        else:
            rigid_init(mc, P, aux, 0.0, y, W, S[S_CAPTURE])
        stats[0] = 0.0
        st, h = advance(kind, mc, P, aux, 0.0, T, y, h, T, A, B, C, E, E3, S, K, ytmp, ynew, ybest, W, sc, n,
                        max_steps, zero_tol, stats)
        if st != OK:
            return st, it + 1, 0.0, h
        res = 0.0
        for j in range(dim):
            f[j] = y[dim + j] - x[j]
            res = max(res, abs(f[j]) / tolv[j])
        # The period started at x is off the limit cycle by up to |f| / (1 - rate) for a map that
        # contracts by ``rate``, estimated from the last two residuals: so at least two periods
        # (a weakly contracting map, e.g. tiny friction or huge amplitudes, has small residuals far
        # from its fixed point).
        # A prior rate (from a neighbour or a previous call, with a safety factor) lets a good warm
        # start converge in one period.
        rate = min(0.999, res / prev) if it > 0 else min(1.0, max(RATE_PRIOR_SAFETY * prior[0], RATE_PRIOR_MIN))
        # Converged; or stalled just above the tolerance, at the period map's own noise (set by the
        # step tolerance): iterating on would not make the result any better.
        if res < best:
            best = res
            since = 0
        else:
            since += 1
        if rate < 1.0 and (res / (1.0 - rate) <= 1.0 or (since >= 3 and res <= 5.0)):
            if it > 0:
                prior[0] = _map_rate(Xh, Fh, q, dim, tolv, x, f)
            # The cycle start: a point part's period end P(x), closer to the fixed point than x by
            # the contraction (a better start for its neighbours' extrapolation); a rigid part's x.
            for j in range(dim):
                out_v[j] = y[j] / T
                out_x[j] = x[j] + f[j] if (kind == 0 and S[S_LONG] > 0.0) else x[j]
            return OK, it + 1, stats[0] / T, h
        if it > 0 and carry[0] >= 0.0 and depth > 0:
            # The newest secant pair of this map, for the next configuration's first step.
            nc = int(carry[0])
            if nc == depth:
                for a in range(depth - 1):
                    CX[a] = CX[a + 1]
                    CF[a] = CF[a + 1]
                nc -= 1
            for j in range(dim):
                CX[nc, j] = x[j] - Xh[q - 1, j]
                CF[nc, j] = f[j] - Fh[q - 1, j]
            carry[0] = nc + 1
        if res >= 4.0 * prev:
            q = 0  # diverging: restart the acceleration (plain step below)
            carried = False
        prev = res
        q = _push(Xh, Fh, q, depth, x, f)
        if it == 0:
            # Small chunks (scattered configurations, from cold): until Anderson has ``depth``
            # differences of its own, the carried ones with this map's own appended as they come
            # (the oldest carried dropped). Long chunks start close enough not to need it.
            carried = carry[0] >= 1.0 and depth > 0
            more = carried and S[S_LONG] <= 0.0
        if carried and (it == 0 or (more and it < depth)):
            _secant_step(CX, CF, int(carry[0]), dim, tolv, x, f)
        else:
            _anderson(Xh, Fh, q, dim, tolv, x)
        # The limit cycle stays within the plate's velocities (within vlim, wlim: point parts by
        # the theorem, rigid parts in practice). Far out the map only translates (the part
        # decelerates) and extrapolating it would wander: outside the bound take the plain step.
        if math.hypot(x[0], x[1]) > vlim or (dim == 3 and abs(x[2]) > wlim):
            for j in range(dim):
                x[j] = Xh[q - 1, j] + Fh[q - 1, j]
            q = 0
    return NOT_CONVERGED, maxp, 0.0, h


@njit(cache=True, error_model="numpy")
def _evenly_spaced(Pall, i, kind, back):
    """Whether configurations i - back, ..., i are evenly spaced on a line (to 1e-9 of the step)."""
    if i < back or back < 2:
        return False
    o = PP_X if kind == 0 else RP_X
    dim = 2 if kind == 0 else 3
    step = 0.0
    off = 0.0
    for k in range(i - back + 2, i + 1):
        for j in range(dim):
            d1 = Pall[k - 1, o + j] - Pall[k - 2, o + j]
            d2 = Pall[k, o + j] - Pall[k - 1, o + j]
            step = max(step, abs(d1))
            off = max(off, abs(d2 - d1))
    return step > 0.0 and off <= 1e-9 * step


@njit(cache=True, error_model="numpy")
def _scatter_start(Pall, out_status, out_x, lo, i, x0, pick):
    """Scattered point configurations: x0 <- the start of the nearest converged configuration of
    this chunk before ``i``, moved along the plane through the three nearest when they span one
    (not nearly collinear). Returns the nearest's index (-1: none); ``pick`` gets the three."""
    px = Pall[i, PP_X]
    py = Pall[i, PP_Y]
    dbest = np.full(3, 1e300)
    pick[0] = -1
    pick[1] = -1
    pick[2] = -1
    for k in range(lo, i):
        if out_status[k] != OK or math.isnan(out_x[k, 0]):
            continue
        d = math.hypot(Pall[k, PP_X] - px, Pall[k, PP_Y] - py)
        if d < dbest[2]:
            a = 2
            while a > 0 and d < dbest[a - 1]:
                dbest[a] = dbest[a - 1]
                pick[a] = pick[a - 1]
                a -= 1
            dbest[a] = d
            pick[a] = k
    k0 = pick[0]
    if k0 < 0:
        return -1
    x0[0] = out_x[k0, 0]
    x0[1] = out_x[k0, 1]
    if pick[2] < 0:
        return k0
    k1 = pick[1]
    k2 = pick[2]
    ax = Pall[k1, PP_X] - Pall[k0, PP_X]
    ay = Pall[k1, PP_Y] - Pall[k0, PP_Y]
    bx = Pall[k2, PP_X] - Pall[k0, PP_X]
    by = Pall[k2, PP_Y] - Pall[k0, PP_Y]
    det = ax * by - ay * bx
    # No plane through repeated or collinear configurations (det 0) or a flat triangle.
    if det == 0.0 or abs(det) < SCATTER_PLANE_SIN * math.hypot(ax, ay) * math.hypot(bx, by):
        return k0
    ex = px - Pall[k0, PP_X]
    ey = py - Pall[k0, PP_Y]
    # (ex, ey) = u (ax, ay) + w (bx, by)
    u = (ex * by - ey * bx) / det
    w = (ax * ey - ay * ex) / det
    for j in range(2):
        x0[j] += u * (out_x[k1, j] - out_x[k0, j]) + w * (out_x[k2, j] - out_x[k0, j])
    if not (math.isfinite(x0[0]) and math.isfinite(x0[1])):
        x0[0] = out_x[k0, 0]
        x0[1] = out_x[k0, 1]
    return k0


@njit(cache=True, error_model="numpy")
def _map_rate(Xh, Fh, q, dim, tolv, x, f):
    """The one-period map's contraction along its last step, |P(x) - P(x_prev)| / |x - x_prev|
    (tolerance-scaled max norms; 1 when there is no previous iterate). Not res / previous res,
    which Anderson acceleration makes far smaller than the map's own rate."""
    if q < 1:
        return 1.0
    num = 0.0
    den = 0.0
    for j in range(dim):
        num = max(num, abs(x[j] + f[j] - Xh[q - 1, j] - Fh[q - 1, j]) / tolv[j])
        den = max(den, abs(x[j] - Xh[q - 1, j]) / tolv[j])
    if den <= 0.0:
        return 1.0
    return min(1.0, num / den)


@njit(cache=True, error_model="numpy")
def _push(Xh, Fh, q, depth, x, f):
    if q == depth + 1:
        for i in range(depth):
            Xh[i] = Xh[i + 1]
            Fh[i] = Fh[i + 1]
        q = depth
    Xh[q] = x
    Fh[q] = f
    return q + 1


@njit(cache=True, error_model="numpy")
def _secant_gamma(CF, m, dim, tolv, f, g):
    """g <- gamma = argmin |f - dF gamma| over the m secant differences dF (rows of CF), components
    scaled by their tolerances, Tikhonov-regularised by 1e-10 of the Gram matrix's trace. False
    when the fit is singular."""
    G = np.zeros(m * m)
    for a in range(m):
        for b in range(m):
            acc = 0.0
            for j in range(dim):
                acc += CF[a, j] * CF[b, j] / (tolv[j] * tolv[j])
            G[a * m + b] = acc
        acc = 0.0
        for j in range(dim):
            acc += CF[a, j] * f[j] / (tolv[j] * tolv[j])
        g[a] = acc
    tr = 0.0
    for a in range(m):
        tr += G[a * m + a]
    for a in range(m):
        G[a * m + a] += 1e-10 * tr + 1e-300
    return gauss_solve(G, 0, g, 0, m) != 0.0


@njit(cache=True, error_model="numpy")
def _secant_correction(CX, CF, g, m, dim, tolv, f, corr):
    """corr <- (dX + dF) gamma. False for a wild extrapolation, a step f - corr over 1e4 plain steps
    f (keep the plain step then; large ones are legitimate: a map that barely contracts, rate 0.999
    say, has its fixed point 1000 residuals away)."""
    step = 0.0
    plain = 0.0
    for j in range(dim):
        c = 0.0
        for a in range(m):
            c += g[a] * (CX[a, j] + CF[a, j])
        corr[j] = c
        step = max(step, abs(f[j] - c) / tolv[j])
        plain = max(plain, abs(f[j]) / tolv[j])
    return step <= 1e4 * plain


@njit(cache=True, error_model="numpy")
def _secant_step(CX, CF, m, dim, tolv, x, f):
    """x <- x + f - (dX + dF) gamma over m given secant differences (:func:`_secant_gamma`,
    :func:`_secant_correction`); the plain step x + f when the fit is singular or the step wild."""
    g = np.zeros(m)
    corr = np.zeros(dim)
    if _secant_gamma(CF, m, dim, tolv, f, g) and _secant_correction(CX, CF, g, m, dim, tolv, f, corr):
        for j in range(dim):
            x[j] += f[j] - corr[j]
        return
    for j in range(dim):
        x[j] += f[j]


@njit(cache=True, error_model="numpy")
def _anderson(Xh, Fh, q, dim, tolv, x):
    """x <- x_k + f_k - (dX + dF) gamma, the secant step over the stored pairs' differences; with one
    stored pair this is the plain step x_k + f_k."""
    k = q - 1
    m = q - 1
    for j in range(dim):
        x[j] = Xh[k, j] + Fh[k, j]
    if m == 0:
        return
    CX = np.empty((m, dim))
    CF = np.empty((m, dim))
    for a in range(m):
        for j in range(dim):
            CX[a, j] = Xh[a + 1, j] - Xh[a, j]
            CF[a, j] = Fh[a + 1, j] - Fh[a, j]
    g = np.zeros(m)
    corr = np.zeros(dim)
    if _secant_gamma(CF, m, dim, tolv, Fh[k], g) and _secant_correction(CX, CF, g, m, dim, tolv, Fh[k], corr):
        for j in range(dim):
            x[j] -= corr[j]


# ------------------------------------------------------------------ all configurations


@njit(cache=True, error_model="numpy")
def solve_chunk(kind, mc, Pall, X0, has_x0, R0, SX0, SF0, SN0, T, kmax, A, B, C, E, E3, S, out_v, out_x,
                out_status, out_periods, out_stick, out_rate, out_sx, out_sf, out_sn, lo, hi):
    """Configurations ``lo .. hi - 1`` in order (with ``warm`` on, each starts from the previous
    one's limit cycle and contraction rate). ``R0`` holds prior contraction rates for rows with
    ``has_x0`` (>= 1: none); ``out_rate`` the rates estimated here (1: none, e.g. closed form).

    ``SX0``, ``SF0`` (N, depth, dim), ``SN0`` (N,): secant differences of a row's own period map
    from an earlier call (its first ``SN0`` rows; 0: none), used for the first step of a point part
    warm-started at that row instead of the previous configuration's; ``out_sx``, ``out_sf``,
    ``out_sn``: the differences of each row's own map as they end here (0 rows: none known)."""
    dim = 2 if kind == 0 else 3
    n = 2 * dim
    nscan = int(S[S_NSCAN]) * kmax
    K = np.zeros((B.shape[0] + 1, n))
    ytmp = np.zeros(n)
    ynew = np.zeros(n)
    ybest = np.zeros(n)
    W = np.zeros(W_SIZE)
    sc = np.zeros(n)
    tolv = np.zeros(dim)
    x0 = np.zeros(dim)
    vres = np.zeros(dim)
    xres = np.zeros(dim)
    stats = np.zeros(4)
    hist = np.zeros((EXTRAP_POINTS, dim))  # the last limit-cycle starts along the chunk, newest first
    prior = np.ones(1)
    depth = int(S[S_DEPTH])
    CX = np.zeros((max(depth, 1), dim))
    CF = np.zeros((max(depth, 1), dim))
    carry = np.zeros(1)
    seg = np.zeros((PERTURB_MAX_PHASES, 6))
    noseg = np.zeros((0, 6))
    nhist = 0  # consecutive converged configurations in hist
    lsx = np.zeros((hi - lo, max(depth, 1), dim))  # each converged row's secant differences
    lsf = np.zeros((hi - lo, max(depth, 1), dim))
    lsn = np.zeros(hi - lo, np.int64)
    pick = np.zeros(3, np.int64)
    hcf = np.zeros((EXTRAP_POINTS, dim))  # their closed-form starts (nearly collinear point parts)
    ncf = 0
    cfx = np.zeros(dim)
    last_ok = -2
    nb_rate = 1.0
    h = T / (8.0 * kmax)
    for i in range(lo, hi):
        P = Pall[i]
        for j in range(dim):
            out_v[i, j] = np.nan
            out_x[i, j] = np.nan
        out_stick[i] = np.nan
        out_periods[i] = 0
        out_rate[i] = 1.0
        out_sn[i] = 0
        if kind == 0:
            px = P[PP_X]
            py = P[PP_Y]
        else:
            px = P[RP_X]
            py = P[RP_Y]
        if min_normal_accel(mc, px, py, T, 4 * nscan) <= 0.0:
            out_status[i] = CONTACT_LOST
            continue
        if kind == 0:
            vscale = point_velocity_scale(mc, px, py)
            wscale = 0.0
            can = True if S[S_SKIP_STICK] <= 0.0 else point_can_stick(mc, P, px, py, T, nscan, W)
            P[PP_CANSTICK] = 1.0 if can else 0.0
            P[PP_VSCALE] = vscale
        else:
            rigid_geometry(P, P[RP_TH], W)
            vscale, wscale = rigid_scales(mc, P, px, py, W)
            can = True if S[S_SKIP_STICK] <= 0.0 else rigid_can_stick(mc, P, px, py, T, nscan, W)
            P[RP_CANSTICK] = 1.0 if can else 0.0
            P[RP_VSCALE] = vscale
            P[RP_WSCALE] = wscale
        for j in range(dim):
            sc[j] = 0.0
            if kind == 1 and j == 2:
                sc[dim + j] = S[S_RTOL] * wscale + S[S_ATOL_W]
                tolv[j] = S[S_FP_RTOL] * wscale + S[S_FP_ATOL_W]
            else:
                sc[dim + j] = S[S_RTOL] * vscale + S[S_ATOL_V]
                tolv[j] = S[S_FP_RTOL] * vscale + S[S_FP_ATOL_V]
        zero_tol = zero_tolerance(S, vscale)
        if kind == 1:
            P[RP_ZTOL] = max(zero_tol, 100.0 * sc[3])
        else:
            point_speed_limits(P, S, sc[2], T)
        # Starting guess: the caller's, else the neighbour's limit cycle (extrapolated by the
        # polynomial through the last converged neighbours while they and this configuration are
        # evenly spaced, as along a grid row: two points, in long chunks up to four), else rest.
        # (Point parts only: a rigid part's limit cycle can change quickly near unstable lines.)
        have_warm = nhist > 0
        npts = 1 if have_warm else 0
        long = S[S_LONG] > 0.0
        if kind == 0 and have_warm and last_ok == i - 1:
            while npts < (nhist if long else min(nhist, 2)) and _evenly_spaced(Pall, i, kind, npts + 1):
                npts += 1
        for j in range(dim):
            if has_x0[i]:
                x0[j] = X0[i, j]
            else:
                x0[j] = 0.0
                for k in range(npts):
                    x0[j] += EXTRAP_WEIGHTS[npts - 1, k] * hist[k, j]
        near_k = -1
        if kind == 0 and not long and not has_x0[i] and npts < 2 and S[S_WARM] > 0.0:
            near_k = _scatter_start(Pall, out_status, out_x, lo, i, x0, pick)
        # The rate prior comes with a warm start from an earlier call (solve_fields), and from the
        # neighbour only in long chunks (large grids): in small calls it would make the number of
        # periods, hence the result within the tolerance, jump as the motion changes slightly
        # (finite-difference design Jacobians).
        if kind == 0 and has_x0[i]:
            prior[0] = R0[i]
        elif long and kind == 0 and have_warm and last_ok == i - 1 and S[S_WARM] > 0.0:
            prior[0] = nb_rate
        else:
            prior[0] = 1.0
        # Far outside the hull the one-period map only decelerates the part towards it; start
        # at 4 velocity scales instead (the limit cycle is unique for point parts).
        lim = 4.0 * vscale + 1e-12
        sp = math.hypot(x0[0], x0[1])
        if sp > lim:
            x0[0] *= lim / sp
            x0[1] *= lim / sp
        if kind == 1 and abs(x0[2]) > 4.0 * wscale + 1e-12:
            x0[2] = math.copysign(4.0 * wscale, x0[2])
        st = OK
        near = 1.0
        perturbed = False
        if kind == 0 and S[S_CLOSED_FORM] > 0.0:
            lin, ex, ey, near = principal_direction(mc, px, py)
        else:
            lin, ex, ey = False, 1.0, 0.0
        if not lin and near <= NEAR_PERTURB_PER_FP_RTOL * S[S_FP_RTOL]:
            # Nearly collinear: the closed form along e plus the first-order transverse slip.
            c1 = line_table(mc, px, py, ex, ey)
            st, lam_avg, lam_start, periods, nseg = line_solve(
                c1, P[PP_MU], P[PP_MUS], P[PP_CANSTICK] > 0.0, T, ex * x0[0] + ey * x0[1], T / nscan,
                S[S_ZERO_RTOL] * vscale * 1e-3 + 1e-300, tolv[0], int(S[S_MAX_PERIODS]), stats, seg, P[PP_MU])
            if st == OK:
                frac = stats[0] / T
                ok, perp_avg, perp_start = line_perp(c1, P[PP_MU], T, seg, nseg, PERTURB_NODES, PERTURB_SPAN)
                if ok:
                    lin = True
                    perturbed = True
                    vres[0] = lam_avg * ex - perp_avg * ey
                    vres[1] = lam_avg * ey + perp_avg * ex
                    xres[0] = lam_start * ex - perp_start * ey
                    xres[1] = lam_start * ey + perp_start * ex
            st = OK
        has_cf = False
        if not lin and near <= NEAR_COLLINEAR_ENERGY and not has_x0[i]:
            # Nearly collinear: the closed form along the principal direction is a close start. In
            # long chunks, along an evenly spaced line, the start is that closed form plus the
            # neighbours' departures from theirs, extrapolated (smoother than the starts
            # themselves); the closed form alone misses the transverse slip by many tolerances.
            c1 = line_table(mc, px, py, ex, ey)
            st0, _, lam_start, _, _ = line_solve(
                c1, P[PP_MU], P[PP_MUS], P[PP_CANSTICK] > 0.0, T, ex * x0[0] + ey * x0[1], T / nscan,
                S[S_ZERO_RTOL] * vscale * 1e-3 + 1e-300, tolv[0], int(S[S_MAX_PERIODS]), stats, noseg,
                P[PP_MU])
            if st0 == OK:
                has_cf = True
                cfx[0] = lam_start * ex
                cfx[1] = lam_start * ey
                if not (long and npts >= 2):
                    x0[0] = cfx[0]
                    x0[1] = cfx[1]
                elif ncf >= npts:
                    for j in range(dim):
                        x0[j] = cfx[j]
                        for k in range(npts):
                            x0[j] += EXTRAP_WEIGHTS[npts - 1, k] * (hist[k, j] - hcf[k, j])
        if lin and not perturbed:
            c1 = line_table(mc, px, py, ex, ey)
            st, lam_avg, lam_start, periods, _ = line_solve(
                c1, P[PP_MU], P[PP_MUS], P[PP_CANSTICK] > 0.0, T, ex * x0[0] + ey * x0[1], T / nscan,
                S[S_ZERO_RTOL] * vscale * 1e-3 + 1e-300, tolv[0], int(S[S_MAX_PERIODS]), stats, noseg,
                P[PP_MUS])
            vres[0] = lam_avg * ex
            vres[1] = lam_avg * ey
            xres[0] = lam_start * ex
            xres[1] = lam_start * ey
            frac = stats[0] / T
        elif not lin:
            # Point parts started from the neighbour's limit cycle take their first step with its
            # secant differences (a quasi-Newton step); otherwise none are used, but they are kept.
            if not (kind == 0 and (has_x0[i] or (have_warm and last_ok == i - 1)) and S[S_WARM] > 0.0):
                carry[0] = -1.0 if not (kind == 0 and S[S_WARM] > 0.0) else 0.0
            # A row warm-started from an earlier call takes the secant differences of its own map
            # there (nearly its Jacobian now: the motion changed little), not its neighbour's.
            if near_k >= 0 and depth > 0:
                # The nearest's own secant differences (none: the plain first step).
                nl = lsn[near_k - lo]
                for a in range(nl):
                    for j in range(dim):
                        CX[a, j] = lsx[near_k - lo, a, j]
                        CF[a, j] = lsf[near_k - lo, a, j]
                carry[0] = nl
            own = kind == 0 and has_x0[i] and SN0[i] > 0 and S[S_WARM] > 0.0 and depth > 0 and SX0.shape[1] > 0
            if own:
                nown = min(int(SN0[i]), depth, SX0.shape[1])
                for a in range(nown):
                    for j in range(dim):
                        CX[a, j] = SX0[i, a, j]
                        CF[a, j] = SF0[i, a, j]
                carry[0] = nown
            vlim = (1.0 if kind == 0 else 2.0) * vscale + 1e-12
            wlim = 2.0 * wscale + 1e-12
            st, periods, frac, h = fixed_point(kind, mc, P, x0, T, h, A, B, C, E, E3, S, K, ytmp, ynew,
                                               ybest, W, sc, n, dim, tolv, zero_tol, vlim, wlim, vres, xres,
                                               stats, prior, CX, CF, carry)
            if st == OK and kind == 0 and carry[0] >= 1.0:
                # This row's own differences: all of them if it started with its own, else the
                # ones its own periods added (one per period after the second).
                nc = int(carry[0])
                keep = min(nc if own else max(periods - 2, 0), nc, out_sx.shape[1])
                for a in range(keep):
                    for j in range(dim):
                        out_sx[i, a, j] = CX[nc - keep + a, j]
                        out_sf[i, a, j] = CF[nc - keep + a, j]
                out_sn[i] = keep
            if st == OK and kind == 0 and carry[0] >= 1.0 and depth > 0:
                nl = int(carry[0])
                for a in range(nl):
                    for j in range(dim):
                        lsx[i - lo, a, j] = CX[a, j]
                        lsf[i - lo, a, j] = CF[a, j]
                lsn[i - lo] = nl
            if st != OK:
                carry[0] = 0.0
            if st == OK and kind == 1 and S[S_STARTS] > 1.5:
                st, extra = _other_starts(mc, P, T, h, A, B, C, E, E3, S, K, ytmp, ynew, ybest, W, sc,
                                          tolv, zero_tol, vres, vscale, wscale, stats)
                periods += extra
            out_rate[i] = prior[0]
        # The next configuration's rate prior: this one's, where it was integrated and converged.
        nb_rate = out_rate[i] if st == OK else 1.0
        out_status[i] = st
        out_periods[i] = periods
        if st == OK:
            for j in range(dim):
                out_v[i, j] = vres[j]
                out_x[i, j] = xres[j]
            out_stick[i] = frac
            if S[S_WARM] > 0.0:
                nhist = min(nhist + 1, EXTRAP_POINTS) if last_ok == i - 1 else 1
                for k in range(EXTRAP_POINTS - 1, 0, -1):
                    for j in range(dim):
                        hist[k, j] = hist[k - 1, j]
                        hcf[k, j] = hcf[k - 1, j]
                for j in range(dim):
                    hist[0, j] = xres[j]
                    hcf[0, j] = cfx[j] if has_cf else 0.0
                # How many of the newest in hist have their closed-form start in hcf.
                ncf = (min(ncf + 1, EXTRAP_POINTS) if nhist > 1 else 1) if has_cf else 0
                last_ok = i


@njit(cache=True, error_model="numpy", parallel=True)
def solve_motions(kind, MC, rows, Pall, X0, has_x0, R0, SX0, SF0, SN0, Ts, kmaxs, A, B, C, E, E3, S, out_v,
                  out_x, out_status, out_periods, out_stick, out_rate, out_sx, out_sf, out_sn):
    """M motions x N configurations, in parallel over (motion, chunk of configurations).

    MC (M, R, TABLE_COLS): motion tables, motion m using its first ``rows[m]`` rows; Pall (M, N, size):
    parameter rows (written to: one copy per motion); X0, out_v, out_x (M, N, dim); has_x0, R0,
    out_* (M, N); SX0, SF0, out_sx, out_sf (M, N, depth, dim) and SN0, out_sn (M, N): each row's own
    secant differences from an earlier call and as they end (:func:`solve_chunk`); Ts, kmaxs (M,):
    periods and highest harmonics.
    """
    M = Pall.shape[0]
    N = Pall.shape[1]
    chunk = max(1, int(S[S_CHUNK]))
    nch = (N + chunk - 1) // chunk
    for job in prange(M * nch):
        m = job // nch
        ci = job - m * nch
        solve_chunk(kind, MC[m, :rows[m]], Pall[m], X0[m], has_x0[m], R0[m], SX0[m], SF0[m], SN0[m], Ts[m],
                    kmaxs[m], A, B, C, E, E3, S, out_v[m], out_x[m], out_status[m], out_periods[m],
                    out_stick[m], out_rate[m], out_sx[m], out_sf[m], out_sn[m], ci * chunk,
                    min(N, (ci + 1) * chunk))


@njit(cache=True, error_model="numpy")
def solve_motions_serial(kind, MC, rows, Pall, X0, has_x0, R0, SX0, SF0, SN0, Ts, kmaxs, A, B, C, E, E3, S,
                         out_v, out_x, out_status, out_periods, out_stick, out_rate, out_sx, out_sf, out_sn):
    """:func:`solve_motions` on the calling thread only (same chunks, same results): no thread
    wake-ups, so no stall when the other core is busy."""
    M = Pall.shape[0]
    N = Pall.shape[1]
    chunk = max(1, int(S[S_CHUNK]))
    nch = (N + chunk - 1) // chunk
    for job in range(M * nch):
        m = job // nch
        ci = job - m * nch
        solve_chunk(kind, MC[m, :rows[m]], Pall[m], X0[m], has_x0[m], R0[m], SX0[m], SF0[m], SN0[m], Ts[m],
                    kmaxs[m], A, B, C, E, E3, S, out_v[m], out_x[m], out_status[m], out_periods[m],
                    out_stick[m], out_rate[m], out_sx[m], out_sf[m], out_sn[m], ci * chunk,
                    min(N, (ci + 1) * chunk))


@njit(cache=True, error_model="numpy")
def _other_starts(mc, P, T, h, A, B, C, E, E3, S, K, ytmp, ynew, ybest, W, sc, tolv, zero_tol, vres,
                  vscale, wscale, stats):
    """Rigid parts: solve again from other initial twists; disagreement is reported, not hidden."""
    nst = int(S[S_STARTS])
    nocx = np.zeros((1, 3))
    nocarry = -np.ones(1)
    x0 = np.zeros(3)
    v2 = np.zeros(3)
    x2 = np.zeros(3)
    total = 0
    for s in range(1, nst):
        ang = 2.0 * math.pi * s / nst
        x0[0] = vscale * math.cos(ang)
        x0[1] = vscale * math.sin(ang)
        x0[2] = wscale if s % 2 else -wscale
        st, periods, _, h = fixed_point(1, mc, P, x0, T, h, A, B, C, E, E3, S, K, ytmp, ynew, ybest, W, sc, 6,
                                        3, tolv, zero_tol, 2.0 * vscale + 1e-12, 2.0 * wscale + 1e-12, v2, x2,
                                        stats, np.ones(1), nocx, nocx, nocarry)
        total += periods
        if st != OK:
            return st, total
        for j in range(3):
            if abs(v2[j] - vres[j]) > 10.0 * tolv[j]:
                return STARTS_DISAGREE, total
    return OK, total

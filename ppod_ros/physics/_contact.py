"""Contact mechanics of point and rigid parts (PHYSICS.md), as compiled right-hand sides.

State vectors: point ``y = (qx, qy, sx, sy)``, rigid ``y = (qx, qy, qtheta, Vx, Vy, thetadot)``,
where ``q`` is the configuration when it evolves (full dynamics) and the running integral of the
velocity when it is held fixed (asymptotic solver: the cycle average is q(T) / T).

Point part, sliding: ``s' = -mu n(t) w/|w|`` with ``w = s - v_h``. Inside one integration step the
direction is continued: w's component against ``d`` (the direction at the step's start) is
reflected, which changes nothing while ``w . d >= 0`` and continues a motion through w = 0 along d
smoothly, and is continuous everywhere; so a step that crosses a zero of w, or swings w round by
more than 90 degrees, can be located as an event (``w . d = 0``, see ``_advance.py``) and the steps
up to it stay accurate. Sticking: ``s' = a_h`` (the part moves with the plate).

Rigid part, sliding: the 4x4 system in (thetadot', N1, N2, N3) built from the Newton-Euler
equations with the friction directions substituted (the translational rows are explicit), solved
as a whole; friction uses the regularised Coulomb law ``f = -mu N u / max(|u|, eps)``. Sticking
(all three contacts): the twist follows the plate's; :func:`stick_ratio` decides whether the
needed tangential forces fit in the friction cones (a small second-order cone program).
"""

from __future__ import annotations

import math

import numpy as np

from ppod_ros.physics._jit import njit
from ppod_ros.physics._layout import (
    AX_BAND,
    AX_DEPART,
    AX_DX,
    AX_DY,
    AX_MODE,
    AX_RD,
    CONTACT_LOST,
    FRICTIONAL_SINGULARITY,
    OK,
    PP_EVOLVE,
    PP_KAPPA,
    PP_KAPPA_DEPART,
    PP_LAG_MAX,
    PP_MU,
    PP_X,
    PP_Y,
    RP_DET0,
    RP_EPS,
    RP_EVOLVE,
    RP_I,
    RP_MASS,
    RP_MU,
    RP_MUS,
    RP_R,
    RP_TH,
    RP_X,
    RP_Y,
    RP_ZTOL,
    STICK,
    W_B,
    W_E,
    W_H,
    W_IW,
    W_M,
    W_N,
    W_RX,
    W_RY,
    W_U,
    W_V,
)
from ppod_ros.physics.plate import G, plate_eval

# ================================================================ point part
# All work arrays are indexed by offset (see _layout): slicing numba arrays in hot loops costs
# reference counting. Stage derivatives go to K[s, :].


@njit(cache=True, error_model="numpy")
def accel_turn_rate(mc, t, x, y, ahx, ahy):
    """Rate (rad/s) at which the horizontal plate acceleration a_h = (ahx, ahy) at plate point (x, y)
    turns at time t: (a_h x a_h') / |a_h|^2, with a_h' from the harmonics' derivatives."""
    jx = 0.0
    jy = 0.0
    jz = 0.0
    for r in range(mc.shape[0]):
        om = mc[r, 0]
        s = math.sin(om * t)
        c = math.cos(om * t)
        jx += om * (mc[r, 1] * c - mc[r, 7] * s)
        jy += om * (mc[r, 2] * c - mc[r, 8] * s)
        jz += om * (mc[r, 6] * c - mc[r, 12] * s)
    jhx = jx - jz * y
    jhy = jy + jz * x
    a2 = ahx * ahx + ahy * ahy
    return (ahx * jhy - ahy * jhx) / a2 if a2 > 0.0 else 0.0


@njit(cache=True, error_model="numpy", inline="always")
def point_rhs(mc, P, aux, t, y, K, s, W):
    plate_eval(mc, t, W, W_U, W_V)
    if P[PP_EVOLVE] > 0.0:
        x = y[0]
        yy = y[1]
    else:
        x = P[PP_X]
        yy = P[PP_Y]
    K[s, 0] = y[2]
    K[s, 1] = y[3]
    n = G + W[W_U + 2] + W[W_U + 3] * yy - W[W_U + 4] * x
    if aux[AX_MODE] == STICK:
        K[s, 2] = W[W_U + 0] - W[W_U + 5] * yy
        K[s, 3] = W[W_U + 1] + W[W_U + 5] * x
    else:
        wx = y[2] - (W[W_V + 0] - W[W_V + 5] * yy)
        wy = y[3] - (W[W_V + 1] + W[W_V + 5] * x)
        nw = math.sqrt(wx * wx + wy * wy)
        ahx = W[W_U + 0] - W[W_U + 5] * yy
        ahy = W[W_U + 1] + W[W_U + 5] * x
        a = math.sqrt(ahx * ahx + ahy * ahy)
        f = P[PP_MU] * n
        if (nw <= P[PP_KAPPA] or (aux[AX_DEPART] > 0.0 and nw <= P[PP_KAPPA_DEPART])) and a >= f and a > 0.0:
            # Just leaving w = 0 (a break-away, or a reversal): the part slides away along -a_h.
            # Following w/|w| at speeds this small would take ever shorter steps (the direction
            # is singular at 0) for a change in velocity below kappa; after a departure from zero
            # (AX_DEPART) up to the larger PP_KAPPA_DEPART (_advance.KAPPA_DEPART_PER_STEP_TOL).
            # On the slow manifold of w/|w| the slip lags -a_h by -|w| psi' / (2 |a_h| - mu n) to
            # first order in |w| (psi': the turn rate of a_h): that is where w/|w| itself sits once
            # its fast relaxation (rate |a_h| / |w|) is over, so the hand-over to w/|w| starts no
            # stiff transient (docs/solver.md).
            ux = -ahx / a
            uy = -ahy / a
            lag = -nw * accel_turn_rate(mc, t, x, yy, ahx, ahy) / (2.0 * a - f)
            if lag > P[PP_LAG_MAX]:
                lag = P[PP_LAG_MAX]
            elif lag < -P[PP_LAG_MAX]:
                lag = -P[PP_LAG_MAX]
            cl = math.cos(lag)
            sl = math.sin(lag)
            K[s, 2] = -f * (cl * ux - sl * uy)
            K[s, 3] = -f * (sl * ux + cl * uy)
            return OK if n > 0.0 else CONTACT_LOST
        if nw > 0.0:
            # Continued direction: w with its component against d reflected (see the module doc).
            proj = wx * aux[AX_DX] + wy * aux[AX_DY]
            if proj < 0.0:
                wx -= 2.0 * proj * aux[AX_DX]
                wy -= 2.0 * proj * aux[AX_DY]
            ex = wx / nw
            ey = wy / nw
        else:
            ex = aux[AX_DX]
            ey = aux[AX_DY]
        K[s, 2] = -f * ex
        K[s, 3] = -f * ey
    return OK if n > 0.0 else CONTACT_LOST


@njit(cache=True, error_model="numpy", inline="always")
def point_plate(mc, P, t, x, y, W):
    """(a_hx, a_hy, n, v_hx, v_hy) at plate point (x, y) and time t."""
    plate_eval(mc, t, W, W_U, W_V)
    return (W[W_U + 0] - W[W_U + 5] * y, W[W_U + 1] + W[W_U + 5] * x,
            G + W[W_U + 2] + W[W_U + 3] * y - W[W_U + 4] * x,
            W[W_V + 0] - W[W_V + 5] * y, W[W_V + 1] + W[W_V + 5] * x)


# ================================================================ rigid part: geometry and solves


@njit(cache=True, error_model="numpy")
def rigid_geometry(P, th, W):
    """World-frame contact offsets rho (W_RX, W_RY), h (W_H) and inertia R I R^T (W_IW) at yaw th."""
    c = math.cos(th)
    s = math.sin(th)
    for i in range(3):
        rx = P[RP_R + 3 * i]
        ry = P[RP_R + 3 * i + 1]
        W[W_RX + i] = c * rx - s * ry
        W[W_RY + i] = s * rx + c * ry
    W[W_H] = -P[RP_R + 2]
    # I_w = R I R^T with R = [[c, -s, 0], [s, c, 0], [0, 0, 1]]: first T = R I (in W_M), then T R^T.
    for j in range(3):
        i0 = P[RP_I + j]
        i1 = P[RP_I + 3 + j]
        W[W_M + j] = c * i0 - s * i1
        W[W_M + 3 + j] = s * i0 + c * i1
        W[W_M + 6 + j] = P[RP_I + 6 + j]
    for a in range(3):
        W[W_IW + 3 * a] = c * W[W_M + 3 * a] - s * W[W_M + 3 * a + 1]
        W[W_IW + 3 * a + 1] = s * W[W_M + 3 * a] + c * W[W_M + 3 * a + 1]
        W[W_IW + 3 * a + 2] = W[W_M + 3 * a + 2]


@njit(cache=True, error_model="numpy", inline="always")
def geometry_for(P, y, W):
    """Refresh the geometry when the configuration evolves (it is set once per configuration when
    held fixed); returns the configuration (sx, sy, theta)."""
    if P[RP_EVOLVE] > 0.0:
        rigid_geometry(P, y[2], W)
        return y[0], y[1], y[2]
    return P[RP_X], P[RP_Y], P[RP_TH]


@njit(cache=True, error_model="numpy", inline="always")
def gauss_solve(M, mo, b, bo, n):
    """Solve M x = b in place (x replaces b) by elimination with partial pivoting; returns det(M).

    M is row-major n x n at offset mo (overwritten), b has n entries at offset bo. A zero pivot
    returns 0 (b is then undefined).
    """
    det = 1.0
    for k in range(n):
        p = k
        best = abs(M[mo + k * n + k])
        for i in range(k + 1, n):
            if abs(M[mo + i * n + k]) > best:
                best = abs(M[mo + i * n + k])
                p = i
        if best == 0.0:
            return 0.0
        if p != k:
            for j in range(n):
                tmp = M[mo + k * n + j]
                M[mo + k * n + j] = M[mo + p * n + j]
                M[mo + p * n + j] = tmp
            tmp = b[bo + k]
            b[bo + k] = b[bo + p]
            b[bo + p] = tmp
            det = -det
        piv = M[mo + k * n + k]
        det *= piv
        for i in range(k + 1, n):
            f = M[mo + i * n + k] / piv
            if f != 0.0:
                for j in range(k, n):
                    M[mo + i * n + j] -= f * M[mo + k * n + j]
                b[bo + i] -= f * b[bo + k]
    for k in range(n - 1, -1, -1):
        acc = b[bo + k]
        for j in range(k + 1, n):
            acc -= M[mo + k * n + j] * b[bo + j]
        b[bo + k] = acc / M[mo + k * n + k]
    return det


@njit(cache=True, error_model="numpy", inline="always")
def contact_velocities(sx, sy, Vx, Vy, wz, W):
    """Sliding velocities u_i of the three contacts into W[W_E + 2i], W[W_E + 2i + 1] (plate velocity
    from W_V, geometry from W); returns max |u_i|."""
    h = W[W_H]
    umax = 0.0
    for i in range(3):
        rx = W[W_RX + i]
        ry = W[W_RY + i]
        ux = Vx - h * W[W_V + 4] - wz * ry - (W[W_V + 0] - W[W_V + 5] * (sy + ry))
        uy = Vy + h * W[W_V + 3] + wz * rx - (W[W_V + 1] + W[W_V + 5] * (sx + rx))
        W[W_E + 2 * i] = ux
        W[W_E + 2 * i + 1] = uy
        umax = max(umax, math.sqrt(ux * ux + uy * uy))
    return umax


@njit(cache=True, error_model="numpy", inline="always")
def sliding_accelerations(P, aux, sx, sy, Vx, Vy, wz, W, K, s):
    """Twist rates (Ax, Ay, thetaddot) -> K[s, 3:6] while sliding; normal forces -> W[W_N:W_N+3].

    Friction per contact: Coulomb's -mu N u/|u|, continued through u = 0 like the point part's
    (u's component against d_i, the direction at the step's start, reflected; d_i itself at a zero),
    or, for a contact in the band (pivoting, or leaving a stuck state), the regularised
    -mu N u / eps.
    Returns a status: CONTACT_LOST if some N_i <= 0, FRICTIONAL_SINGULARITY if the system is
    singular or its determinant has the opposite sign of the frictionless one.
    """
    m = P[RP_MASS]
    eps = P[RP_EPS]
    h = W[W_H]
    contact_velocities(sx, sy, Vx, Vy, wz, W)
    for i in range(3):
        ux = W[W_E + 2 * i]
        uy = W[W_E + 2 * i + 1]
        if aux[AX_BAND + i] > 0.0:
            W[W_E + 2 * i] = ux / eps
            W[W_E + 2 * i + 1] = uy / eps
            continue
        dx = aux[AX_RD + 2 * i]
        dy = aux[AX_RD + 2 * i + 1]
        nu = math.sqrt(ux * ux + uy * uy)
        if nu > P[RP_ZTOL]:
            proj = ux * dx + uy * dy
            if proj < 0.0:
                ux -= 2.0 * proj * dx
                uy -= 2.0 * proj * dy
            W[W_E + 2 * i] = ux / nu
            W[W_E + 2 * i + 1] = uy / nu
        else:
            W[W_E + 2 * i] = dx
            W[W_E + 2 * i + 1] = dy
    W[W_M + 0] = 0.0
    W[W_M + 4] = -W[W_IW + 2]
    W[W_M + 8] = -W[W_IW + 5]
    W[W_M + 12] = -W[W_IW + 8]
    for i in range(3):
        mu = P[RP_MU + i]
        rx = W[W_RX + i]
        ry = W[W_RY + i]
        ex = W[W_E + 2 * i]
        ey = W[W_E + 2 * i + 1]
        W[W_M + 1 + i] = 1.0
        W[W_M + 5 + i] = ry - h * mu * ey
        W[W_M + 9 + i] = h * mu * ex - rx
        W[W_M + 13 + i] = mu * (ry * ex - rx * ey)
    u3 = W[W_U + 3]
    u4 = W[W_U + 4]
    W[W_B + 0] = m * (G + W[W_U + 2] + u3 * sy - u4 * sx)
    W[W_B + 1] = W[W_IW + 0] * u3 + W[W_IW + 1] * u4
    W[W_B + 2] = W[W_IW + 3] * u3 + W[W_IW + 4] * u4
    W[W_B + 3] = W[W_IW + 6] * u3 + W[W_IW + 7] * u4
    det = gauss_solve(W, W_M, W, W_B, 4)
    det0 = P[RP_DET0]
    if det * det0 <= 0.0 or abs(det) < 1e-9 * abs(det0):
        K[s, 3] = 0.0
        K[s, 4] = 0.0
        K[s, 5] = 0.0
        return FRICTIONAL_SINGULARITY
    ax = 0.0
    ay = 0.0
    status = OK
    for i in range(3):
        N = W[W_B + 1 + i]
        W[W_N + i] = N
        if N <= 0.0:
            status = CONTACT_LOST
        f = P[RP_MU + i] * N / m
        ax -= f * W[W_E + 2 * i]
        ay -= f * W[W_E + 2 * i + 1]
    K[s, 3] = ax
    K[s, 4] = ay
    K[s, 5] = W[W_B + 0]
    return status


@njit(cache=True, error_model="numpy")
def stick_forces(P, sx, sy, W, uo):
    """Normal forces of a stuck part into W[W_N:W_N+3], for plate acceleration W[uo:uo+6].

    Returns the required (m Ax, m Ay, tau_z) and the smallest normal force.
    """
    m = P[RP_MASS]
    h = W[W_H]
    u0, u1, u2, u3, u4, u5 = W[uo], W[uo + 1], W[uo + 2], W[uo + 3], W[uo + 4], W[uo + 5]
    ax = u0 - u5 * sy + h * u4
    ay = u1 + u5 * sx - h * u3
    tx = W[W_IW + 0] * u3 + W[W_IW + 1] * u4 + W[W_IW + 2] * u5
    ty = W[W_IW + 3] * u3 + W[W_IW + 4] * u4 + W[W_IW + 5] * u5
    tz = W[W_IW + 6] * u3 + W[W_IW + 7] * u4 + W[W_IW + 8] * u5
    for i in range(3):
        W[W_M + i] = 1.0
        W[W_M + 3 + i] = W[W_RY + i]
        W[W_M + 6 + i] = -W[W_RX + i]
    W[W_B + 0] = m * (G + u2 + u3 * sy - u4 * sx)
    W[W_B + 1] = tx - h * m * ay
    W[W_B + 2] = ty + h * m * ax
    gauss_solve(W, W_M, W, W_B, 3)
    nmin = 1e300
    for i in range(3):
        W[W_N + i] = W[W_B + i]
        nmin = min(nmin, W[W_B + i])
    return m * ax, m * ay, tz, nmin


@njit(cache=True, error_model="numpy")
def stick_ratio(P, Fx, Fy, tz, W, decide):
    """Smallest achievable max_i |f_i| / (mu_s,i N_i) for tangential forces f_i that give the
    required force (Fx, Fy) and yaw torque tz, with N_i from :func:`stick_forces` in W.

    The part can stick iff the result is <= 1. The least-norm distribution answers quickly when it
    is well inside; otherwise a log-barrier interior-point method solves the cone program
    min tau s.t. |g_i| <= tau over the 3-dimensional family of force distributions.

    With ``decide`` only the answer to "is it <= 1" is exact (the sticking test after a step): the
    result is then an upper bound that is <= 1, or a lower bound that is > 1, whichever is found
    first. Without it (the break-away event, located by root finding) the value is exact.
    """
    # Cheap lower bounds first: |F| <= sum |f_i| and |tau_z| <= sum |rho_i| |f_i|. When either
    # already exceeds 1 the part cannot stick and the bound is returned (it is <= the exact ratio,
    # so the sign of 1 - ratio, all that the break-away event uses near 1, is unchanged).
    cap_f = 0.0
    cap_t = 0.0
    for i in range(3):
        ci = P[RP_MUS + i] * W[W_N + i]
        if ci <= 0.0:
            return 1e300 if (Fx != 0.0 or Fy != 0.0 or tz != 0.0) else 0.0
        cap_f += ci
        cap_t += ci * math.hypot(W[W_RX + i], W[W_RY + i])
    bound = max(math.hypot(Fx, Fy) / cap_f, abs(tz) / cap_t if cap_t > 0.0 else 0.0)
    if bound > 1.0:
        return bound
    c = np.empty(3)
    for i in range(3):
        c[i] = P[RP_MUS + i] * W[W_N + i]
    B = np.zeros((3, 6))
    for i in range(3):
        B[0, 2 * i] = c[i]
        B[1, 2 * i + 1] = c[i]
        B[2, 2 * i] = -c[i] * W[W_RY + i]
        B[2, 2 * i + 1] = c[i] * W[W_RX + i]
    req = np.array([Fx, Fy, tz])
    BBt = B @ B.T
    lam = np.linalg.solve(BBt, req)
    gp = B.T @ lam
    worst = 0.0
    for i in range(3):
        worst = max(worst, math.hypot(gp[2 * i], gp[2 * i + 1]))
    if worst <= 0.5 or worst == 0.0 or (decide and worst <= 1.0):
        return worst
    _, _, Vt = np.linalg.svd(B)
    Z = np.ascontiguousarray(Vt[3:6].T)  # (6, 3) orthonormal basis of B's null space
    return _socp_min_max(gp, Z, worst, decide)


@njit(cache=True, error_model="numpy")
def _barrier(gp, Z, x, tb):
    """Value of tb * tau - sum_i log(tau^2 - |g_i|^2) at x = (lambda (3), tau); inf if infeasible."""
    tau = x[3]
    if tau <= 0.0:
        return np.inf
    val = tb * tau
    for i in range(3):
        gx = gp[2 * i] + Z[2 * i, 0] * x[0] + Z[2 * i, 1] * x[1] + Z[2 * i, 2] * x[2]
        gy = gp[2 * i + 1] + Z[2 * i + 1, 0] * x[0] + Z[2 * i + 1, 1] * x[1] + Z[2 * i + 1, 2] * x[2]
        s = tau * tau - gx * gx - gy * gy
        if s <= 0.0:
            return np.inf
        val -= math.log(s)
    return val


#: Centring of the cone program's barrier ends when the Newton decrement squared (lambda^2, in the
#: barrier's own units) is below this. The final duality gap is set by the outer loop (6 / tb below
#: 1e-11 of tau); a centring error lambda^2 / 2 moves tau by about lambda^2 / (2 tb), far below it.
#: At 1e-14 (before) Newton ran on into round-off, where the line search only halves its step: a
#: bracket's stick-slip rows called this 743 times per solve at 272 Newton steps (286 us) each, now
#: 124 (31 us), with the same values within 2.2e-16 (99.6 % bit for bit; docs/solver.md).
NEWTON_DEC = 2e-10

#: With ``decide`` the barrier starts this much steeper (tb = DECIDE_TB0 / tau instead of 1 / tau):
#: fewer outer steps, as only the side of 1 is wanted. On the 743 real inputs of a bracket's
#: stick-slip row, 24.5 Newton steps a call instead of 124 (exact) or 48 (decide, tb = 1 / tau),
#: every decision the same (docs/solver.md).
DECIDE_TB0 = 64.0


@njit(cache=True, error_model="numpy")
def _socp_min_max(gp, Z, start, decide):
    """min tau s.t. |gp_i + Z_i lambda| <= tau (i = 1..3) by a log barrier (degree 6) and Newton.

    The iterate's tau is always feasible (an upper bound); once centred (Newton decrement below
    NEWTON_DEC), tau - 6 / tb is a lower bound. With ``decide`` it returns as soon as tau <= 1, or
    as soon as, centred, twice that gap leaves the lower bound above 1.
    """
    x = np.zeros(4)
    x[3] = 1.05 * start + 1e-12
    tb = (DECIDE_TB0 if decide else 1.0) / x[3]
    grad = np.zeros(4)
    H = np.zeros(16)
    step = np.zeros(4)
    ds = np.empty(4)
    trial = np.empty(4)
    for _outer in range(40):
        centred = False
        for _newton in range(50):
            grad[:] = 0.0
            H[:] = 0.0
            grad[3] = tb
            tau = x[3]
            for i in range(3):
                gx = gp[2 * i] + Z[2 * i, 0] * x[0] + Z[2 * i, 1] * x[1] + Z[2 * i, 2] * x[2]
                gy = gp[2 * i + 1] + Z[2 * i + 1, 0] * x[0] + Z[2 * i + 1, 1] * x[1] + Z[2 * i + 1, 2] * x[2]
                s = tau * tau - gx * gx - gy * gy
                # d s / d(lambda_a) = -2 (g . Z_a),  d s / d tau = 2 tau
                for a in range(3):
                    ds[a] = -2.0 * (gx * Z[2 * i, a] + gy * Z[2 * i + 1, a])
                ds[3] = 2.0 * tau
                for a in range(4):
                    grad[a] -= ds[a] / s
                    for bb in range(4):
                        H[4 * a + bb] += ds[a] * ds[bb] / (s * s)
                # second derivatives of s: d2s/dl_a dl_b = -2 Z_a . Z_b, d2s/dtau2 = 2
                for a in range(3):
                    for bb in range(3):
                        zz = Z[2 * i, a] * Z[2 * i, bb] + Z[2 * i + 1, a] * Z[2 * i + 1, bb]
                        H[4 * a + bb] += 2.0 * zz / s
                H[15] -= 2.0 / s
            for a in range(4):
                step[a] = -grad[a]
            if gauss_solve(H, 0, step, 0, 4) == 0.0:
                break
            dec = 0.0
            for a in range(4):
                dec -= grad[a] * step[a]
            if dec < NEWTON_DEC:
                centred = True
                break
            f0 = _barrier(gp, Z, x, tb)
            alpha = 1.0
            for _ls in range(60):
                for a in range(4):
                    trial[a] = x[a] + alpha * step[a]
                if _barrier(gp, Z, trial, tb) <= f0 - 0.25 * alpha * dec:
                    break
                alpha *= 0.5
            for a in range(4):
                x[a] = trial[a]
            if decide and x[3] <= 1.0:
                return x[3]
        if decide and centred and x[3] - 12.0 / tb > 1.0:
            return x[3] - 12.0 / tb
        if 6.0 / tb < 1e-11 * max(1.0, x[3]):
            break
        tb *= 8.0
    return x[3]


# ================================================================ rigid part: right-hand side


@njit(cache=True, error_model="numpy", inline="always")
def rigid_rhs(mc, P, aux, t, y, K, s, W):
    plate_eval(mc, t, W, W_U, W_V)
    sx, sy, _ = geometry_for(P, y, W)
    K[s, 0] = y[3]
    K[s, 1] = y[4]
    K[s, 2] = y[5]
    if aux[AX_MODE] == STICK:
        h = W[W_H]
        K[s, 3] = W[W_U + 0] - W[W_U + 5] * sy + h * W[W_U + 4]
        K[s, 4] = W[W_U + 1] + W[W_U + 5] * sx - h * W[W_U + 3]
        K[s, 5] = W[W_U + 5]
        _, _, _, nmin = stick_forces(P, sx, sy, W, W_U)
        return OK if nmin > 0.0 else CONTACT_LOST
    return sliding_accelerations(P, aux, sx, sy, y[3], y[4], y[5], W, K, s)


@njit(cache=True, error_model="numpy")
def plate_twist(sx, sy, W):
    """The twist (Vx, Vy, thetadot) of a part stuck to the plate (plate velocity from W_V)."""
    h = W[W_H]
    return (W[W_V + 0] - W[W_V + 5] * sy + h * W[W_V + 4], W[W_V + 1] + W[W_V + 5] * sx - h * W[W_V + 3],
            W[W_V + 5])


@njit(cache=True, error_model="numpy", inline="always")
def rhs(kind, mc, P, aux, t, y, K, s, W):
    """Dispatch: kind 0 = point part, 1 = rigid part. Writes K[s, :]; returns a status."""
    if kind == 0:
        return point_rhs(mc, P, aux, t, y, K, s, W)
    return rigid_rhs(mc, P, aux, t, y, K, s, W)


def frictionless_det(contacts, inertia) -> float:
    """det of the rigid contact system with mu = 0: I_zz * det([1 1 1; rho_y; -rho_x]) (constant)."""
    c = np.asarray(contacts, float)
    D3 = np.linalg.det(np.array([[1.0, 1.0, 1.0], c[:, 1], -c[:, 0]]))
    return float(np.asarray(inertia, float)[2, 2] * D3)


__all__ = ["contact_velocities", "frictionless_det", "gauss_solve", "geometry_for", "plate_twist",
           "point_plate", "point_rhs", "rhs", "rigid_geometry", "rigid_rhs", "sliding_accelerations",
           "stick_forces", "stick_ratio"]

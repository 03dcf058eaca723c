"""The calibration's fit: Gauss-Newton on the channels' sensitivities with the motions projected out.

For given sensitivities every harmonic's motion is a linear least-squares solution (variable
projection), so the problem is one in the 3C sensitivities alone (:func:`_reduced_jacobian`). Each
step stays off the directions the readings cannot see (:mod:`~ppod_ros.estimation.unobservable`),
moves the sensitivities along them to the convention (least change from nominal, mean gain 1),
weighs a prior on the sensor errors against the readings' misfit, and is halved until the objective
drops. Also here: the conditioning check that refuses a fit, and the misfit of a held-out motion.

Plate bending: a plate's lowest bending mode is a saddle (two nodal diameters), driven by its vertical
acceleration; the vertical channels read it as ``(b_c cos 2 theta + b_s sin 2 theta) p''z``, which no
rigid motion and no per-channel gain makes on every motion (a gain scales the tilt about x and y as
well, the saddle does not). With at least five vertical channels at distinct angles (so that the
saddle is not a rigid tilt or bounce there) the fit adds the two coefficients (:func:`bending_shapes`);
left out, the saddle was taken into the vertical channels' gains, up to 1.3 % on the simulated
device's 2 % bending.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.estimation import unobservable
from ppod_ros.estimation.layout import AccelerometerLayout
from ppod_ros.estimation.second_order import second_order_phasors

if TYPE_CHECKING:
    from ppod_ros.estimation.calibration import MotionData

#: Largest condition number of a channel's excitation (its 3 x 3 sensitivity normal matrix, square
#: root) for its gain and axis to be fitted: beyond it one direction is seen 30x less than another.
MAX_CHANNEL_CONDITION = 30.0
#: Gauss-Newton passes, and the relative change of the sensitivities that ends them.
MAX_PASSES = 50
PASS_TOLERANCE = 1e-9
#: Expected size of a channel's sensitivity error (gain and axis, relative; the PPOD2 lab's worst are
#: 8 % and 5 degrees): the prior that keeps directions the motions barely see near nominal.
PRIOR_SENSOR_ERROR = 0.05
#: Halvings of a Gauss-Newton step before the pass gives up improving the misfit.
MAX_HALVINGS = 10


#: A vertical channel: its nominal axis within 25 degrees of the plate's normal.
VERTICAL_AXIS_MIN_Z = 0.9


class CalibrationError(ConfigError):
    """The recorded motions do not determine the calibration (ill-conditioned); nothing was fitted."""


# ---------------------------------------------------------------------- fit
def bending_shapes(layout: AccelerometerLayout) -> np.ndarray:
    """Saddle-bending regressors (C, 2): (cos 2 theta, sin 2 theta) of each vertical channel, 0 elsewhere.

    All zero when the vertical channels cannot tell the saddle from a rigid motion (fewer than five
    at distinct angles: the saddle then lies in the span of 1, cos theta, sin theta there).
    """
    return saddle_shapes(layout.position_m, layout.axis)


def saddle_shapes(position_m: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """:func:`bending_shapes` from channel positions (C, 3) and nominal axes (C, 3)."""
    position_m, axis = np.asarray(position_m, float), np.asarray(axis, float)
    vertical = np.abs(axis[:, 2]) > VERTICAL_AXIS_MIN_Z
    theta = np.arctan2(position_m[:, 1], position_m[:, 0])
    shapes = np.where(vertical[:, None], np.stack([np.cos(2 * theta), np.sin(2 * theta)], axis=1), 0.0)
    t = theta[vertical]
    basis = np.stack([np.ones_like(t), np.cos(t), np.sin(t), np.cos(2 * t), np.sin(2 * t)], axis=1)
    if t.size < 5 or np.linalg.matrix_rank(basis, tol=1e-6) < 5:
        return np.zeros_like(shapes)
    return shapes


def _levers(layout: AccelerometerLayout, motions: Sequence[MotionData], gravity: float) -> list[np.ndarray]:
    """Per motion, the lever of every harmonic and channel (K, C, 3), tilted-gravity term included."""
    out = []
    for m in motions:
        om = 2 * math.pi * m.frequency_hz * np.asarray(m.k, float)
        lift = np.zeros((om.size, 1, 3))
        lift[:, 0, 2] = gravity / om**2 if gravity > 0 else 0.0
        out.append(layout.position_m[None] + lift)
    return out


def _rows(U: np.ndarray, lever: np.ndarray) -> np.ndarray:
    """Specific-force phasor vectors at every channel, (K, C, 3): p'' + alpha x lever."""
    return U[:, None, :3] + np.cross(np.broadcast_to(U[:, None, 3:], lever.shape), lever)


def _design(w: np.ndarray, lever: np.ndarray, beta: np.ndarray | None) -> np.ndarray:
    """Readings per unit motion (K, C, 6): w . a + alpha . (lever x w), plus the bending beta_c p''z."""
    H = np.concatenate([np.broadcast_to(w, lever.shape), np.cross(lever, w[None])], axis=2)
    if beta is not None and np.any(beta):
        H = H.copy()
        H[..., 2] += beta[None]
    return H


def _solve_motions(w: np.ndarray, Y: np.ndarray, lever: np.ndarray, beta: np.ndarray | None = None) -> np.ndarray:
    """Plate motions (K, 6) given sensitivities w (C, 3) (and bending weights beta (C,))."""
    H = _design(w, lever, beta)
    return np.stack([np.linalg.lstsq(H[i], Y[i], rcond=None)[0] for i in range(Y.shape[0])])


def _predicted(U: np.ndarray, w: np.ndarray, lever: np.ndarray, beta: np.ndarray | None) -> np.ndarray:
    """Readings (K, C) of motions U (K, 6)."""
    out = np.einsum("kcj,cj->kc", _rows(U, lever), w)
    return out if beta is None else out + U[:, 2:3] * beta[None]


def _second_order(U: np.ndarray, m: MotionData, layout: AccelerometerLayout, axis: np.ndarray,
                  terms: tuple[str, ...], gravity: float) -> np.ndarray:
    if not terms:
        return np.zeros((m.k.size, layout.num_channels), complex)
    kmax = int(m.k.max())
    dense = np.zeros((kmax, 6), complex)
    dense[m.k - 1] = U
    return second_order_phasors(dense, m.frequency_hz, layout.position_m, axis, terms, gravity)[m.k - 1]


def _describe_direction(d: np.ndarray) -> str:
    d = d * np.sign(d[np.argmax(np.abs(d))])
    if abs(d[2]) > 0.7:
        hint = "vertical acceleration there (a bounce or a tilt about x or y)"
    else:
        hint = "in-plane acceleration there (a translation along x or y, or a rotation about z)"
    return f"[{d[0]:+.2f}, {d[1]:+.2f}, {d[2]:+.2f}]: record a motion with {hint}"


def _reduced_jacobian(layout: AccelerometerLayout, motions: Sequence[MotionData], w: np.ndarray,
                      levers: list[np.ndarray], Ss: list[np.ndarray], shapes: np.ndarray, bend: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Variable projection at (w, bend): (Jacobian (rows, 3C + 2), residual (rows,), motions [(K, 6)]).

    The last two columns are the bending coefficients' (``shapes`` (C, 2) x p''z).

    For given sensitivities every harmonic's motion is a linear least-squares solution; what remains
    is a problem in the sensitivities alone, whose Jacobian is the readings' Jacobian with respect to
    w projected off the columns the motion can explain (Kaufman's form). Its null space is the set of
    sensitivity changes some change of the motions hides: the unobserved directions.
    """
    C = layout.num_channels
    beta = shapes @ bend
    Us, J, r = [], [], []
    for m, S, lv in zip(motions, Ss, levers):
        Y = m.phasors - S
        U = _solve_motions(w, Y, lv, beta)
        Us.append(U)
        V = _rows(U, lv)  # (K, C, 3): d reading_c / d w_c
        H = _design(w, lv, beta)  # (K, C, 6)
        for i in range(Y.shape[0]):
            q = np.linalg.qr(H[i])[0]
            Jw = np.zeros((C, C, 3), complex)
            Jw[np.arange(C), np.arange(C)] = V[i]
            Jw = np.concatenate([Jw.reshape(C, 3 * C), shapes * U[i, 2]], axis=1)
            res = Y[i] - H[i] @ U[i]
            J.append(Jw - q @ (q.T @ Jw))
            r.append(res)
    J = np.concatenate(J)
    r = np.concatenate(r)
    return np.concatenate([J.real, J.imag]), np.concatenate([r.real, r.imag]), Us


def _cost(w: np.ndarray, motions: Sequence[MotionData], Ss: list[np.ndarray], levers: list[np.ndarray],
          beta: np.ndarray | None = None) -> float:
    """Sum of squared residuals of every reading with the motions fitted for sensitivities w."""
    total = 0.0
    for m, S, lv in zip(motions, Ss, levers):
        Y = m.phasors - S
        U = _solve_motions(w, Y, lv, beta)
        total += float(np.sum(np.abs(Y - _predicted(U, w, lv, beta)) ** 2))
    return total


def _fit(layout: AccelerometerLayout, motions: Sequence[MotionData], terms: tuple[str, ...], gravity: float,
         bending: bool = True) -> tuple[np.ndarray, list[np.ndarray], np.ndarray, np.ndarray, np.ndarray]:
    """Sensitivities w (C, 3), motions [(K, 6)], residual RMS (C,), unobserved basis (3C, n), bending (2,).

    Gauss-Newton on the sensitivities (:func:`_reduced_jacobian`) and, with ``bending`` on a layout
    that can see it (:func:`bending_shapes`), the two saddle-bending coefficients; the second-order
    terms evaluated at the current motions. Directions the data do not see are fixed by the least
    change from the nominal sensitivities (and mean gain 1): every step also moves w to the point of
    its family of equivalent sensitivities nearest the nominal layout, along the unobserved
    directions at w (the family is curved: a common rotation of axes is one of its directions).
    """
    C = layout.num_channels
    n = 3 * C + 2
    shapes = bending_shapes(layout) if bending else np.zeros((C, 2))
    levers = _levers(layout, motions, gravity)
    w = layout.axis.copy()
    bend = np.zeros(2)
    Ss = [np.zeros_like(m.phasors) for m in motions]
    ring: list[str] = []
    basis = np.zeros((3 * C, 0))
    nominal = np.concatenate([layout.axis.reshape(-1), np.zeros(2)])
    for i in range(MAX_PASSES):
        J, r, Us = _reduced_jacobian(layout, motions, w, levers, Ss, shapes, bend)
        if i == 0:  # which of the ring's directions this layout cannot see: decided at the nominal axes
            ring = unobservable.unseen_directions(layout.position_m, w, J[:, : 3 * C])
        basis = unobservable.unobserved_basis(layout.position_m, w, J[:, : 3 * C], ring)
        full = np.concatenate([basis, np.zeros((2, basis.shape[1]))])
        if not np.any(shapes):  # no bending term: its two coefficients stay 0
            full = np.concatenate([full, np.eye(n)[:, 3 * C :]], axis=1)
        # Gauss-Newton in the observed directions only (the others are the convention's).
        perp = np.linalg.svd(np.eye(n) - full @ full.T)[0][:, : n - full.shape[1]]
        # A prior on the sensor errors and the bending (size PRIOR_SENSOR_ERROR) against the readings'
        # misfit: directions the motions see faintly stay near nominal instead of fitting noise.
        lam = math.sqrt(float(r @ r) / r.size) / PRIOR_SENSOR_ERROR
        x = np.concatenate([w.reshape(-1), bend])
        A = np.concatenate([J @ perp, lam * perp])
        b = np.concatenate([r, -lam * (x - nominal)])
        sv, vt = unobservable.right_singular(A)  # least squares via the small Gram matrix (see there)
        keep = sv > sv[0] * unobservable.NULL_TOLERANCE
        z = vt[keep].T @ ((vt[keep] @ (A.T @ b)) / sv[keep] ** 2)
        step = perp @ z
        # Backtracking: the reduced problem is not linear; a full step may overshoot, so halve it
        # until the objective (misfit and prior) drops.
        cost = float(r @ r) + lam**2 * float(np.sum((x - nominal) ** 2))
        for _halving in range(MAX_HALVINGS):
            x_new = x + step
            w_try, bend_try = x_new[: 3 * C].reshape(w.shape), x_new[3 * C :]
            if _cost(w_try, motions, Ss, levers, shapes @ bend_try) + lam**2 * float(
                    np.sum((x_new - nominal) ** 2)) <= cost:
                break
            step = step / 2
        else:
            x_new = x
        w_new, bend_new = x_new[: 3 * C].reshape(w.shape), x_new[3 * C :]
        # The common gain is fixed by the mean gain, the other unobserved directions by the least change.
        gain_dir = w.reshape(-1, 1) / np.linalg.norm(w)  # in the basis at w: removing it drops one
        q, sv, _ = np.linalg.svd(basis - gain_dir @ (gain_dir.T @ basis), full_matrices=False)
        q = q[:, sv > 0.5]
        w_new = w_new - (q @ (q.T @ (w_new - layout.axis).reshape(-1))).reshape(w.shape)
        # A common gain scales the bending's readings as well.
        scale = float(np.mean(np.linalg.norm(w_new, axis=1)))
        w_new, bend_new = w_new / scale, bend_new / scale
        change = float(np.linalg.norm(np.concatenate([(w_new - w).reshape(-1), bend_new - bend]))
                       / np.linalg.norm(w))
        w, bend = w_new, bend_new
        Ss = [_second_order(U, m, layout, w, terms, gravity) for U, m in zip(Us, motions)]
        if change < PASS_TOLERANCE:
            break
    beta = shapes @ bend
    Us = [_solve_motions(w, m.phasors - S, lv, beta) for m, S, lv in zip(motions, Ss, levers)]
    res = np.concatenate([m.phasors - S - _predicted(U, w, lv, beta) for m, S, U, lv in zip(motions, Ss, Us, levers)])
    rms = np.sqrt(np.mean(np.abs(res) ** 2, axis=0))
    return w, Us, rms, basis, bend


def _check_conditioning(layout: AccelerometerLayout, motions: Sequence[MotionData], gravity: float) -> None:
    """Refuse when a channel's sensitivity is ill-conditioned under the nominal motions' estimate."""
    levers = _levers(layout, motions, gravity)
    Us = [_solve_motions(layout.axis, m.phasors, lv) for m, lv in zip(motions, levers)]
    V = np.concatenate([_rows(U, lv) for U, lv in zip(Us, levers)], axis=0)
    problems = []
    for c, name in enumerate(layout.names):
        A = np.concatenate([V[:, c].real, V[:, c].imag])
        _, s, vt = np.linalg.svd(A, full_matrices=False)
        cond = math.inf if s[-1] <= s[0] * 1e-12 else float(s[0] / s[-1])
        if not cond <= MAX_CHANNEL_CONDITION:
            problems.append(f"{name} (condition {cond:.3g}) lacks direction {_describe_direction(vt[-1])}")
    if problems:
        raise CalibrationError(
            f"calibration is ill-conditioned with motions {[m.name for m in motions]}: "
            + "; ".join(problems)
        )


def _misfit(layout: AccelerometerLayout, w: np.ndarray, m: MotionData, terms: tuple[str, ...], gravity: float,
            bend: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """Misfit of one motion under sensitivities w (and bending coefficients ``bend`` (2,)):
    (total residual / reading, per channel (C,))."""
    lv = _levers(layout, [m], gravity)[0]
    beta = None if bend is None else bending_shapes(layout) @ bend
    axis = w / np.linalg.norm(w, axis=1)[:, None]
    U = _solve_motions(w, m.phasors, lv, beta)
    for _ in range(3):
        S = _second_order(U, m, layout, axis, terms, gravity)
        U = _solve_motions(w, m.phasors - S, lv, beta)
    R = m.phasors - S - _predicted(U, w, lv, beta)
    own = np.linalg.norm(m.phasors, axis=0)
    total = float(np.linalg.norm(R) / np.linalg.norm(m.phasors))
    with np.errstate(divide="ignore", invalid="ignore"):
        per = np.where(own > 0, np.linalg.norm(R, axis=0) / own, 0.0)
    return total, per


__all__ = ["CalibrationError", "MAX_CHANNEL_CONDITION", "PRIOR_SENSOR_ERROR", "bending_shapes", "saddle_shapes"]

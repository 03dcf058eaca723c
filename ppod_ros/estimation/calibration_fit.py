"""The calibration's fit: Gauss-Newton on the channels' sensitivities with the motions projected out.

For given sensitivities every harmonic's motion is a linear least-squares solution (variable
projection), so the problem is one in the 3C sensitivities alone (:func:`_reduced_jacobian`). Each
step stays off the directions the readings cannot see (:mod:`~ppod_ros.estimation.unobservable`),
moves the sensitivities along them to the convention (least change from nominal, mean gain 1),
weighs a prior on the sensor errors against the readings' misfit, and is halved until the objective
drops. Also here: the conditioning check that refuses a fit, and the misfit of a held-out motion.
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


class CalibrationError(ConfigError):
    """The recorded motions do not determine the calibration (ill-conditioned); nothing was fitted."""


# ---------------------------------------------------------------------- fit
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


def _solve_motions(w: np.ndarray, Y: np.ndarray, lever: np.ndarray) -> np.ndarray:
    """Plate motions (K, 6) given sensitivities w (C, 3): reading = w . a + alpha . (lever x w)."""
    H = np.concatenate([np.broadcast_to(w, lever.shape), np.cross(lever, w[None])], axis=2)  # (K, C, 6)
    return np.stack([np.linalg.lstsq(H[i], Y[i], rcond=None)[0] for i in range(Y.shape[0])])


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
                      levers: list[np.ndarray], Ss: list[np.ndarray]
                      ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Variable projection at w: (Jacobian (rows, 3C), residual (rows,), motions [(K, 6)]).

    For given sensitivities every harmonic's motion is a linear least-squares solution; what remains
    is a problem in the sensitivities alone, whose Jacobian is the readings' Jacobian with respect to
    w projected off the columns the motion can explain (Kaufman's form). Its null space is the set of
    sensitivity changes some change of the motions hides: the unobserved directions.
    """
    C = layout.num_channels
    Us, J, r = [], [], []
    for m, S, lv in zip(motions, Ss, levers):
        Y = m.phasors - S
        U = _solve_motions(w, Y, lv)
        Us.append(U)
        V = _rows(U, lv)  # (K, C, 3): d reading_c / d w_c
        H = np.concatenate([np.broadcast_to(w, lv.shape), np.cross(lv, w[None])], axis=2)  # (K, C, 6)
        for i in range(Y.shape[0]):
            q = np.linalg.qr(H[i])[0]
            Jw = np.zeros((C, C, 3), complex)
            Jw[np.arange(C), np.arange(C)] = V[i]
            Jw = Jw.reshape(C, 3 * C)
            res = Y[i] - H[i] @ U[i]
            J.append(Jw - q @ (q.T @ Jw))
            r.append(res)
    J = np.concatenate(J)
    r = np.concatenate(r)
    return np.concatenate([J.real, J.imag]), np.concatenate([r.real, r.imag]), Us


def _cost(w: np.ndarray, motions: Sequence[MotionData], Ss: list[np.ndarray], levers: list[np.ndarray]) -> float:
    """Sum of squared residuals of every reading with the motions fitted for sensitivities w."""
    total = 0.0
    for m, S, lv in zip(motions, Ss, levers):
        Y = m.phasors - S
        U = _solve_motions(w, Y, lv)
        total += float(np.sum(np.abs(Y - np.einsum("kcj,cj->kc", _rows(U, lv), w)) ** 2))
    return total


def _fit(layout: AccelerometerLayout, motions: Sequence[MotionData], terms: tuple[str, ...], gravity: float
         ) -> tuple[np.ndarray, list[np.ndarray], np.ndarray, np.ndarray]:
    """Sensitivities w (C, 3), motions [(K, 6)], residual RMS (C,), unobserved basis (3C, n).

    Gauss-Newton on the sensitivities (:func:`_reduced_jacobian`), the second-order terms evaluated at
    the current motions. Directions the data do not see are fixed by the least change from the
    nominal sensitivities (and mean gain 1): every step also moves w to the point of its family of
    equivalent sensitivities nearest the nominal layout, along the unobserved directions at w (the
    family is curved: a common rotation of axes is one of its directions).
    """
    C = layout.num_channels
    levers = _levers(layout, motions, gravity)
    w = layout.axis.copy()
    Ss = [np.zeros_like(m.phasors) for m in motions]
    ring: list[str] = []
    basis = np.zeros((3 * C, 0))
    for i in range(MAX_PASSES):
        J, r, Us = _reduced_jacobian(layout, motions, w, levers, Ss)
        if i == 0:  # which of the ring's directions this layout cannot see: decided at the nominal axes
            ring = unobservable.unseen_directions(layout.position_m, w, J)
        basis = unobservable.unobserved_basis(layout.position_m, w, J, ring)
        # Gauss-Newton in the observed directions only (the others are the convention's).
        perp = np.linalg.svd(np.eye(3 * C) - basis @ basis.T)[0][:, : 3 * C - basis.shape[1]]
        # A prior on the sensor errors (size PRIOR_SENSOR_ERROR) against the readings' misfit: directions
        # the motions see faintly stay near nominal instead of fitting the misfit (bending, noise).
        lam = math.sqrt(float(r @ r) / r.size) / PRIOR_SENSOR_ERROR
        A = np.concatenate([J @ perp, lam * perp])
        b = np.concatenate([r, -lam * (w - layout.axis).reshape(-1)])
        sv, vt = unobservable.right_singular(A)  # least squares via the small Gram matrix (see there)
        keep = sv > sv[0] * unobservable.NULL_TOLERANCE
        z = vt[keep].T @ ((vt[keep] @ (A.T @ b)) / sv[keep] ** 2)
        step = (perp @ z).reshape(w.shape)
        # Backtracking: the reduced problem is not linear; a full step may overshoot, so halve it
        # until the objective (misfit and prior) drops.
        cost = float(r @ r) + lam**2 * float(np.sum((w - layout.axis) ** 2))
        for _halving in range(MAX_HALVINGS):
            w_new = w + step
            if _cost(w_new, motions, Ss, levers) + lam**2 * float(np.sum((w_new - layout.axis) ** 2)) <= cost:
                break
            step = step / 2
        else:
            w_new = w
        # The common gain is fixed by the mean gain, the other unobserved directions by the least change.
        gain_dir = w.reshape(-1, 1) / np.linalg.norm(w)  # in the basis at w: removing it drops one
        q, sv, _ = np.linalg.svd(basis - gain_dir @ (gain_dir.T @ basis), full_matrices=False)
        q = q[:, sv > 0.5]
        w_new = w_new - (q @ (q.T @ (w_new - layout.axis).reshape(-1))).reshape(w.shape)
        w_new /= float(np.mean(np.linalg.norm(w_new, axis=1)))
        change = float(np.linalg.norm(w_new - w) / np.linalg.norm(w))
        w = w_new
        Ss = [_second_order(U, m, layout, w, terms, gravity) for U, m in zip(Us, motions)]
        if change < PASS_TOLERANCE:
            break
    Us = [_solve_motions(w, m.phasors - S, lv) for m, S, lv in zip(motions, Ss, levers)]
    res = np.concatenate([
        m.phasors - S - np.einsum("kcj,cj->kc", _rows(U, lv), w) for m, S, U, lv in zip(motions, Ss, Us, levers)
    ])
    rms = np.sqrt(np.mean(np.abs(res) ** 2, axis=0))
    return w, Us, rms, basis


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


def _misfit(layout: AccelerometerLayout, w: np.ndarray, m: MotionData, terms: tuple[str, ...], gravity: float
            ) -> tuple[float, np.ndarray]:
    """Misfit of one motion under sensitivities w: (total residual / reading, per channel (C,))."""
    lv = _levers(layout, [m], gravity)[0]
    axis = w / np.linalg.norm(w, axis=1)[:, None]
    U = _solve_motions(w, m.phasors, lv)
    for _ in range(3):
        S = _second_order(U, m, layout, axis, terms, gravity)
        U = _solve_motions(w, m.phasors - S, lv)
    R = m.phasors - S - np.einsum("kcj,cj->kc", _rows(U, lv), w)
    own = np.linalg.norm(m.phasors, axis=0)
    total = float(np.linalg.norm(R) / np.linalg.norm(m.phasors))
    with np.errstate(divide="ignore", invalid="ignore"):
        per = np.where(own > 0, np.linalg.norm(R, axis=0) / own, 0.0)
    return total, per


__all__ = ["CalibrationError", "MAX_CHANNEL_CONDITION", "PRIOR_SENSOR_ERROR"]

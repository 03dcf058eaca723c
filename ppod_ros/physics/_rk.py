"""Embedded explicit Runge-Kutta pairs, chosen by name, and one compiled step.

The Butcher tableaus are scipy's (``scipy.integrate.RK23``, ``RK45``, ``DOP853``): the same
coefficients users know from ``solve_ivp``, kept as constants in ``_tableaus.py`` (checked against
scipy by the tests; importing scipy.integrate only to read them cost 0.3 s of start-up). The step
evaluates the stages with :func:`~._contact.rhs`, always including the final stage f(t + h, y_new)
(first-same-as-last: it is the next step's first stage) and returns a scaled error norm (max norm
over the velocity components; DOP853 uses its own combined 5th/3rd order estimate) together with
the worst contact status met in the stages.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ppod_ros.physics._contact import rhs
from ppod_ros.physics._jit import njit
from ppod_ros.physics._tableaus import TABLEAUS


@dataclass(frozen=True)
class Tableau:
    """An embedded pair: stages A (s, s), weights B (s,), nodes C (s,), error weights E (s+1,)
    (and E3 (s+1,) for DOP853's combined estimate); ``order`` of the solution, ``error_order`` of
    the embedded estimate."""

    name: str
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    E: np.ndarray
    E3: np.ndarray
    combined_error: bool
    order: int
    error_order: int

    @property
    def stages(self) -> int:
        return int(self.B.shape[0])

    @property
    def exponent(self) -> float:
        """Step-size exponent -1 / (error_order + 1)."""
        return -1.0 / (self.error_order + 1)


def _tableau(name: str) -> Tableau:
    A, B, C, E, E3, order, error_order = TABLEAUS[name]
    E = np.asarray(E, float)
    return Tableau(name, np.ascontiguousarray(np.asarray(A, float)), np.asarray(B, float), np.asarray(C, float), E,
                   np.zeros_like(E) if E3 is None else np.asarray(E3, float), E3 is not None, order, error_order)


#: Integrators by name (STYLE.md rule 5): Bogacki-Shampine 3(2), Dormand-Prince 5(4), Dormand-Prince 8(5,3).
INTEGRATORS: dict[str, Tableau] = {name: _tableau(name) for name in ("bs3", "dopri5", "dop853")}


@njit(cache=True, error_model="numpy")
def rk_step(kind, mc, P, aux, t, y, h, A, B, C, E, E3, combined, K, reuse_f0, ytmp, ynew, W, sc, n):
    """One step of size h from (t, y) into ``ynew``; returns (scaled error norm, worst status).

    ``K`` (stages + 1, n) holds the stage derivatives; with ``reuse_f0`` K[0] already holds
    f(t, y). ``sc`` (n,) are the error scales (0: component not error-controlled).
    """
    status = 0
    ns = B.shape[0]
    # One call site of the right-hand side (it is inlined: one copy of its body, not three); every
    # stage's state goes through ytmp, the last also into ynew.
    for s in range(0 if not reuse_f0 else 1, ns + 1):
        if s == 0:
            ts = t
            for j in range(n):
                ytmp[j] = y[j]
        elif s < ns:
            ts = t + C[s] * h
            for j in range(n):
                acc = 0.0
                for q in range(s):
                    acc += A[s, q] * K[q, j]
                ytmp[j] = y[j] + h * acc
        else:
            ts = t + h
            for j in range(n):
                acc = 0.0
                for q in range(ns):
                    acc += B[q] * K[q, j]
                ynew[j] = y[j] + h * acc
                ytmp[j] = ynew[j]
        status = max(status, rhs(kind, mc, P, aux, ts, ytmp, K, s, W))
    if not combined:
        err = 0.0
        for j in range(n):
            if sc[j] > 0.0:
                acc = 0.0
                for q in range(ns + 1):
                    acc += E[q] * K[q, j]
                err = max(err, abs(h * acc) / sc[j])
        return err, status
    # DOP853: |h| * |e5|^2 / sqrt((|e5|^2 + 0.01 |e3|^2) * m), as in Hairer's code and scipy.
    n5 = 0.0
    n3 = 0.0
    m = 0
    for j in range(n):
        if sc[j] > 0.0:
            a5 = 0.0
            a3 = 0.0
            for q in range(ns + 1):
                a5 += E[q] * K[q, j]
                a3 += E3[q] * K[q, j]
            n5 += (a5 / sc[j]) ** 2
            n3 += (a3 / sc[j]) ** 2
            m += 1
    if n5 == 0.0 and n3 == 0.0:
        return 0.0, status
    return abs(h) * n5 / np.sqrt((n5 + 0.01 * n3) * m), status


__all__ = ["INTEGRATORS", "Tableau", "rk_step"]

"""The simulated plate plant in the time domain: exact discretisation, vectorised over a chunk.

The plant has the nominal model's structure (:class:`ppod_ros.actuation.plant.NominalPlant`: rigid
plate on six flexure legs, coil circuits with back-EMF, PI current loops) and is simulated on the
device's control grid. The current references are piecewise linear between control steps (the
device's DAC interpolates), so the *first-order-hold* discretisation

    x[n+1] = Phi x[n] + G0 u[n] + G1 u[n+1]

is exact for the linear part. A chunk of L steps is computed at once, on the grid of reported rows
(every m-th step; the inputs of the m steps in between are aggregated exactly): the recursion is a
parallel prefix scan (log2(L/m) matrix products over the whole chunk) plus the free response.

With ``exact_geometry`` the plant is the exact one to second order in the motion: leg lengths,
directions and rates from the exact kinematics, the rotation of the plate's inertia and centre of
mass, centripetal and gyroscopic terms. Their difference from the linear model enters as the
disturbance inputs (generalised force f_d and coil voltage v_d), computed from the chunk's first
pass and applied in a second pass (a Picard step: the terms are ~1e-3 of the motion and one step
leaves a third-order remainder, 3e-5 of the state at LineSinkX amplitude against a Runge-Kutta
integration of the exact equations, tests/device/test_sim_plant.py). Gravity and the flexure
preload balance at home; their geometric-stiffness terms (about 1 % of the flexure stiffness,
0.1 % of the response above the suspension modes) are left out of both models.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ppod_ros.actuation.plant import NU, NX, NominalPlant
from ppod_ros.device.config import DeviceConfig
from ppod_ros.kinematics.stewart import cross, rotation_and_left_jacobian
from ppod_ros.motion import GRAVITY_MPS2


@dataclass(frozen=True)
class Discretisation:
    """First-order-hold discretisation for control step ``dt_s``, aggregated to a grid of ``every`` steps.

    ``x[(j+1) m] = Phi^m x[j m] + sum_{i=0..m} Gamma_i u[j m + i]`` is exact for references linear
    between control steps (m = ``every``); ``powers`` holds (Phi^m)^j for j = 0..rows.
    """

    dt_s: float
    every: int
    rows: int
    Phi_m: np.ndarray  # (24, 24)
    Gamma: np.ndarray  # (every + 1, 24, 18)
    Gamma_flat: np.ndarray  # ((every + 1) 18, 24): Gamma stacked for one matrix product per chunk
    powers: np.ndarray  # (rows + 1, 24, 24)
    doubling: tuple[np.ndarray, ...]  # (Phi^m)^(2^l)


def foh_discretise(A: np.ndarray, B: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact discretisation for inputs linear between samples: (Phi, G0, G1)."""
    n, m = B.shape
    big = np.zeros((n + 2 * m, n + 2 * m))
    big[:n, :n] = A * dt_s
    big[:n, n : n + m] = B * dt_s
    big[n : n + m, n + m :] = np.eye(m)
    E = scipy.linalg.expm(big)
    Phi, P1, P2 = E[:n, :n], E[:n, n : n + m], E[:n, n + m :]
    return Phi, P1 - P2, P2


@dataclass
class ChunkResult:
    """The plant over one chunk, at the reported rows 0, every, 2 every, ... < L of the chunk.

    Attributes
    ----------
    x : (n, 24) state; accel_world : (n, 6) [p'', alpha] in the base frame; accel_plate : (n, 6)
    [p'', alpha] expressed in the plate frame (the ground truth of PHYSICS.md's control vector);
    omega_plate : (n, 3) angular velocity in the plate frame; gravity_plate : (n, 3) the gravity
    vector in the plate frame; leg : (n, 6) leg displacements (m). At the reported rows and the
    chunk end: voltage : (n+1, 6) amplifier outputs (V); current : (n+1, 6) coil currents (A).
    """

    x: np.ndarray
    accel_world: np.ndarray
    accel_plate: np.ndarray
    omega_plate: np.ndarray
    gravity_plate: np.ndarray
    voltage: np.ndarray
    leg: np.ndarray
    current: np.ndarray
    x_grid: np.ndarray = None  # (n+1, 24) plant state at the reported rows and the chunk end
    u_grid: np.ndarray = None  # (n+1, 18) inputs there (the disturbance part carries over)


class PlantSimulator:
    """The plate plant of one simulated device (see the module docstring).

    Parameters
    ----------
    config : DeviceConfig
    exact_geometry : bool, optional
        Override ``config.sim.exact_geometry``.
    """

    def __init__(self, config: DeviceConfig, exact_geometry: bool | None = None):
        self.config = config
        self.model = NominalPlant(config)
        self.kin = self.model.kinematics
        self.exact = config.sim.exact_geometry if exact_geometry is None else bool(exact_geometry)
        self.x = np.zeros(NX)
        self._u_last = np.zeros(NU)
        self._cache: dict[float, Discretisation] = {}
        p = config.plate
        self._m = p.mass_kg
        self._com = np.asarray(p.com_m)
        self._inertia = np.asarray(p.inertia_kgm2)
        a = config.actuators
        self._kf = a.force_constant_n_per_a
        self._kb = a.back_emf_v_s_per_m
        self._mc = a.moving_mass_kg
        self._k = config.flexures.leg_stiffness_n_per_m
        self._c = config.flexures.leg_damping_n_s_per_m

    def reset(self) -> None:
        self.x = np.zeros(NX)
        self._u_last = np.zeros(NU)

    def discretisation(self, dt_s: float, every: int, rows: int) -> Discretisation:
        """Grid discretisation for control step ``dt_s`` (cached), with powers for ``rows`` grid rows."""
        key = (float(dt_s), int(every))
        d = self._cache.get(key)
        if d is None or d.rows < rows:
            Phi, G0, G1 = foh_discretise(self.model.A, self.model.B, dt_s)
            m = int(every)
            P = [np.eye(NX)]
            for _ in range(m):
                P.append(P[-1] @ Phi)
            Gamma = np.zeros((m + 1, NX, NU))
            for i in range(m + 1):
                if i <= m - 1:
                    Gamma[i] += P[m - 1 - i] @ G0
                if i >= 1:
                    Gamma[i] += P[m - i] @ G1
            Phi_m = P[m]
            powers = np.empty((rows + 1, NX, NX))
            powers[0] = np.eye(NX)
            for n in range(1, rows + 1):
                powers[n] = powers[n - 1] @ Phi_m
            doubling, Q, span = [], Phi_m, 1
            while span < rows:
                doubling.append(Q)
                Q, span = Q @ Q, 2 * span
            flat = np.ascontiguousarray(Gamma.transpose(0, 2, 1).reshape((m + 1) * NU, NX))
            d = Discretisation(float(dt_s), m, int(rows), Phi_m, Gamma, flat, powers, tuple(doubling))
            if len(self._cache) > 16:
                self._cache.clear()
            self._cache[key] = d
        return d

    # ------------------------------------------------------------------ linear pass
    @staticmethod
    def _linear_pass(d: Discretisation, x0: np.ndarray, U: np.ndarray) -> np.ndarray:
        """States at the grid rows 0, m, ..., L for control-step inputs U (L+1, 18), by a prefix scan."""
        m = d.every
        J = (U.shape[0] - 1) // m
        blocks = U[np.arange(J)[:, None] * m + np.arange(m + 1)].reshape(J, -1)  # (J, (m+1) 18)
        W = blocks @ d.Gamma_flat  # (J, 24): drives grid row j+1
        span = 1
        for P in d.doubling:
            if span >= J:
                break
            shifted = W[:-span] @ P.T
            W = W.copy()
            W[span:] += shifted
            span *= 2
        X = np.empty((J + 1, NX))
        X[0] = x0
        X[1:] = W + d.powers[1 : J + 1] @ x0
        return X

    def _accel(self, X: np.ndarray, U: np.ndarray) -> np.ndarray:
        return X @ self.model.A[6:12].T + U @ self.model.B[6:12].T

    # ------------------------------------------------------------------ exact terms
    def _kinematics(self, X: np.ndarray, qdd: np.ndarray) -> dict[str, np.ndarray]:
        """Exact rigid-body and leg kinematics at the given rows (n, ...)."""
        q, qd = X[:, 0:6], X[:, 6:12]
        R, Jl = rotation_and_left_jacobian(q[:, 3:])
        omega = np.einsum("nij,nj->ni", Jl, qd[:, 3:])
        # alpha = J_l phi'' + (dJ_l/dt) phi'; the second term is third order in the motion (dropped).
        alpha = np.einsum("nij,nj->ni", Jl, qdd[:, 3:])
        r = np.einsum("nij,lj->nli", R, self.kin.plate)  # attachments about P, (n, 6, 3)
        legs = self.kin.home + q[:, None, :3] + r - self.kin.base
        L = np.sqrt(np.einsum("nli,nli->nl", legs, legs))
        return {
            "R": R,
            "omega": omega,
            "alpha": alpha,
            "r": r,
            "n": legs / L[..., None],
            "leg": L - self.kin.home_lengths_m,
        }

    def _disturbance(self, X: np.ndarray, qdd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Generalised force and voltage that turn the linear model into the exact one, (n, 6) each."""
        q, qd, cur = X[:, 0:6], X[:, 6:12], X[:, 12:18]
        J0 = self.model.J
        g = self._kinematics(X, qdd)
        R, omega, alpha, r, n_hat = g["R"], g["omega"], g["alpha"], g["r"], g["n"]
        Ldot = np.einsum("nli,nli->nl", n_hat, qd[:, None, :3] + cross(omega[:, None, :], r))
        f = self._kf * cur - self._k * g["leg"] - self._c * Ldot - self._mc * (qdd @ J0.T)
        fn = f[..., None] * n_hat
        F = fn.sum(axis=1)
        tau = cross(r, fn).sum(axis=1)
        c_w = R @ self._com
        I_w = R @ self._inertia @ np.swapaxes(R, 1, 2)
        pdd = qdd[:, :3]
        a_c = pdd + cross(alpha, c_w) + cross(omega, cross(omega, c_w))
        Iw_om = np.einsum("nij,nj->ni", I_w, omega)
        tau_in = self._m * cross(c_w, a_c) + np.einsum("nij,nj->ni", I_w, alpha) + cross(omega, Iw_om)
        exact = np.hstack([self._m * a_c - F, tau_in - tau])
        linear = qdd @ self.model.M.T + qd @ self.model.C.T + q @ self.model.K.T - self._kf * cur @ J0
        return linear - exact, self._kb * (qd @ J0.T - Ldot)

    # ------------------------------------------------------------------ public
    def simulate(self, current_ref: np.ndarray, dt_s: float, every: int = 1) -> ChunkResult:
        """Advance over one chunk and report the plate at every ``every``-th control step.

        Parameters
        ----------
        current_ref : ndarray, shape (L+1, 6)
            Current references at the control steps; row 0 is the value at the chunk start (it must
            equal the last row of the previous chunk: the reference is continuous).
        dt_s : float
            Control step (s).
        every : int
            Report rows 0, every, 2 every, ... < L (L must be a multiple). The exact terms are
            evaluated on this grid and interpolated linearly between (they are smooth, ~1e-3 of
            the motion).
        """
        L = current_ref.shape[0] - 1
        if L % every:
            raise ValueError(f"every: the chunk's {L} steps must be a multiple of {every}")
        J = L // every
        d = self.discretisation(dt_s, every, J)
        U = np.zeros((L + 1, NU))
        U[:, :6] = current_ref
        U[0, 6:] = self._u_last[6:]
        grid = np.arange(0, L + 1, every)
        X = self._linear_pass(d, self.x, U)  # states at the grid rows
        qdd = self._accel(X, U[grid])
        if self.exact:
            f_d, v_d = self._disturbance(X, qdd)
            D = np.hstack([f_d, v_d])
            D[0] = self._u_last[6:]  # the chunk start is already simulated: keep its input
            n = np.arange(L + 1)
            j = np.minimum(n // every, J - 1)
            w = ((n - j * every) / every)[:, None]
            U[:, 6:] = (1 - w) * D[j] + w * D[j + 1]
            X = self._linear_pass(d, self.x, U)
            qdd = self._accel(X, U[grid])
        Xs, qs = X[:-1], qdd[:-1]
        if self.exact:
            g = self._kinematics(Xs, qs)
            R, omega_w, alpha_w, leg = g["R"], g["omega"], g["alpha"], g["leg"]
        else:
            R = rotation_and_left_jacobian(Xs[:, 3:6])[0]
            omega_w, alpha_w = Xs[:, 9:12], qs[:, 3:]
            leg = Xs[:, 0:6] @ self.model.J.T
        self.x = X[-1].copy()
        self._u_last = U[-1].copy()
        Rt = np.swapaxes(R, 1, 2)
        accel_world = np.hstack([qs[:, :3], alpha_w])
        accel_plate = np.hstack(
            [np.einsum("nij,nj->ni", Rt, qs[:, :3]), np.einsum("nij,nj->ni", Rt, alpha_w)]
        )
        omega_plate = np.einsum("nij,nj->ni", Rt, omega_w)
        gravity_plate = Rt[:, :, 2] * -GRAVITY_MPS2
        Cv, Dv = self.model.output_matrices("voltage")
        voltage = X @ Cv.T + U[grid] @ Dv.T
        return ChunkResult(
            Xs,
            accel_world,
            accel_plate,
            omega_plate,
            gravity_plate,
            voltage,
            leg,
            X[:, 12:18].copy(),
            X,
            U[grid],
        )

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """The plant state and the carried-over input (to resume a simulation from here)."""
        return self.x.copy(), self._u_last.copy()

    def set_state(self, x: np.ndarray, u_last: np.ndarray) -> None:
        """Resume from a state returned by :meth:`state` or a row of ``ChunkResult.x_grid/u_grid``."""
        self.x = np.array(x, dtype=float)
        self._u_last = np.array(u_last, dtype=float)


__all__ = ["ChunkResult", "Discretisation", "PlantSimulator", "foh_discretise"]

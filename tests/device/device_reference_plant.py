"""An independent reference for the simulated plant: the exact equations integrated by solve_ivp.

Written separately from ppod_sim.plant (which linearises and corrects by a Picard step): here the
Newton-Euler equations of the plate on its six exact legs are solved for the generalised
accelerations at every right-hand-side evaluation and integrated with the classical fourth-order
Runge-Kutta method, ``substeps`` steps per interval of the reference grid (the references are linear
within each interval, so the right-hand side is smooth there).
"""

import numpy as np

from ppod_ros.actuation.plant import NominalPlant
from ppod_ros.kinematics.stewart import left_jacobian, rotation_matrix, skew


def reference_run(config, t_grid, current_ref, exact=True, substeps=8):
    """States (len(t_grid), 24) for current references linear between ``t_grid`` points (rows of (n, 6))."""
    model = NominalPlant(config)
    kin = model.kinematics
    a, fl, p = config.actuators, config.flexures, config.plate
    J0 = model.J
    m, com, Ic = p.mass_kg, np.asarray(p.com_m), np.asarray(p.inertia_kgm2)

    def icmd(t):
        j = min(max(int(np.searchsorted(t_grid, t, side="right")) - 1, 0), len(t_grid) - 2)
        w = (t - t_grid[j]) / (t_grid[j + 1] - t_grid[j])
        return (1 - w) * current_ref[j] + w * current_ref[j + 1]

    def rhs(t, x):
        q, qd, i, z = x[0:6], x[6:12], x[12:18], x[18:24]
        u = icmd(t)
        if not exact:
            return model.A @ x + model.B[:, :6] @ u
        R = rotation_matrix(q[3:])
        Jl = left_jacobian(q[3:])
        omega = Jl @ qd[3:]
        r = (R @ kin.plate.T).T
        legs = kin.home + q[:3] + r - kin.base
        L = np.linalg.norm(legs, axis=1)
        n = legs / L[:, None]
        G = np.hstack([n, np.cross(r, n)])  # leg rates per [v, omega]
        Ldot = G @ np.concatenate([qd[:3], omega])
        f0 = (
            a.force_constant_n_per_a * i
            - fl.leg_stiffness_n_per_m * (L - kin.home_lengths_m)
            - fl.leg_damping_n_s_per_m * Ldot
        )
        c_w = R @ com
        I_w = R @ Ic @ R.T
        S = skew(c_w)
        Mw = np.block([[m * np.eye(3), -m * S], [m * S, I_w - m * S @ S]])
        cent = np.cross(omega, np.cross(omega, c_w))
        h = np.concatenate([m * cent, m * np.cross(c_w, cent) + np.cross(omega, I_w @ omega)])
        T = np.eye(6)
        T[3:, 3:] = Jl
        A_mat = Mw @ T + a.moving_mass_kg * G.T @ J0
        qdd = np.linalg.solve(A_mat, G.T @ f0 - h)
        V = model.kp * (u - i) + model.ki * z
        di = (V - a.resistance_ohm * i - a.back_emf_v_s_per_m * Ldot) / a.inductance_h
        return np.concatenate([qd, qdd, di, u - i])

    x = np.zeros(24)
    out = [x]
    for j in range(len(t_grid) - 1):
        h = (t_grid[j + 1] - t_grid[j]) / substeps
        t = t_grid[j]
        for _ in range(substeps):
            k1 = rhs(t, x)
            k2 = rhs(t + h / 2, x + h / 2 * k1)
            k3 = rhs(t + h / 2, x + h / 2 * k2)
            k4 = rhs(t + h, x + h * k3)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            t += h
        out.append(x)
    return np.array(out)

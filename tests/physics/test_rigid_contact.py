"""The rigid contact model against direct solutions of PHYSICS.md's equations."""

import math

import numpy as np
import pytest
from scipy.optimize import minimize

from ppod_ros.parts import RigidPart
from ppod_ros.physics import _layout as lay
from ppod_ros.physics._contact import (
    FRICTIONAL_SINGULARITY,
    rigid_geometry,
    sliding_accelerations,
    stick_forces,
    stick_ratio,
)
from ppod_ros.physics._params import rigid_rows

G = 9.81


def _setup(part, th, u, v):
    P = rigid_rows(part, np.array([[0.01, -0.02, th]]), 1e-6)[0]
    P[lay.RP_ZTOL] = 0.0
    W = np.zeros(lay.W_SIZE)
    W[lay.W_U:lay.W_U + 6] = u
    W[lay.W_V:lay.W_V + 6] = v
    rigid_geometry(P, th, W)
    return P, W


def _direct(part, th, sx, sy, u, dirs):
    """Newton-Euler with F_i = (-mu_i N_i d_i, N_i): the 6x6 system in (Ax, Ay, thetadd, N1..N3)."""
    c, s = math.cos(th), math.sin(th)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    Iw = R @ part.inertia @ R.T
    rho = part.contacts @ R.T
    m = part.mass
    M = np.zeros((6, 6))
    b = np.zeros(6)
    M[0, 0] = M[1, 1] = m
    for i in range(3):
        M[0, 3 + i] = part.mu[i] * dirs[i, 0]
        M[1, 3 + i] = part.mu[i] * dirs[i, 1]
        M[2, 3 + i] = 1.0
        F = np.array([-part.mu[i] * dirs[i, 0], -part.mu[i] * dirs[i, 1], 1.0])  # per unit N_i
        M[3:6, 3 + i] = -np.cross(rho[i], F)
    b[2] = m * (G + u[2] + u[3] * sy - u[4] * sx)
    M[3:6, 2] = Iw[:, 2]
    b[3:6] = -(Iw[:, 0] * u[3] + Iw[:, 1] * u[4])
    return np.linalg.solve(M, b)


@pytest.mark.parametrize("th", [0.0, 0.7, 2.5])
def test_sliding_accelerations_solve_the_whole_newton_euler_system(th):
    inertia = np.array([[1.1e-5, 2e-7, -3e-7], [2e-7, 1.3e-6, 1e-7], [-3e-7, 1e-7, 1.2e-5]])  # full tensor
    part = RigidPart(0.0216, inertia, [[0.01, -0.03, -0.004], [0.0, 0.03, -0.004], [-0.01, -0.03, -0.004]],
                     [0.3, 0.4, 0.5])
    u = np.array([3.0, -1.0, 2.0, 20.0, -15.0, 40.0])
    v = np.array([0.01, 0.02, 0.0, 0.1, -0.2, 0.3])
    P, W = _setup(part, th, u, v)
    K = np.zeros((1, 6))
    aux = np.zeros(lay.AX_SIZE)
    Vx, Vy, wz = 0.05, -0.03, 1.5
    status = sliding_accelerations(P, aux, 0.01, -0.02, Vx, Vy, wz, W, K, 0)
    assert status == 0
    dirs = W[lay.W_E:lay.W_E + 6].reshape(3, 2)
    assert np.allclose(np.hypot(dirs[:, 0], dirs[:, 1]), 1.0)
    x = _direct(part, th, 0.01, -0.02, u, dirs)
    assert K[0, 3:6] == pytest.approx(x[[0, 1, 2]], rel=1e-10, abs=1e-12)
    assert W[lay.W_N:lay.W_N + 3] == pytest.approx(x[3:6], rel=1e-10)


def test_with_the_centre_of_mass_on_the_contact_plane_normal_forces_ignore_sliding_directions():
    part = RigidPart(0.0216, [1.084e-5, 0.123e-5, 1.20e-5], [[0.01, -0.03, 0.0], [0.0, 0.03, 0.0],
                                                             [-0.01, -0.03, 0.0]], 0.3)
    u = np.array([5.0, 0.0, 1.0, 10.0, -20.0, 0.0])
    normals = []
    for v in ([0.3, 0.1, 0, 0, 0, 0], [-0.2, 0.5, 0, 0, 0, 0], [0.0, -0.4, 0, 0, 0, 0]):
        P, W = _setup(part, 0.4, u, np.array(v, float))
        sliding_accelerations(P, np.zeros(lay.AX_SIZE), 0.01, -0.02, 0.0, 0.0, 0.0, W, np.zeros((1, 6)), 0)
        normals.append(W[lay.W_N:lay.W_N + 3].copy())
    assert np.allclose(normals[0], normals[1]) and np.allclose(normals[0], normals[2])


def test_friction_that_flips_the_system_determinant_is_a_frictional_singularity():
    """Large mu h against a small contact base, contacts sliding in different directions (the part
    spinning about its centre): the triangle of the contacts shifted by mu h along their sliding
    directions turns over."""
    part = RigidPart(0.02, [1e-6, 1e-6, 1e-6], [[0.003, -0.003, -0.05], [0.0, 0.003, -0.05],
                                               [-0.003, -0.003, -0.05]], 2.0)
    hits = 0
    rng = np.random.default_rng(3)
    for _ in range(200):
        P, W = _setup(part, 0.0, np.zeros(6), np.zeros(6))
        V = rng.normal(scale=0.01, size=2)
        wz = rng.normal(scale=50.0)
        aux = np.zeros(lay.AX_SIZE)
        st = sliding_accelerations(P, aux, 0.01, -0.02, V[0], V[1], wz, W, np.zeros((1, 6)), 0)
        hits += st == FRICTIONAL_SINGULARITY
    assert hits > 0


def _best_ratio(rho, cap, req, rng):
    """min over force distributions of max_i |f_i| / cap_i, by Nelder-Mead on the null space."""
    B = np.zeros((3, 6))
    B[0, 0::2] = 1.0
    B[1, 1::2] = 1.0
    B[2, 0::2] = -rho[:, 1]
    B[2, 1::2] = rho[:, 0]
    f0 = np.linalg.lstsq(B, req, rcond=None)[0]
    Z = np.linalg.svd(B)[2][3:].T

    def worst(lam):
        f = f0 + Z @ lam
        return max(np.hypot(f[2 * i], f[2 * i + 1]) / cap[i] for i in range(3))

    opts = {"xatol": 1e-12, "fatol": 1e-12, "maxiter": 4000}
    return min(minimize(worst, rng.normal(scale=1e-3, size=3), method="Nelder-Mead", options=opts).fun
               for _ in range(3))


def test_the_sticking_test_finds_the_best_force_distribution():
    part = RigidPart(0.0216, [1.084e-5, 0.123e-5, 1.20e-5], [[0.01, -0.03, -0.002], [0.0, 0.03, -0.002],
                                                             [-0.01, -0.03, -0.002]], 0.3)
    rng = np.random.default_rng(11)
    for _ in range(12):
        u = rng.normal(scale=[2, 2, 2, 30, 30, 60])
        P, W = _setup(part, 0.5, u, np.zeros(6))
        fx, fy, tz, nmin = stick_forces(P, 0.01, -0.02, W, lay.W_U)
        assert nmin > 0
        ratio = stick_ratio(P, fx, fy, tz, W, False)
        cap = part.mu_static * W[lay.W_N:lay.W_N + 3]
        rho = np.column_stack([W[lay.W_RX:lay.W_RX + 3], W[lay.W_RY:lay.W_RY + 3]])
        ref = _best_ratio(rho, cap, [fx, fy, tz], rng)
        if ratio <= 0.5:        # the least-norm distribution already fits: an upper bound
            assert ref <= ratio * (1 + 1e-6)
        elif ratio > 1.0:       # cannot stick; a lower bound may be returned
            assert ref > 1.0 - 1e-6 and ratio <= ref * (1 + 2e-3)
        else:                   # solved exactly (the break-away test needs it precisely near 1)
            assert ratio == pytest.approx(ref, rel=2e-3)


def test_the_sticking_decision_stops_early_on_the_same_side_of_one_as_the_exact_ratio():
    """decide=True (the test after each step) may stop as soon as the side of 1 is certain; it must
    agree with the exact ratio there, also within 1e-9 of 1, and bound it from the right side."""
    part = RigidPart(0.0216, [1.084e-5, 0.123e-5, 1.20e-5], [[0.01, -0.03, -0.002], [0.0, 0.03, -0.002],
                                                             [-0.01, -0.03, -0.002]], 0.3)
    rng = np.random.default_rng(12)
    checked = 0
    for _ in range(40):
        u = rng.normal(scale=[2, 2, 2, 30, 30, 60])
        P, W = _setup(part, 0.5, u, np.zeros(6))
        fx, fy, tz, nmin = stick_forces(P, 0.01, -0.02, W, lay.W_U)
        exact = stick_ratio(P, fx, fy, tz, W, False)
        if not 0.5 < exact <= 1.0:
            continue        # outside the cone program (bounds or the least-norm distribution answer)
        for target in (0.7, 0.999, 1 - 1e-6, 1 - 1e-9, 1 + 1e-9, 1 + 1e-6, 1.001, 1.3):
            k = target / exact     # the ratio is homogeneous of degree 1 in the required wrench
            ref = stick_ratio(P, k * fx, k * fy, k * tz, W, False)
            got = stick_ratio(P, k * fx, k * fy, k * tz, W, True)
            assert (got <= 1.0) == (ref <= 1.0) == (target < 1.0)
            if got <= 1.0:
                assert got >= ref - 1e-12      # a feasible distribution: an upper bound
            else:
                assert got <= ref + 1e-12      # certified: a lower bound
            checked += 1
    assert checked >= 40

"""Synthetic plates for the control tests: a nominal model and a "true" plate that differs from it.

The nominal plant is a Stewart platform on flexures: six voice coils push along legs attached to the
plate; the plate (mass, inertia) sits on a suspension with resonances around 8-15 Hz, so at the
working frequencies the response is near the mass line with some phase. Its frequency response is
a callable ``response(freq_hz (K,)) -> (K, 6, 6)``, like the nominal model the project will provide.

The "true" plate has a gain and phase error, cross-coupling between actuators, and a third harmonic:
added (a fixed fraction of the fundamental) or made by a cubic coil nonlinearity.
"""

from __future__ import annotations

import numpy as np

MASS_KG = 2.0
INERTIA = np.diag([0.012, 0.012, 0.02])
FORCE_N_PER_A = 8.0
COIL_CORNER_HZ = 250.0


def _legs() -> np.ndarray:
    """Wrench (6, 6) per unit leg force: columns [u_j; b_j x u_j] of a hexapod in three leg pairs."""
    cols = []
    for j in range(6):
        centre = np.radians(120 * (j // 2) + 90)
        side = 1 if j % 2 else -1
        th = centre + side * np.radians(20)
        b = np.array([0.12 * np.cos(th), 0.12 * np.sin(th), -0.02])
        tangent = np.array([-np.sin(centre), np.cos(centre), 0.0])
        # The two legs of a pair lean towards each other along the pair's tangent (a classic hexapod).
        u = np.cos(np.radians(55)) * np.array([0, 0, 1.0]) - side * np.sin(np.radians(55)) * tangent
        cols.append(np.concatenate([u, np.cross(b, u)]))
    return np.array(cols).T


WRENCH = _legs()
M6 = np.block([[MASS_KG * np.eye(3), np.zeros((3, 3))], [np.zeros((3, 3)), INERTIA]])
STIFF = np.diag(M6.diagonal() * (2 * np.pi * np.array([8.0, 9.0, 12.0, 14.0, 15.0, 10.0])) ** 2)
DAMP = 0.04 * np.sqrt(STIFF * M6)


def nominal_response(freq_hz) -> np.ndarray:
    """G(f): acceleration phasors per coil-current phasor, shape (K, 6, 6)."""
    f = np.atleast_1d(np.asarray(freq_hz, float))
    out = []
    for fk in f:
        w = 2 * np.pi * fk
        coil = FORCE_N_PER_A / (1 + 1j * fk / COIL_CORNER_HZ)
        x = np.linalg.solve(STIFF + 1j * w * DAMP - w**2 * M6, WRENCH * coil)
        out.append(-(w**2) * x)
    return np.array(out)


def mismatched_response(gain=1.15, phase_deg=10.0, coupling=0.05, seed=0):
    """A true G(f) = gain e^{i phase} G_nom(f) (I + coupling X): X off-diagonal, random phases,
    scaled to spectral norm 1, so ``coupling`` is the size of the cross-coupling error."""
    rng = np.random.default_rng(seed)
    X = np.exp(1j * rng.uniform(0, 2 * np.pi, (6, 6)))
    np.fill_diagonal(X, 0)
    X /= np.linalg.norm(X, 2)
    mix = np.eye(6) + coupling * X
    factor = gain * np.exp(1j * np.radians(phase_deg))

    def response(freq_hz):
        return factor * nominal_response(freq_hz) @ mix

    return response


SCALE = np.array([1, 1, 1, 0.1, 0.1, 0.1])  # the error measure's scaling (L = 0.1 m)


class SyntheticPlate:
    """The true plate: coil currents (harmonics 1..Kc) -> plate acceleration phasors (harmonics 1..Kout).

    Two ways to add a third harmonic:

    - ``third`` (additive): the plate adds ``third`` times its fundamental, turned by a fixed random
      unitary map (in the error measure's scaled units), to its third harmonic, whatever the drive:
      exactly "an added third harmonic" of that fraction;
    - ``beta`` (cubic coils, 1/A^2): each coil's force follows i + beta i^3 (a Hammerstein model):
      it also mixes harmonics, e.g. cancelling the third harmonic makes a small fifth.
    """

    def __init__(
        self,
        response,
        frequency_hz: float,
        beta: float = 0.0,
        harmonics_out: int = 6,
        third: float = 0.0,
        seed: int = 1,
    ):
        self.response = response
        self.frequency_hz = frequency_hz
        self.beta = beta
        self.kout = harmonics_out
        q, _ = np.linalg.qr(
            np.random.default_rng(seed).normal(size=(6, 6))
            + 1j * np.random.default_rng(seed + 1).normal(size=(6, 6))
        )
        self.third_map = third * (q / SCALE[:, None]) * SCALE[None, :]

    def forces(self, currents_a: np.ndarray) -> np.ndarray:
        """Harmonics 1..Kout (Kout, 6) of i + beta i^3 per coil, by FFT over one period."""
        I = np.asarray(currents_a, complex)
        M = 128
        phase = 2 * np.pi * np.outer(np.arange(M) / M, np.arange(1, I.shape[0] + 1))
        i_t = np.imag(np.exp(1j * phase) @ I)  # (M, 6)
        f_t = i_t + self.beta * i_t**3
        ks = np.arange(1, self.kout + 1)
        c = np.exp(-2j * np.pi * np.outer(ks, np.arange(M) / M)) @ f_t / M
        return 2j * c

    def accel(self, currents_a: np.ndarray) -> np.ndarray:
        """Plate acceleration phasors (Kout, 6) on harmonics 1..Kout."""
        F = self.forces(currents_a)
        G = self.response(np.arange(1, self.kout + 1) * self.frequency_hz)
        A = np.einsum("kij,kj->ki", G, F)
        A[2] += self.third_map @ A[0]
        return A

    def calibrate_third_harmonic(self, currents_a: np.ndarray, fraction: float) -> None:
        """Choose beta so the accel's 3rd harmonic is ``fraction`` of the fundamental (norms, L = 0.1)."""
        self.beta = 1e-3
        for _ in range(3):  # the ratio is nearly linear in beta for small beta
            a = self.accel(currents_a)
            ratio = np.linalg.norm(a[2] * SCALE) / np.linalg.norm(a[0] * SCALE)
            self.beta *= fraction / ratio

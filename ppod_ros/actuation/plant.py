"""The nominal plant: the plate on its flexure legs, driven by six voice coils, linearised at home.

Model (docs/device.md has the derivation). Generalised coordinates q = [p, phi] (displacement of
the plate origin P, base frame, and small rotation), leg displacements delta = J q with J the leg
Jacobian at home (:class:`ppod_ros.kinematics.StewartKinematics`):

    M q'' + C q' + K q = J^T (k_f i) + f_d            plate (mass matrix about P) + coil moving masses
    L i' = V - R i - k_b J q' + v_d                    coil circuit with back-EMF
    V = k_p (i_cmd - i) + k_i z,   z' = i_cmd - i       the amplifier's PI current loop

with M = M_plate + m_c J^T J, C = c J^T J, K = k J^T J, k_p = L w_c and k_i = R w_c (the loop
cancels the coil's L/R pole: without back-EMF, i / i_cmd = w_c / (s + w_c)). ``f_d`` (generalised
force) and ``v_d`` (coil voltage) are disturbance inputs: the simulated device feeds its
second-order geometric terms through them.

The state is x = [q, q', i, z] (24) and the input u = [i_cmd, f_d, v_d] (18). The device's command
unit is the coil-current reference i_cmd (A); :meth:`NominalPlant.frequency_response` maps its six
phasors to the plate acceleration phasors [p''x, p''y, p''z, alpha_x, alpha_y, alpha_z] (PHYSICS.md
convention, u(t) = Im(X e^{i k Omega t})).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ppod_ros.device.config import DeviceConfig, PlateParams
from ppod_ros.errors import ConfigError
from ppod_ros.kinematics.stewart import StewartKinematics, skew
from ppod_ros.motion import PlateMotion

NX = 24
NU = 18
OUTPUTS = ("accel", "pose", "leg", "current", "voltage")


def rigid_body_mass_matrix(plate: PlateParams) -> np.ndarray:
    """6x6 mass matrix about the plate origin P for accelerations [p'', alpha], plate axes.

    ``[[m I, -m [c]x], [m [c]x, I_c - m [c]x [c]x]]`` with c the centre of mass in the plate frame.
    """
    m = plate.mass_kg
    S = skew(plate.com_m)
    M = np.zeros((6, 6))
    M[:3, :3] = m * np.eye(3)
    M[:3, 3:] = -m * S
    M[3:, :3] = m * S
    M[3:, 3:] = plate.inertia_kgm2 - m * S @ S
    return M


@dataclass(frozen=True)
class Mode:
    """One mechanical mode of the nominal plant (coil currents held by the current loop)."""

    frequency_hz: float  # undamped natural frequency
    damping_ratio: float


#: Sets of frequencies whose state-space solve :meth:`NominalPlant.responses` remembers.
_SOLVED_CACHE = 64


class NominalPlant:
    """The linear nominal model of the device (see the module docstring).

    Parameters
    ----------
    config : DeviceConfig

    Attributes
    ----------
    A : ndarray, shape (24, 24); B : ndarray, shape (24, 18)
        Continuous-time state space, x' = A x + B u.
    J : ndarray, shape (6, 6)
        Leg Jacobian at the home pose.
    M, C, K : ndarray, shape (6, 6)
        Mass, damping and stiffness matrices in q = [p, phi].
    """

    def __init__(self, config: DeviceConfig):
        self.config = config
        self._solved: dict[tuple, np.ndarray] = {}   # responses(): (s I - A)^-1 B per set of frequencies
        self._derived: dict[tuple, np.ndarray] = {}  # responses() per output, inverse_response(), from them
        a = config.actuators
        fl = config.flexures
        self.kinematics = StewartKinematics(config.geometry)
        J = self.kinematics.jacobian()
        self.J = J
        JtJ = J.T @ J
        self.M = rigid_body_mass_matrix(config.plate) + a.moving_mass_kg * JtJ
        self.C = fl.leg_damping_n_s_per_m * JtJ
        self.K = fl.leg_stiffness_n_per_m * JtJ
        wc = 2 * math.pi * a.current_loop_bandwidth_hz
        self.kp = a.inductance_h * wc
        self.ki = a.resistance_ohm * wc
        Minv = np.linalg.inv(self.M)
        I6 = np.eye(6)
        A = np.zeros((NX, NX))
        B = np.zeros((NX, NU))
        q, v, i, z = slice(0, 6), slice(6, 12), slice(12, 18), slice(18, 24)
        A[q, v] = I6
        A[v, q] = -Minv @ self.K
        A[v, v] = -Minv @ self.C
        A[v, i] = Minv @ J.T * a.force_constant_n_per_a
        B[v, 6:12] = Minv
        L = a.inductance_h
        A[i, v] = -a.back_emf_v_s_per_m * J / L
        A[i, i] = -(a.resistance_ohm + self.kp) / L * I6
        A[i, z] = self.ki / L * I6
        B[i, 0:6] = self.kp / L * I6
        B[i, 12:18] = I6 / L
        A[z, i] = -I6
        B[z, 0:6] = I6
        A.flags.writeable = B.flags.writeable = False   # fixed: responses() remembers its solves
        self.A, self.B = A, B
        self._outputs = self._output_maps()

    def _output_maps(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Output equations y = Cx + Du for each named output (all shape (6, ...))."""
        out = {}
        Cacc = self.A[6:12]
        Dacc = self.B[6:12]
        out["accel"] = (Cacc, Dacc)
        Cpose = np.zeros((6, NX))
        Cpose[:, 0:6] = np.eye(6)
        out["pose"] = (Cpose, np.zeros((6, NU)))
        out["leg"] = (self.J @ Cpose, np.zeros((6, NU)))
        Ccur = np.zeros((6, NX))
        Ccur[:, 12:18] = np.eye(6)
        out["current"] = (Ccur, np.zeros((6, NU)))
        Cv = np.zeros((6, NX))
        Cv[:, 12:18] = -self.kp * np.eye(6)
        Cv[:, 18:24] = self.ki * np.eye(6)
        Dv = np.zeros((6, NU))
        Dv[:, 0:6] = self.kp * np.eye(6)
        out["voltage"] = (Cv, Dv)
        return out

    def output_matrices(self, output: str) -> tuple[np.ndarray, np.ndarray]:
        """(C, D) of a named output: accel, pose, leg, current or voltage."""
        if output not in self._outputs:
            raise ConfigError(f"output: expected one of {', '.join(OUTPUTS)}, got {output!r}")
        return self._outputs[output]

    # ------------------------------------------------------------------ frequency domain
    @staticmethod
    def _freqs(freq_hz) -> np.ndarray:
        f = np.asarray(freq_hz, dtype=float)
        if not np.all(np.isfinite(f)) or np.any(f <= 0):
            raise ConfigError(f"freq_hz: frequencies must be finite and > 0 Hz, got {np.ravel(f).tolist()}")
        return f

    def response(self, freq_hz, output: str = "accel") -> np.ndarray:
        """Frequency response from the six current references (A) to a named output, (..., 6, 6).

        ``accel``: plate acceleration [p'', alpha] (m/s^2, rad/s^2); ``pose``: [p, phi] (m, rad);
        ``leg``: leg displacements (m); ``current``: coil currents (A); ``voltage``: amplifier
        output voltages (V).
        """
        return self.responses(freq_hz, (output,))[output]

    def responses(self, freq_hz, outputs: tuple[str, ...] = OUTPUTS) -> dict[str, np.ndarray]:
        """Frequency responses of several outputs from one solve: {name: (..., 6, 6)}.

        The solve is remembered per set of frequencies (the checker asks for the same few harmonics
        of one frequency for every motion it checks); callers get their own copies."""
        f = self._freqs(freq_hz)
        key = (f.shape, f.tobytes())
        X = self._solved.get(key)
        if X is None:
            s = 2j * math.pi * f[..., None, None]
            X = np.linalg.solve(s * np.eye(NX) - self.A, np.broadcast_to(self.B[:, :6], f.shape + (NX, 6)))
            if len(self._solved) >= _SOLVED_CACHE:
                self._solved.clear()
                self._derived.clear()
            self._solved[key] = X
        out = {}
        for name in outputs:
            Y = self._derived.get((key, name))
            if Y is None:
                Cy, Dy = self.output_matrices(name)
                Y = Cy @ X + Dy[:, :6]
                Y.flags.writeable = False
                self._derived[(key, name)] = Y
            out[name] = Y.copy()
        return out

    def frequency_response(self, freq_hz) -> np.ndarray:
        """Coil-current phasors (A) -> plate acceleration phasors, complex (..., 6, 6).

        Rows: [p''x, p''y, p''z, alpha_x, alpha_y, alpha_z] (m/s^2, rad/s^2); columns: actuators.
        """
        return self.response(freq_hz, "accel")

    def inverse_response(self, freq_hz) -> np.ndarray:
        """Plate acceleration phasors -> coil-current phasors (A), the feed-forward map, (..., 6, 6)
        (remembered with the solve it inverts; callers get their own copies)."""
        f = self._freqs(freq_hz)
        key = ((f.shape, f.tobytes()), None)
        Ginv = self._derived.get(key)
        if Ginv is None:
            Ginv = np.linalg.inv(self.frequency_response(f))
            Ginv.flags.writeable = False
            self._derived[key] = Ginv
        return Ginv.copy()

    def feedforward(self, motion: PlateMotion, kmax: int | None = None) -> np.ndarray:
        """Coil-current phasors (A) that make the nominal plant follow ``motion``.

        Returns
        -------
        complex ndarray, shape (kmax, 6)
            Row k-1 is harmonic k (default kmax: the motion's highest harmonic); harmonics the
            motion lacks are zero.
        """
        top = int(motion.k.max()) if motion.num_harmonics else 0
        kmax = top if kmax is None else int(kmax)
        if kmax < top:
            raise ConfigError(f"kmax: the table must hold the motion's harmonics up to {top}, got {kmax}")
        X = motion.phasor_table(kmax)  # (kmax, 6)
        out = np.zeros((kmax, 6), dtype=complex)
        rows = np.flatnonzero(np.any(X != 0, axis=1))
        if rows.size:
            Ginv = self.inverse_response(motion.frequency_hz * (rows + 1))
            out[rows] = np.einsum("kij,kj->ki", Ginv, X[rows])
        return out

    def predict(self, frequency_hz: float, currents: np.ndarray, output: str = "accel") -> np.ndarray:
        """Steady-state phasors of a named output for a current table (dense harmonics 1..K), (K, 6)."""
        return self.predict_all(frequency_hz, currents, (output,))[output]

    def predict_all(
        self, frequency_hz: float, currents: np.ndarray, outputs: tuple[str, ...] = OUTPUTS
    ) -> dict[str, np.ndarray]:
        """Steady-state phasors of several outputs for a current table (K, 6): {name: (K, 6)}."""
        currents = np.asarray(currents, dtype=complex)
        if currents.ndim != 2 or currents.shape[1] != 6:
            raise ConfigError(
                f"currents: expected shape (K, 6) of coil-current phasors (A), got {currents.shape}"
            )
        K = currents.shape[0]
        if K == 0:
            return {name: np.zeros((0, 6), dtype=complex) for name in outputs}
        G = self.responses(frequency_hz * np.arange(1, K + 1), outputs)
        return {name: np.einsum("kij,kj->ki", g, currents) for name, g in G.items()}

    # ------------------------------------------------------------------ modes
    def modes(self) -> list[Mode]:
        """Mechanical modes (lightly damped poles below the current loop), sorted by frequency."""
        lam = np.linalg.eigvals(self.A)
        wc = 2 * math.pi * self.config.actuators.current_loop_bandwidth_hz
        mech = lam[(lam.imag > 0) & (np.abs(lam) < 0.5 * wc)]
        modes = [Mode(float(abs(p) / (2 * math.pi)), float(-p.real / abs(p))) for p in mech]
        return sorted(modes, key=lambda m: m.frequency_hz)


__all__ = ["Mode", "NX", "NU", "NominalPlant", "OUTPUTS", "rigid_body_mass_matrix"]

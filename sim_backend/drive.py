"""The simulated actuators' imperfections: how the played current differs from the commanded one.

The host plans with the nominal plant. The simulated device deliberately differs from it
(``sim.mismatch`` in the device YAML), in the drive path of each voice coil:

* gain and phase errors per actuator, drawn uniformly within +-``gain`` and +-``phase_deg``;
* cross-coupling between actuators, off-diagonal entries drawn within +-``coupling``;
* a nonlinearity that adds ``third_harmonic`` times each actuator's harmonic-k current at 3k, with
  the phase a compressive cubic characteristic gives (a few percent, as real plates show).

All draws come from the simulation seed; with every setting zero the drive is exact. The errors act
on the harmonic table, so they are the same at every frequency: gain/phase errors of the actuator,
amplifier and linkage lumped into one complex factor per actuator.
"""

from __future__ import annotations

import math

import numpy as np

from ppod_ros.device.config import Mismatch

#: Harmonics the played (distorted) table can hold: 3 x the protocol's 10.
MAX_PLAYED_HARMONIC = 30


class ActuatorDrive:
    """Maps a commanded current table to the current references the coils actually follow.

    Parameters
    ----------
    mismatch : Mismatch
    rng : numpy.random.Generator
        Source of the per-actuator draws (deterministic under the simulation seed).

    Attributes
    ----------
    matrix : complex ndarray, shape (6, 6)
        Played = matrix @ commanded, per harmonic (identity without mismatch).
    """

    def __init__(self, mismatch: Mismatch, rng: np.random.Generator):
        self.mismatch = mismatch
        gain = 1.0 + rng.uniform(-mismatch.gain, mismatch.gain, 6)
        phase = np.deg2rad(rng.uniform(-mismatch.phase_deg, mismatch.phase_deg, 6))
        coupling = rng.uniform(-mismatch.coupling, mismatch.coupling, (6, 6))
        np.fill_diagonal(coupling, 0.0)
        self.matrix = np.diag(gain * np.exp(1j * phase)) @ (np.eye(6) + coupling)
        self.third_harmonic = mismatch.third_harmonic

    def played(self, table: np.ndarray) -> np.ndarray:
        """The played table for a commanded dense table (K, 6), shape (MAX_PLAYED_HARMONIC, 6).

        Row k-1 is harmonic k; rows above K hold the nonlinearity's harmonics.
        """
        table = np.asarray(table, dtype=complex)
        out = np.zeros((MAX_PLAYED_HARMONIC, 6), dtype=complex)
        K = table.shape[0]
        lin = table @ self.matrix.T
        out[:K] = lin
        if self.third_harmonic:
            mag2 = np.abs(lin) ** 2
            safe = np.where(mag2 > 0, mag2, 1.0)
            distortion = np.where(mag2 > 0, self.third_harmonic * lin**3 / safe, 0.0)
            for k in range(1, K + 1):
                if 3 * k <= MAX_PLAYED_HARMONIC:
                    out[3 * k - 1] += distortion[k - 1]
        return out

    def describe(self) -> str:
        g = np.abs(np.diag(self.matrix))
        p = np.rad2deg(np.angle(np.diag(self.matrix)))
        return (
            f"gain {np.round(g, 3).tolist()}, phase {np.round(p, 2).tolist()} deg, coupling up to "
            f"{self.mismatch.coupling:g}, third harmonic {self.third_harmonic:g}"
        )


def ramp_shape(fraction: np.ndarray) -> np.ndarray:
    """Raised cosine from 0 to 1 over fraction in [0, 1]: no step in value or slope."""
    f = np.clip(fraction, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(math.pi * f)


__all__ = ["ActuatorDrive", "MAX_PLAYED_HARMONIC", "ramp_shape"]

"""A closed-loop test rig: synthetic plate -> exact accelerometer readings with noise -> estimator.

``Rig.measure(correction)`` applies feed-forward plus correction to the true plate, simulates the
default accelerometer layout with the rigid-body oracle (tests/estimation/plate_sim.py), adds noise
and returns the estimator's PlateEstimate: the same path the feedback node will take on the device.
Every command the rig receives is kept, so tests can check that none exceeded the limits.
"""

from __future__ import annotations

import numpy as np

from ppod_ros.estimation import AccelerometerLayout, AccelEstimator
from tests.control.synthetic_plant import SyntheticPlate
from tests.estimation.plate_sim import readings, sample_times

LAYOUT = AccelerometerLayout.default()
NOISE_MPS2 = 0.1
RATE_HZ = 5000.0


class Rig:
    def __init__(
        self,
        plate: SyntheticPlate,
        feedforward_a: np.ndarray,
        *,
        cycles: float = 10,
        seed: int = 0,
        noise_mps2: float = NOISE_MPS2,
    ):
        self.plate = plate
        self.feedforward_a = np.asarray(feedforward_a, complex)
        self.t = sample_times(plate.frequency_hz, cycles, RATE_HZ)
        self.t_identify = sample_times(plate.frequency_hz, 4, RATE_HZ)  # small steps, shorter windows
        self.rng = np.random.default_rng(seed)
        self.noise = noise_mps2
        self.estimator = AccelEstimator(LAYOUT, harmonics=plate.kout)
        self.commands: list[np.ndarray] = []
        self.truth: list[np.ndarray] = []
        self.records: list[tuple[np.ndarray, np.ndarray]] = []  # (time_s, readings) per measurement

    def accel_of(self, currents_a: np.ndarray, t: np.ndarray | None = None):
        """Estimate of the plate's acceleration under coil currents (K, 6) on harmonics 1..K."""
        t = self.t if t is None else t
        currents_a = np.asarray(currents_a, complex)
        self.commands.append(currents_a.copy())
        A = self.plate.accel(currents_a)
        self.truth.append(A)
        K = self.plate.kout
        r = readings(A, np.arange(1, K + 1), self.plate.frequency_hz, t, LAYOUT.position_m, LAYOUT.axis)
        r = r + self.rng.normal(0.0, self.noise, r.shape)
        self.records.append((t, r))
        return self.estimator.from_samples(t, r, self.plate.frequency_hz)

    def measure(self, correction_a: np.ndarray):
        return self.accel_of(self.feedforward_a + correction_a)

    def measure_step(self, step):
        """For identification: the step's currents alone (on the plan's harmonics 1..K)."""
        return self.accel_of(step.command_a, self.t_identify)

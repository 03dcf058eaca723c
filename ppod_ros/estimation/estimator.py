"""Accelerometer estimation entry points: raw samples, harmonic summaries, recordings.

:class:`AccelEstimator` turns raw samples (fitted per channel by
:func:`~ppod_ros.estimation.harmonic_fit.fit_harmonics`) or per-channel harmonic summaries (phasors
per channel and harmonic, as a device DSP sends them) into the plate's acceleration phasors
``U_k = [p''x, p''y, p''z, alpha_x, alpha_y, alpha_z]`` per harmonic. Each entry point checks its own
kind of data for unusable and suspect channels; the least-squares solve over channels, the removal
of the tilted-gravity and second-order terms, and the channel rejection are
:class:`~ppod_ros.estimation.six_dof.SixDofSolver`'s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.estimation.acquisition import check_samples_alive, check_summaries_alive
from ppod_ros.estimation.calibration import AccelCalibration
from ppod_ros.estimation.harmonic_fit import HealthSettings, fit_harmonics
from ppod_ros.estimation.layout import AccelerometerLayout
from ppod_ros.estimation.recording import AccelRecording
from ppod_ros.estimation.second_order import SECOND_ORDER_TERMS, check_terms
from ppod_ros.estimation.six_dof import EstimationError, PlateEstimate, SixDofSolver
from ppod_ros.motion import GRAVITY_MPS2, MAX_HARMONIC


class AccelEstimator:
    """Estimate the plate's acceleration harmonics from an accelerometer layout's channels.

    Parameters
    ----------
    layout : AccelerometerLayout
    harmonics : int
        K: harmonics 1..K are fitted to raw samples and estimated. Choose at least twice the
        highest harmonic the plate moves at, so the second-order terms are fitted, not leaked.
    second_order_terms : tuple of str
        Second-order terms to remove (default all of :data:`SECOND_ORDER_TERMS`; empty: pure first
        order). ``gravity_mps2 = 0`` removes the tilted-gravity term from the model.
    max_iterations, tolerance : int, float
        Second-order correction passes; stop when the relative change falls below ``tolerance``.
    health : HealthSettings
        Channel-check thresholds.
    calibration : AccelCalibration, optional
        The device's array calibration (:mod:`~ppod_ros.estimation.calibration`): readings are
        divided by its gains, its axes replace the layout's, and each channel's misfit allowance
        is set from its measured misfit.
    misfit_allowance : array_like, shape (C,), optional
        Per-channel misfit allowance (fraction of each channel's reading), e.g. learned from
        operation (:meth:`~ppod_ros.estimation.misfit.MisfitHistory.allowance`); replaces the
        calibration's and the settings' default.
    """

    def __init__(
        self,
        layout: AccelerometerLayout,
        *,
        harmonics: int = 6,
        second_order_terms: Sequence[str] = SECOND_ORDER_TERMS,
        gravity_mps2: float = GRAVITY_MPS2,
        max_iterations: int = 8,
        tolerance: float = 1e-9,
        health: HealthSettings | None = None,
        calibration: AccelCalibration | None = None,
        misfit_allowance: np.ndarray | None = None,
    ):
        if not isinstance(layout, AccelerometerLayout):
            raise ConfigError(f"layout: expected an AccelerometerLayout, got {type(layout).__name__}")
        if not (isinstance(harmonics, (int, np.integer)) and 1 <= harmonics <= 4 * MAX_HARMONIC):
            raise ConfigError(f"harmonics: expected an integer in 1..{4 * MAX_HARMONIC}, got {harmonics!r}")
        if not (math.isfinite(gravity_mps2) and gravity_mps2 >= 0):
            raise ConfigError(f"gravity_mps2: must be finite and >= 0, got {gravity_mps2}")
        if not (isinstance(max_iterations, int) and max_iterations >= 1 and tolerance > 0):
            raise ConfigError("max_iterations must be an integer >= 1 and tolerance > 0")
        self.calibration = calibration
        self._gain = np.ones(layout.num_channels)
        allowance = None
        bending = None
        if calibration is not None:
            if not isinstance(calibration, AccelCalibration):
                raise ConfigError(f"calibration: expected an AccelCalibration, got {type(calibration).__name__}")
            layout = calibration.layout(layout)
            self._gain = np.asarray(calibration.gain, float)
            allowance = calibration.misfit_allowance()
            bending = calibration.bending_weights()
        if misfit_allowance is not None:
            allowance = misfit_allowance
        self.layout = layout
        self.harmonics = int(harmonics)
        self.terms = check_terms(second_order_terms)
        self.gravity_mps2 = float(gravity_mps2)
        self.max_iterations = max_iterations
        self.tolerance = float(tolerance)
        self.health = health or HealthSettings()
        self._solver = SixDofSolver(
            layout, self.terms, self.gravity_mps2, self.health, max_iterations, self.tolerance, allowance, bending
        )

    # ------------------------------------------------------------------ entry points
    def from_samples(
        self,
        time_s: np.ndarray,
        samples_mps2: np.ndarray,
        frequency_hz: float,
        channels: Sequence[str] | None = None,
    ) -> PlateEstimate:
        """Estimate from raw samples.

        Parameters
        ----------
        time_s : array_like, shape (N,) or (N, C)
            Sample times (s) from a device cycle start (t = 0 at a cycle boundary).
        samples_mps2 : array_like, shape (N, C)
            Readings (m/s^2), NaN for missing samples; columns in the order of ``channels``.
        frequency_hz : float
        channels : sequence of str, optional
            Layout channel names of the columns (default: the layout's order, all channels).
        """
        idx = self._columns(channels, np.shape(samples_mps2)[-1] if np.ndim(samples_mps2) == 2 else -1)
        check_samples_alive(samples_mps2, [self.layout.names[i] for i in idx])
        fit = fit_harmonics(
            time_s,
            np.asarray(samples_mps2, dtype=float) / self._gain[idx],
            frequency_hz,
            self.harmonics,
            full_scale_mps2=self.layout.full_scale_mps2[idx] / self._gain[idx],
            health=self.health,
        )
        return self._solver.solve(
            idx,
            fit.k,
            fit.phasors,
            fit.variance,
            float(frequency_hz),
            list(fit.fatal),
            list(fit.suspect),
            fit.cycles,
        )

    def from_cycle(self, samples_mps2: np.ndarray, sample_rate_hz: float, cycles: int = 1,
                   channels: Sequence[str] | None = None) -> PlateEstimate:
        """Estimate from whole saved cycles sampled evenly from a cycle start.

        The plate's frequency is the data's own, ``cycles * sample_rate_hz / N`` (a lab that saves one
        cycle of 263 samples at 10 kHz ran at 38.02 Hz, not its nominal 38 Hz: fitting the nominal
        frequency would leak 0.2-0.6 % of the signal into the wrong phases).

        Parameters
        ----------
        samples_mps2 : array_like, shape (N, C)
        sample_rate_hz : float
        cycles : int
            Whole plate cycles the N samples span.
        """
        n = np.shape(samples_mps2)[0] if np.ndim(samples_mps2) == 2 else 0
        if not (np.isfinite(sample_rate_hz) and sample_rate_hz > 0):
            raise ConfigError(f"sample_rate_hz: must be a finite number > 0 Hz, got {sample_rate_hz}")
        if not (isinstance(cycles, (int, np.integer)) and cycles >= 1):
            raise ConfigError(f"cycles: expected an integer >= 1, got {cycles!r}")
        if n < 2:
            raise ConfigError(f"samples_mps2: expected shape (N >= 2, C), got {np.shape(samples_mps2)}")
        t = np.arange(n) / float(sample_rate_hz)
        return self.from_samples(t, samples_mps2, cycles * float(sample_rate_hz) / n, channels=channels)

    def from_summaries(
        self,
        k: Sequence[int],
        phasors: np.ndarray,
        frequency_hz: float,
        *,
        variance: np.ndarray | None = None,
        faulty: np.ndarray | None = None,
        channels: Sequence[str] | None = None,
    ) -> PlateEstimate:
        """Estimate from per-channel harmonic summaries.

        Parameters
        ----------
        k : sequence of int, length K
            Harmonics of the summaries (ascending, >= 1; need not be contiguous).
        phasors : complex array_like, shape (K, C) or (cycles, K, C)
            Per-channel phasors (m/s^2), one summary or one per cycle; NaN where a cycle's summary
            of a channel is missing. Several cycles are averaged, and their scatter is the noise.
        variance : array_like, shape (K, C), optional
            Noise variance of the (averaged) phasors, when the device reports it.
        faulty : bool array_like, shape (C,) or (cycles, C), optional
            Device-side fault flags (saturated, overrun): a flagged cycle is ignored.
        """
        ks = np.asarray(k)
        if (
            ks.ndim != 1
            or ks.size == 0
            or ks.dtype.kind not in "iu"
            or np.any(ks < 1)
            or np.any(np.diff(ks) <= 0)
        ):
            raise ConfigError(
                f"k: expected ascending distinct harmonic numbers >= 1, got {np.asarray(k).tolist()}"
            )
        P = np.asarray(phasors, dtype=complex)
        if P.ndim == 2:
            P = P[None]
        if P.ndim != 3 or P.shape[1] != ks.size:
            raise ConfigError(
                f"phasors: expected shape (K={ks.size}, C) or (cycles, K, C), got {np.shape(phasors)}"
            )
        n_cyc, K, C = P.shape
        idx = self._columns(channels, C)
        check_summaries_alive(P, [self.layout.names[i] for i in idx])
        P = P / self._gain[idx]
        if faulty is not None:
            flags = np.asarray(faulty, dtype=bool)
            flags = np.broadcast_to(flags if flags.ndim == 2 else flags[None], (n_cyc, C))
            P = np.where(flags[:, None, :], np.nan, P)
        good = np.all(np.isfinite(P), axis=1)  # (cycles, C): a cycle counts only if every harmonic came
        fatal: list[str | None] = [None] * C
        suspect: list[str | None] = [None] * C
        n_good = good.sum(axis=0)
        for c in range(C):
            if n_good[c] < max(1, math.ceil(self.health.min_valid_fraction * n_cyc)):
                fatal[c] = f"missing: {n_good[c]} of {n_cyc} cycle summaries valid"
        Pm = np.where(good[:, None, :], P, 0)
        Y = Pm.sum(axis=0) / np.maximum(n_good, 1)
        if variance is not None:
            var = np.asarray(variance, dtype=float)
            if var.shape != (K, C) or np.any(~np.isfinite(var)) or np.any(var < 0):
                raise ConfigError(
                    f"variance: expected finite values >= 0 of shape ({K}, {C}), got shape {var.shape}"
                )
            var = var / self._gain[idx] ** 2
        elif n_cyc >= 2:
            dev = np.where(good[:, None, :], np.abs(P - Y) ** 2, 0).sum(axis=0)
            var = dev / np.maximum(n_good - 1, 1) / np.maximum(n_good, 1)
        else:
            var = np.zeros((K, C))
        for c in range(C):
            if fatal[c] is not None:
                Y[:, c] = np.nan
                continue
            rows = P[good[:, c], :, c]
            if np.all(np.abs(rows) <= self.health.flat_mps2):
                suspect[c] = "flat: all harmonics zero"
            elif rows.shape[0] >= 3 and np.all(rows == rows[0]):
                suspect[c] = f"stuck: {rows.shape[0]} identical cycle summaries"
        if variance is None and n_cyc >= 3:
            # A channel whose summaries wander far more from cycle to cycle than the others' is
            # failing (intermittent, dying): suspect, like a raw channel that is not periodic.
            spread = np.sqrt(var.sum(axis=0))
            alive = [c for c in range(C) if fatal[c] is None]
            typical = float(np.median(spread[alive])) if alive else 0.0
            limit = max(self.health.fit_residual_ratio * typical, self.health.flat_mps2)
            for c in alive:
                if suspect[c] is None and spread[c] > limit:
                    ratio = spread[c] / max(typical, 1e-300)
                    suspect[c] = f"not steady: cycle-to-cycle scatter {ratio:.0f}x the median channel's"
        return self._solver.solve(idx, ks, Y, var, float(frequency_hz), fatal, suspect, float(np.max(n_good)))

    def from_recording(self, recording: AccelRecording, segment: int | None = None) -> PlateEstimate:
        """Estimate one segment of a recording (raw samples or summaries); default: its only segment."""
        if segment is None:
            segs = recording.segments()
            if len(segs) != 1:
                raise ConfigError(f"recording has segments {segs}: name one with segment=")
            segment = segs[0]
        if segment not in recording.segments():
            raise ConfigError(f"segment: {segment} is not in the recording's segments {recording.segments()}")
        a, b = recording.segment_data(segment)
        if recording.kind == "samples":
            return self.from_samples(a, b, recording.frequency_hz, channels=recording.channels)
        return self.from_summaries(a, b, recording.frequency_hz, channels=recording.channels)

    # ------------------------------------------------------------------ solve
    def _columns(self, channels: Sequence[str] | None, C: int) -> np.ndarray:
        if channels is None:
            if self.layout.num_channels != C:
                raise ConfigError(
                    f"data has {C} channel columns but the layout has {self.layout.num_channels}; "
                    f"pass channels= to name them"
                )
            return np.arange(C)
        idx = self.layout.index(list(channels))
        if len(idx) != C or len(set(idx.tolist())) != C:
            raise ConfigError(f"channels: expected {C} distinct layout channel names, got {list(channels)}")
        return idx


__all__ = ["AccelEstimator", "EstimationError", "PlateEstimate"]

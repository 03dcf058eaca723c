"""6-DoF plate-acceleration harmonics from accelerometer channels.

:class:`AccelEstimator` turns either raw samples (fitted per channel by
:func:`~ppod_ros.estimation.harmonic_fit.fit_harmonics`) or per-channel harmonic summaries (phasors
per channel and harmonic, as a device DSP sends them) into the plate's acceleration phasors
``U_k = [p''x, p''y, p''z, alpha_x, alpha_y, alpha_z]`` per harmonic, by least squares over the
channels. Per harmonic the model is ``Y_k = H_k U_k + S_k(U)``: ``H_k`` is the layout's first-order
matrix with the tilted-gravity term of that harmonic, ``S_k`` the second-order terms
(:mod:`~ppod_ros.estimation.second_order`), which depend on the motion itself; they are removed by
iterating solve -> evaluate S at the estimate -> subtract -> solve again (a contraction: S is about
1% of the signal, so each pass gains about two digits).

Channels are checked before and during the solve: unusable ones are dropped, suspects (flat, stuck,
not periodic) are set aside and dropped only when the other channels predict a reading they do not
show, and a channel whose residual is inconsistent with the rest is dropped (worst first) while the
remaining channels still determine all six components. Otherwise :class:`EstimationError` says which
channels failed and which combination became unobservable.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ppod_ros.errors import ConfigError, DeviceError
from ppod_ros.estimation.harmonic_fit import HealthSettings, fit_harmonics
from ppod_ros.estimation.layout import AccelerometerLayout
from ppod_ros.estimation.recording import AccelRecording
from ppod_ros.estimation.second_order import SECOND_ORDER_TERMS, check_terms, second_order_phasors
from ppod_ros.motion import GRAVITY_MPS2, MAX_HARMONIC, PlateMotion

OK = "ok"


class EstimationError(DeviceError):
    """The healthy channels no longer determine the plate's acceleration.

    Attributes
    ----------
    channel_status : dict of str to str
        Every channel's status ("ok" or why it was dropped).
    """

    def __init__(self, message: str, channel_status: dict[str, str]):
        super().__init__(message)
        self.channel_status = dict(channel_status)


@dataclass(frozen=True)
class PlateEstimate:
    """Estimated plate-acceleration harmonics and how they were obtained.

    Attributes
    ----------
    frequency_hz : float
    k : ndarray of int, shape (K,)
        Harmonic numbers of the rows of ``phasors``.
    phasors : complex ndarray, shape (K, 6)
        U_k = [p''x, p''y, p''z, alpha_x, alpha_y, alpha_z] (m/s^2, rad/s^2), PHYSICS.md convention.
    std : ndarray, shape (K, 6)
        Standard deviation of each phasor from the channels' noise (0 where no noise is known).
    channels : tuple of str, length C
    status : tuple of str, length C
        "ok" or why the channel was dropped.
    residual_rms_mps2 : float
        RMS over used channels and harmonics of the least-squares residual phasors (m/s^2).
    residual_mps2 : ndarray, shape (K,)
        Residual norm over the used channels per harmonic (m/s^2).
    second_order_mps2 : ndarray, shape (K,)
        RMS over used channels of the second-order reading removed, per harmonic (m/s^2).
    iterations : int
        Solve passes of the second-order correction (of the final channel set).
    last_change : float
        Relative change of the estimate in the last pass (what the iteration leaves unconverged).
    cycles : float
        Periods of data behind the estimate (fractional for a partial cycle; the number of
        cycles averaged for summaries).
    """

    frequency_hz: float
    k: np.ndarray
    phasors: np.ndarray
    std: np.ndarray
    channels: tuple[str, ...]
    status: tuple[str, ...]
    residual_rms_mps2: float
    residual_mps2: np.ndarray
    second_order_mps2: np.ndarray
    iterations: int
    last_change: float
    cycles: float

    @property
    def used(self) -> np.ndarray:
        """Boolean mask (C,) of channels that entered the final solve."""
        return np.array([s == OK for s in self.status])

    @property
    def dropped(self) -> dict[str, str]:
        return {n: s for n, s in zip(self.channels, self.status) if s != OK}

    def table(self, kmax: int) -> np.ndarray:
        """Phasors on a dense harmonic axis 1..kmax (row k-1 = harmonic k), shape (kmax, 6)."""
        out = np.zeros((kmax, 6), dtype=complex)
        for row, k in enumerate(self.k):
            if k <= kmax:
                out[k - 1] = self.phasors[row]
        return out

    def motion(self, name: str = "measured") -> PlateMotion:
        """The estimate as a :class:`PlateMotion` (harmonics up to MAX_HARMONIC)."""
        keep = self.k <= MAX_HARMONIC
        return PlateMotion.from_phasors(self.frequency_hz, self.k[keep], self.phasors[keep], name=name)


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
    ):
        if not isinstance(layout, AccelerometerLayout):
            raise ConfigError(f"layout: expected an AccelerometerLayout, got {type(layout).__name__}")
        if not (isinstance(harmonics, (int, np.integer)) and 1 <= harmonics <= 4 * MAX_HARMONIC):
            raise ConfigError(f"harmonics: expected an integer in 1..{4 * MAX_HARMONIC}, got {harmonics!r}")
        if not (math.isfinite(gravity_mps2) and gravity_mps2 >= 0):
            raise ConfigError(f"gravity_mps2: must be finite and >= 0, got {gravity_mps2}")
        if not (isinstance(max_iterations, int) and max_iterations >= 1 and tolerance > 0):
            raise ConfigError("max_iterations must be an integer >= 1 and tolerance > 0")
        self.layout = layout
        self.harmonics = int(harmonics)
        self.terms = check_terms(second_order_terms)
        self.gravity_mps2 = float(gravity_mps2)
        self.max_iterations = max_iterations
        self.tolerance = float(tolerance)
        self.health = health or HealthSettings()

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
        fit = fit_harmonics(
            time_s,
            samples_mps2,
            frequency_hz,
            self.harmonics,
            full_scale_mps2=self.layout.full_scale_mps2[idx],
            health=self.health,
        )
        return self._solve(
            idx,
            fit.k,
            fit.phasors,
            fit.variance,
            float(frequency_hz),
            list(fit.fatal),
            list(fit.suspect),
            fit.cycles,
        )

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
        return self._solve(idx, ks, Y, var, float(frequency_hz), fatal, suspect, float(np.max(n_good)))

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

    def _solve(
        self,
        idx: np.ndarray,
        ks: np.ndarray,
        Y: np.ndarray,
        var: np.ndarray,
        freq_hz: float,
        fatal: list[str | None],
        suspect: list[str | None],
        cycles: float,
    ) -> PlateEstimate:
        if not (math.isfinite(freq_hz) and freq_hz > 0):
            raise ConfigError(f"frequency_hz: must be a finite number > 0 Hz, got {freq_hz}")
        ks = np.asarray(ks, dtype=int)
        names = tuple(self.layout.names[i] for i in idx)
        omega = 2 * math.pi * freq_hz
        H = np.stack(
            [self.layout.measurement_matrix(omega * k, self.gravity_mps2)[idx] for k in ks]
        )  # (K, C, 6)
        pos, ax = self.layout.position_m[idx], self.layout.axis[idx]
        thr = self.health.residual_threshold
        status: list[str] = [OK if f is None else f for f in fatal]
        usable = np.array([s == OK for s in status])
        pending = {c: suspect[c] for c in np.flatnonzero(usable) if suspect[c] is not None}
        use = usable.copy()
        use[list(pending)] = False
        verify = bool(pending) and self._determined(idx, use)
        if not verify:
            # The channels above suspicion cannot determine the motion: suspects must take part,
            # and are accepted only if every channel then fits consistently.
            use, unverified, pending = usable.copy(), dict(pending), {}
        self._require(idx, use, names, status, "before any residual test")
        U = np.zeros((ks.size, 6), dtype=complex)
        while True:
            U, S, iters, change, P = self._second_order_solve(U, ks, Y, H, use, freq_hz, pos, ax)
            Yc = Y - S
            R = Yc - np.einsum("kcj,kj->kc", H, U)
            scale2 = self._scale2(Y, var, use)
            # Suspects, out of sample: dropped if the others predict a reading they do not show.
            admitted = False
            for c, why in list(pending.items()):
                z = math.sqrt(np.sum(np.abs(R[:, c]) ** 2) / np.sum(scale2[:, c]))
                del pending[c]
                if z > thr:
                    status[c] = f"{why}; inconsistent with the other channels (residual {z:.1f} sigma)"
                else:
                    use[c] = admitted = True
            if admitted:
                continue
            z_in = self._studentized(H, P, R, scale2, use)
            if not verify and unverified and z_in.max() > thr:
                bad = ", ".join(f"{names[c]} ({why})" for c, why in unverified.items())
                raise EstimationError(
                    f"accelerometer channels {bad} look dead, and the other channels cannot determine the "
                    f"plate acceleration to check them; the readings are inconsistent "
                    f"(residual {z_in.max():.1f} sigma at {names[int(np.argmax(z_in))]})",
                    dict(zip(names, status)),
                )
            worst, z_out = self._leave_one_out(idx, H, Yc, scale2, use)
            if worst is not None and z_out > thr:
                use[worst] = False
                status[worst] = f"inconsistent residual ({z_out:.1f} sigma)"
                continue
            # Leave-one-out found nobody to blame; an inconsistency left is in a channel the layout
            # cannot spare (it could not be left out), so the estimate cannot be trusted.
            for c in np.flatnonzero(z_in > thr):
                rest = use.copy()
                rest[c] = False
                if not self._determined(idx, rest):
                    status[c] = f"inconsistent residual ({z_in[c]:.1f} sigma)"
                    self._require(
                        idx,
                        rest,
                        names,
                        status,
                        "after a channel the layout cannot spare became inconsistent",
                    )
            break
        std = np.sqrt(np.einsum("kjc,kc->kj", np.abs(P) ** 2, np.where(use, np.nan_to_num(var), 0.0)))
        Ru = R[:, use]
        return PlateEstimate(
            frequency_hz=freq_hz,
            k=ks.copy(),
            phasors=U,
            std=std,
            channels=names,
            status=tuple(status),
            residual_rms_mps2=float(np.sqrt(np.mean(np.abs(Ru) ** 2))),
            residual_mps2=np.linalg.norm(Ru, axis=1),
            second_order_mps2=np.sqrt(np.mean(np.abs(S[:, use]) ** 2, axis=1)),
            iterations=iters,
            last_change=change,
            cycles=cycles,
        )

    @staticmethod
    def _studentized(
        H: np.ndarray, P: np.ndarray, R: np.ndarray, scale2: np.ndarray, use: np.ndarray
    ) -> np.ndarray:
        """In-sample residual of each used channel in sigmas, corrected for its leverage (0 if untestable)."""
        lev = np.einsum("kcj,kjc->c", H, P) / H.shape[0]
        z = np.zeros(use.size)
        ok = use & (lev < 1 - 1e-6)
        z[ok] = np.sqrt(np.sum(np.abs(R[:, ok]) ** 2, axis=0) / (1 - lev[ok]) / np.sum(scale2[:, ok], axis=0))
        return z

    def _leave_one_out(
        self, idx: np.ndarray, H: np.ndarray, Yc: np.ndarray, scale2: np.ndarray, use: np.ndarray
    ) -> tuple[int | None, float]:
        """The used channel whose removal best explains the residuals, and its prediction residual (sigmas).

        One bad channel pulls a least-squares fit towards itself and can make a good neighbour's
        residual the largest; refitting without each candidate in turn does not suffer from that.
        """
        best, best_chi2, best_z = None, math.inf, 0.0
        for c in np.flatnonzero(use):
            rest = use.copy()
            rest[c] = False
            if not self._determined(idx, rest):
                continue
            U = np.stack([np.linalg.pinv(H[i][rest]) @ Yc[i, rest] for i in range(H.shape[0])])
            R = Yc - np.einsum("kcj,kj->kc", H, U)
            chi2 = float(np.sum(np.abs(R[:, rest]) ** 2 / scale2[:, rest]))
            if chi2 < best_chi2:
                best, best_chi2 = int(c), chi2
                best_z = math.sqrt(np.sum(np.abs(R[:, c]) ** 2) / np.sum(scale2[:, c]))
        return best, best_z

    def _second_order_solve(self, U0, ks, Y, H, use, freq_hz, pos, ax):
        """Fixed-point iteration U = H^+ (Y - S(U)) on the channels in ``use``."""
        P = np.stack([np.linalg.pinv(H[i][use]) for i in range(ks.size)])  # (K, 6, Cu)
        kmax = int(ks.max())
        U, change, iters = U0, math.inf, 0
        scale = np.array(
            [1, 1, 1, self.layout.length_scale_m, self.layout.length_scale_m, self.layout.length_scale_m]
        )
        S = np.zeros_like(Y)
        for it in range(1, self.max_iterations + 1):
            iters = it
            if self.terms:
                dense = np.zeros((kmax, 6), dtype=complex)
                dense[ks - 1] = U
                S = second_order_phasors(dense, freq_hz, pos, ax, self.terms, self.gravity_mps2)[ks - 1]
            Yc = (Y - S)[:, use]
            U_new = np.einsum("kjc,kc->kj", P, Yc)
            norm = np.linalg.norm(U_new * scale)
            change = float(np.linalg.norm((U_new - U) * scale) / norm) if norm > 0 else 0.0
            U = U_new
            if not self.terms or change < self.tolerance:
                break
        if self.terms:  # S at the final estimate, so residuals and reports match U
            dense = np.zeros((kmax, 6), dtype=complex)
            dense[ks - 1] = U
            S = second_order_phasors(dense, freq_hz, pos, ax, self.terms, self.gravity_mps2)[ks - 1]
        Pfull = np.zeros((ks.size, 6, use.size))
        Pfull[:, :, use] = P
        return U, S, iters, change, Pfull

    def _scale2(self, Y: np.ndarray, var: np.ndarray, use: np.ndarray) -> np.ndarray:
        """Expected residual power per harmonic and channel: noise plus the model floor.

        The noise is the median over the used channels, not each channel's own: a failing channel's
        own scatter is large and would excuse its residual.
        """
        h = self.health
        signal = np.sqrt(np.mean(np.abs(Y[:, use]) ** 2, axis=1))  # (K,) RMS channel signal per harmonic
        floor2 = (h.model_floor * signal) ** 2 + h.flat_mps2**2
        noise = np.median(np.nan_to_num(var[:, use], nan=0.0), axis=1)
        return np.broadcast_to((noise + floor2)[:, None], Y.shape)

    def _determined(self, idx: np.ndarray, use: np.ndarray) -> bool:
        return use.sum() >= 6 and self.layout.observability(self._full_mask(idx, use)).ok(
            self.layout.max_condition
        )

    def _full_mask(self, idx: np.ndarray, use: np.ndarray) -> np.ndarray:
        # ``use`` indexes the data's columns; observability needs a mask over the whole layout.
        mask = np.zeros(self.layout.num_channels, bool)
        mask[idx[use]] = True
        return mask

    def _require(
        self, idx: np.ndarray, use: np.ndarray, names: tuple[str, ...], status: list[str], when: str
    ) -> None:
        if self._determined(idx, use):
            return
        obs = self.layout.observability(self._full_mask(idx, use))
        by_reason: dict[str, list[str]] = {}
        for n, s in zip(names, status):
            if s != OK:
                by_reason.setdefault(s, []).append(n)
        raise EstimationError(
            f"accelerometer channels no longer determine the plate acceleration {when}: "
            f"{int(use.sum())} usable channels, condition {obs.condition:.3g} > "
            f"{self.layout.max_condition:g}, "
            f"unobservable: {obs.describe_weakest()}; dropped: "
            + "; ".join(f"{', '.join(ns)}: {s}" for s, ns in by_reason.items()),
            dict(zip(names, status)),
        )


__all__ = ["AccelEstimator", "EstimationError", "PlateEstimate"]

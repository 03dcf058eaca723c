"""Per-channel harmonic phasors from raw accelerometer samples, with channel health checks.

Each channel's samples are fitted by least squares with a constant and sin/cos pairs at k Omega,
k = 1..K. With samples that cover whole periods evenly the basis is orthogonal and this is the DFT
over those periods; the least-squares form keeps the answer right when the record ends in a partial
cycle, when samples are missing (NaN), or when channels are sampled at different times. The
phasor of harmonic k is ``X = b_sin + i b_cos`` so that the fitted signal is ``Im(X exp(i k Omega
t))`` (PHYSICS.md phasor convention, t = 0 at a device cycle start).

Health checks here look at one channel's samples alone: too few valid samples or too little phase
coverage, saturation at the channel's full scale (both fatal for the channel), and a flat, stuck
or badly fitted signal (suspect: :mod:`ppod_ros.estimation.estimator` drops a suspect channel only
when the other channels predict a reading it does not show).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from ppod_ros.config.fields import Fields
from ppod_ros.errors import ConfigError

_S = TypeVar("_S")


@dataclass(frozen=True)
class HealthSettings:
    """Thresholds of the per-channel checks (see docs/feedback.md, "Channel health").

    Attributes
    ----------
    min_valid_fraction : float
        A channel with fewer finite samples than this fraction of the record is dead ("missing").
    saturation_fraction : float
        Fraction of samples at or beyond 0.999 of full scale that marks a channel "saturated".
    flat_mps2 : float
        Peak-to-peak (m/s^2) at or below which a channel is suspect "flat" (real sensors show noise).
    stuck_fraction : float
        Fraction of consecutive repeated values above which a channel is suspect "stuck".
    fit_residual_ratio : float
        A channel whose fit residual RMS exceeds this multiple of the median channel's (and
        ``flat_mps2``) is suspect: its signal is not periodic over the record (e.g. died mid-record).
    max_fit_condition : float
        Largest condition number of a channel's (column-normalised) sin/cos design matrix; beyond
        it the samples do not cover enough of the cycle to separate the harmonics.
    residual_threshold : float
        Normalised residual above which the 6-DoF solve calls a channel inconsistent.
    model_floor : float
        Relative model uncertainty (calibration, unmodelled terms) added to the noise when
        normalising residuals, as a fraction of the RMS channel signal of each harmonic.
    misfit_allowance : float
        Fraction of its own reading by which the other channels' prediction of a channel may miss
        before the channel counts as inconsistent (both this and ``residual_threshold`` must be
        exceeded). A real array misfits by its sensors' gain and axis errors and the plate's bending:
        up to 36 % of a weak channel's reading on the PPOD2 lab's device (docs/feedback.md), while a
        halved, zeroed, sign-flipped or swapped channel misses by 75 % or more. A calibration's
        measured per-channel misfit replaces it (``AccelEstimator(calibration=...)``).
    swap_ratio : float
        Two used channels whose exchange leaves at most this fraction of the residual (and one of
        which misfits by more than ``residual_threshold``) look swapped in wiring: an
        EstimationError (:mod:`~ppod_ros.estimation.swaps`; healthy real records: 0.77 at best).
    """

    min_valid_fraction: float = 0.5
    saturation_fraction: float = 0.002
    flat_mps2: float = 1e-6
    stuck_fraction: float = 0.5
    fit_residual_ratio: float = 10.0
    max_fit_condition: float = 1.0e3
    residual_threshold: float = 5.0
    model_floor: float = 0.01
    misfit_allowance: float = 0.5
    swap_ratio: float = 0.5

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = "health") -> HealthSettings:
        """Strict reader of a parameter mapping; missing keys keep their defaults."""
        return settings_from_dict(cls, data, where)

    def __post_init__(self) -> None:
        for name in ("min_valid_fraction", "saturation_fraction", "stuck_fraction"):
            v = getattr(self, name)
            if not 0 < v <= 1:
                raise ConfigError(f"health.{name}: must be in (0, 1], got {v}")
        for name in (
            "flat_mps2",
            "fit_residual_ratio",
            "max_fit_condition",
            "residual_threshold",
            "model_floor",
            "misfit_allowance",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"health.{name}: must be finite and >= 0, got {v}")


def settings_from_dict(cls: type[_S], data: Mapping[str, Any], where: str) -> _S:
    """Build a settings dataclass of numbers from a mapping (ROS parameters, YAML), strictly.

    Unknown keys are errors naming the key; fields annotated ``int`` must be integers; missing keys
    keep the dataclass defaults; the dataclass validates ranges itself.
    """
    f = Fields(data, where)
    kw: dict[str, Any] = {}
    for fld in dataclasses.fields(cls):
        if f.has(fld.name):
            kw[fld.name] = f.integer(fld.name) if fld.type in ("int", int) else f.number(fld.name)
    f.finish()
    try:
        return cls(**kw)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from exc


@dataclass(frozen=True)
class ChannelFit:
    """Harmonic fit of every channel of one record.

    Attributes
    ----------
    k : ndarray of int, shape (K,)
        Harmonics 1..K.
    phasors : complex ndarray, shape (K, C)
        Fitted phasor of each harmonic and channel (m/s^2); NaN where the channel is unusable.
    variance : ndarray, shape (K, C)
        Noise variance of each phasor (sum of real and imaginary parts, (m/s^2)^2).
    dc_mps2 : ndarray, shape (C,)
        Fitted constant (sensor offset, static 1 g, second-order 0 Hz terms).
    residual_rms_mps2 : ndarray, shape (C,)
        RMS of each channel's time-domain fit residual.
    fatal : tuple of (str or None), length C
        Why a channel is unusable ("missing", "saturated", "coverage"), or None.
    suspect : tuple of (str or None), length C
        Why a channel is suspect ("flat", "stuck", "not periodic"), or None.
    samples_used : ndarray of int, shape (C,)
    cycles : float
        Time span of the record in periods (a partial cycle shows as a fraction).
    """

    k: np.ndarray
    phasors: np.ndarray
    variance: np.ndarray
    dc_mps2: np.ndarray
    residual_rms_mps2: np.ndarray
    fatal: tuple[str | None, ...]
    suspect: tuple[str | None, ...]
    samples_used: np.ndarray
    cycles: float


def cycle_times(
    cycle_index: np.ndarray, sample_index: np.ndarray, samples_per_cycle: int, frequency_hz: float
) -> np.ndarray:
    """Sample times (s) from cycle numbers and sample indices within the cycle (t = 0 at cycle 0)."""
    if samples_per_cycle <= 0 or frequency_hz <= 0:
        raise ConfigError("samples_per_cycle and frequency_hz must be > 0")
    return (
        np.asarray(cycle_index, float) + np.asarray(sample_index, float) / samples_per_cycle
    ) / frequency_hz


def _design(t: np.ndarray, omega: float, K: int) -> np.ndarray:
    arg = np.outer(t, omega * np.arange(1, K + 1))
    A = np.empty((t.size, 2 * K + 1))
    A[:, 0] = 1.0
    A[:, 1::2] = np.sin(arg)
    A[:, 2::2] = np.cos(arg)
    return A


def _stuck_fraction(x: np.ndarray) -> float:
    if x.size < 2:
        return 0.0
    return float(np.mean(x[1:] == x[:-1]))


def fit_harmonics(
    time_s: np.ndarray,
    samples_mps2: np.ndarray,
    frequency_hz: float,
    harmonics: int,
    *,
    full_scale_mps2: np.ndarray | None = None,
    health: HealthSettings | None = None,
) -> ChannelFit:
    """Fit harmonics 1..K (and a constant) to every channel's samples.

    Parameters
    ----------
    time_s : array_like, shape (N,) or (N, C)
        Sample times (s) measured from a device cycle start (any cycle: only t mod T sets phases);
        per channel when channels are sampled at different times.
    samples_mps2 : array_like, shape (N, C)
        Readings (m/s^2); NaN marks a missing sample.
    frequency_hz : float
        Fundamental f (Hz).
    harmonics : int
        K, the highest harmonic fitted (>= 1).
    full_scale_mps2 : array_like, shape (C,), optional
        Saturation level of each channel (inf: unknown).
    """
    health = health or HealthSettings()
    y = np.asarray(samples_mps2, dtype=float)
    if y.ndim != 2 or y.shape[0] < 1:
        raise ConfigError(f"samples_mps2: expected shape (N samples, C channels), got {y.shape}")
    N, C = y.shape
    t = np.asarray(time_s, dtype=float)
    if t.shape == (N,):
        t = np.broadcast_to(t[:, None], (N, C))
    if t.shape != (N, C):
        raise ConfigError(f"time_s: expected shape ({N},) or ({N}, {C}) to match samples_mps2, got {t.shape}")
    if not (
        isinstance(frequency_hz, (int, float, np.floating))
        and math.isfinite(frequency_hz)
        and frequency_hz > 0
    ):
        raise ConfigError(f"frequency_hz: must be a finite number > 0 Hz, got {frequency_hz!r}")
    if not (isinstance(harmonics, (int, np.integer)) and harmonics >= 1):
        raise ConfigError(f"harmonics: must be an integer >= 1, got {harmonics!r}")
    K = int(harmonics)
    fs = np.full(C, np.inf) if full_scale_mps2 is None else np.asarray(full_scale_mps2, float)
    if fs.shape != (C,):
        raise ConfigError(f"full_scale_mps2: expected shape ({C},), got {fs.shape}")
    omega = 2.0 * math.pi * frequency_hz
    if N > 1:
        # Uniformly sampled channels alias harmonics above Nyquist onto lower ones: say so plainly
        # rather than through an ill-conditioned fit.
        dt = np.diff(np.sort(t[:, 0][np.isfinite(t[:, 0])]))
        rate_hz = 1.0 / float(np.median(dt)) if dt.size and np.median(dt) > 0 else math.inf
        if K * frequency_hz >= rate_hz / 2:
            raise ConfigError(
                f"harmonics: harmonic {K} at {K * frequency_hz:g} Hz is above the Nyquist frequency "
                f"{rate_hz / 2:g} Hz of samples at {rate_hz:g} Hz; fit fewer harmonics"
            )
    valid = np.isfinite(y) & np.isfinite(t)
    span = (
        np.nanmax(np.where(valid, t, np.nan)) - np.nanmin(np.where(valid, t, np.nan)) if valid.any() else 0.0
    )

    phasors = np.full((K, C), np.nan + 0j)
    variance = np.full((K, C), np.nan)
    dc = np.full(C, np.nan)
    rms = np.full(C, np.nan)
    fatal: list[str | None] = [None] * C
    suspect: list[str | None] = [None] * C
    used = valid.sum(axis=0)
    for c in range(C):
        yc = y[valid[:, c], c]
        if used[c] < max(health.min_valid_fraction * N, 2 * K + 2):
            fatal[c] = f"missing: {used[c]} of {N} samples valid"
        elif np.isfinite(fs[c]) and np.mean(np.abs(yc) >= 0.999 * fs[c]) >= health.saturation_fraction:
            share = np.mean(np.abs(yc) >= 0.999 * fs[c])
            fatal[c] = f"saturated: {share:.1%} of samples at full scale {fs[c]:g} m/s^2"
    # Channels sampled at the same times with the same gaps share one design matrix: fit them together.
    groups: dict[bytes, list[int]] = {}
    for c in range(C):
        if fatal[c] is None:
            groups.setdefault(valid[:, c].tobytes() + t[:, c].tobytes(), []).append(c)
    for cols in groups.values():
        ok = valid[:, cols[0]]
        A = _design(t[ok, cols[0]], omega, K)
        cond = np.linalg.cond(A / np.linalg.norm(A, axis=0))
        if not cond <= health.max_fit_condition:
            for c in cols:
                fatal[c] = (
                    f"coverage: samples span {span * frequency_hz:.2f} cycles, too little to separate "
                    f"harmonics 1..{K} (condition {cond:.3g})"
                )
            continue
        Y = y[ok][:, cols]
        coef, *_ = np.linalg.lstsq(A, Y, rcond=None)
        res = Y - A @ coef
        ss = np.sum(res**2, axis=0)
        inv_diag = np.diag(np.linalg.inv(A.T @ A))
        sigma2 = ss / max(Y.shape[0] - A.shape[1], 1)
        dc[cols] = coef[0]
        phasors[:, cols] = coef[1::2] + 1j * coef[2::2]
        variance[:, cols] = np.outer(inv_diag[1::2] + inv_diag[2::2], sigma2)
        rms[cols] = np.sqrt(ss / Y.shape[0])
        for i, c in enumerate(cols):
            if np.ptp(Y[:, i]) <= health.flat_mps2:
                suspect[c] = f"flat: peak-to-peak {np.ptp(Y[:, i]):.3g} m/s^2"
            elif _stuck_fraction(Y[:, i]) >= health.stuck_fraction:
                suspect[c] = f"stuck: {_stuck_fraction(Y[:, i]):.0%} of consecutive samples repeat"
    alive = np.isfinite(rms)
    if alive.any():
        typical = float(np.median(rms[alive]))
        for c in np.flatnonzero(alive):
            if suspect[c] is None and rms[c] > max(health.fit_residual_ratio * typical, health.flat_mps2):
                suspect[c] = (
                    f"not periodic: fit residual {rms[c]:.3g} m/s^2 RMS, "
                    f"{rms[c] / max(typical, 1e-300):.0f}x the median channel's"
                )
    return ChannelFit(
        np.arange(1, K + 1),
        phasors,
        variance,
        dc,
        rms,
        tuple(fatal),
        tuple(suspect),
        used,
        float(span * frequency_hz),
    )


__all__ = ["ChannelFit", "HealthSettings", "cycle_times", "fit_harmonics", "settings_from_dict"]

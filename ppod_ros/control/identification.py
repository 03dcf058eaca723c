"""Plant identification: drive one actuator at a time, one harmonic at a time, and measure.

The experiment (:class:`IdentificationPlan`) is a baseline step with no drive, then for each harmonic
k and actuator j a step that drives actuator j alone with a small current phasor a_k (A, phase 0) at
harmonic k. Column j of G_k is the measured acceleration phasor of harmonic k minus the baseline's,
divided by a_k. One harmonic at a time keeps the plate's distortion of one harmonic (a third
harmonic made by the fundamental) out of another harmonic's matrix; the baseline removes whatever
the plate does without drive. Each step lasts ``settle_cycles`` (the device ramps and settles) plus
``measure_cycles`` (averaged by the estimator).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ppod_ros.control.limits import DeviceLimits, check_within
from ppod_ros.control.plant import PlantModel
from ppod_ros.errors import ConfigError
from ppod_ros.estimation import PlateEstimate


@dataclass(frozen=True)
class IdentificationStep:
    """One step: ``command_a`` (K, 6) complex on the plan's harmonics (all zero for the baseline)."""

    index: int
    k: int | None
    actuator: int | None
    command_a: np.ndarray

    @property
    def is_baseline(self) -> bool:
        return self.k is None


@dataclass(frozen=True, eq=False)
class IdentificationPlan:
    """The one-actuator-at-a-time experiment at one fundamental frequency.

    Parameters
    ----------
    frequency_hz : float
    k : sequence of int
        Harmonics to identify.
    amplitude_a : float or array_like, shape (K,)
        Drive amplitude per harmonic (A); small, so the plate stays near-linear and safe.
    settle_cycles, measure_cycles : int
        Periods to wait after each change and to average per step.
    """

    frequency_hz: float
    k: tuple[int, ...]
    amplitude_a: np.ndarray
    settle_cycles: int = 10
    measure_cycles: int = 20

    def __post_init__(self) -> None:
        f = self.frequency_hz
        if not (isinstance(f, (int, float, np.integer, np.floating)) and math.isfinite(f) and f > 0):
            raise ConfigError(f"identification.frequency_hz: must be a finite number > 0 Hz, got {f!r}")
        ks = tuple(int(k) for k in self.k)
        if not ks or any(k < 1 for k in ks) or len(set(ks)) != len(ks):
            raise ConfigError(f"identification.k: expected distinct harmonics >= 1, got {list(self.k)}")
        amp = np.broadcast_to(np.asarray(self.amplitude_a, float), (len(ks),)).copy()
        if not np.all(np.isfinite(amp)) or np.any(amp <= 0):
            raise ConfigError(f"identification.amplitude_a: must be finite and > 0 A, got {amp.tolist()}")
        for name in ("settle_cycles", "measure_cycles"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= (0 if name == "settle_cycles" else 1)):
                raise ConfigError(f"identification.{name}: expected a whole number of cycles, got {v!r}")
        amp.setflags(write=False)
        object.__setattr__(self, "frequency_hz", float(f))
        object.__setattr__(self, "k", ks)
        object.__setattr__(self, "amplitude_a", amp)

    @classmethod
    def scaled_to(
        cls, model: PlantModel, accel_mps2: float, k: Sequence[int] | None = None, **kw: int
    ) -> IdentificationPlan:
        """A plan whose drive makes about ``accel_mps2`` per actuator by the model (e.g. the nominal one).

        The amplitude of harmonic k is ``accel_mps2`` over the median column norm of the model's G_k
        (angular rows scaled by its length scale), so each step moves the plate by about that much.
        """
        if not (math.isfinite(accel_mps2) and accel_mps2 > 0):
            raise ConfigError(f"accel_mps2: must be finite and > 0, got {accel_mps2}")
        ks = list(model.k) if k is None else [int(x) for x in k]
        L = model.length_scale_m
        scale = np.array([1, 1, 1, L, L, L])[:, None]
        amp = [accel_mps2 / float(np.median(np.linalg.norm(model.matrix(kk) * scale, axis=0))) for kk in ks]
        return cls(model.frequency_hz, tuple(ks), np.array(amp), **kw)

    def steps(self) -> list[IdentificationStep]:
        """The baseline, then each (harmonic, actuator) pair: 1 + 6 K steps."""
        K = len(self.k)
        out = [IdentificationStep(0, None, None, np.zeros((K, 6), complex))]
        for i, k in enumerate(self.k):
            for j in range(6):
                cmd = np.zeros((K, 6), complex)
                cmd[i, j] = self.amplitude_a[i]
                out.append(IdentificationStep(len(out), k, j, cmd))
        return out

    def duration_s(self) -> float:
        return len(self.steps()) * (self.settle_cycles + self.measure_cycles) / self.frequency_hz

    def check(self, limits: DeviceLimits) -> None:
        """Raise LimitError if any step's drive exceeds the device's current limit."""
        for step in self.steps():
            check_within(limits, step.command_a, np.zeros_like(step.command_a))


def _rows(measured: PlateEstimate | np.ndarray, ks: tuple[int, ...], step: IdentificationStep) -> np.ndarray:
    if isinstance(measured, PlateEstimate):
        missing = sorted(set(ks) - set(measured.k.tolist()))
        if missing:
            raise ConfigError(f"identification step {step.index}: estimate lacks harmonics {missing}")
        return np.stack([measured.phasors[list(measured.k).index(k)] for k in ks])
    M = np.asarray(measured, complex)
    if M.shape != (len(ks), 6) or not np.all(np.isfinite(M)):
        raise ConfigError(
            f"identification step {step.index}: expected finite phasors ({len(ks)}, 6) at harmonics "
            f"{list(ks)}, got shape {M.shape}"
        )
    return M


def identify(
    plan: IdentificationPlan, measurements: Sequence[PlateEstimate | np.ndarray], **kw
) -> PlantModel:
    """G_k from the measurements of every step of ``plan.steps()``, in order.

    Each measurement is a :class:`PlateEstimate` or phasors (K, 6) on the plan's harmonics.
    Keyword arguments go to :class:`PlantModel` (e.g. ``max_condition``).
    """
    steps = plan.steps()
    if len(measurements) != len(steps):
        raise ConfigError(f"identify: {len(steps)} steps in the plan, {len(measurements)} measurements")
    base = _rows(measurements[0], plan.k, steps[0])
    G = np.zeros((len(plan.k), 6, 6), complex)
    for step, meas in zip(steps[1:], measurements[1:]):
        i = plan.k.index(step.k)
        G[i, :, step.actuator] = (_rows(meas, plan.k, step)[i] - base[i]) / plan.amplitude_a[i]
    return PlantModel(plan.frequency_hz, np.array(plan.k), G, source="identified", **kw)


def run_identification(
    plan: IdentificationPlan,
    measure: Callable[[IdentificationStep], PlateEstimate | np.ndarray],
    limits: DeviceLimits | None = None,
    **kw,
) -> PlantModel:
    """Run the experiment through ``measure(step)`` (apply the step's currents, settle, estimate).

    With ``limits``, the whole plan is checked before the first step is driven.
    """
    if limits is not None:
        plan.check(limits)
    return identify(plan, [measure(step) for step in plan.steps()], **kw)


__all__ = ["IdentificationPlan", "IdentificationStep", "identify", "run_identification"]

"""Device limits on the learning loop's commands: peak coil current and step size per iteration.

The command of actuator j is a sum of harmonics, ``i_j(t) = sum_k Im(I_kj e^{i k Omega t})``; its
peak is at most ``sum_k |I_kj|`` (equal when the harmonics line up), and this bound is what is
limited, so a limited command is safe whatever the phases. A step is limited the same way: the
change of actuator j's waveform in one iteration peaks at most at ``sum_k |dI_kj|``.

:meth:`DeviceLimits.apply` moves from the previous command towards the proposed one as far as both
limits allow, along the same direction (the update's direction is kept, only its length is cut), and
reports every cut. Anything with the same call signature can stand in for it (a node may pass the
generator's own limit check).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ppod_ros.config.fields import check_array
from ppod_ros.errors import ConfigError, LimitError


@dataclass(frozen=True)
class LimitEvent:
    """One cut: ``limit`` ("max_current_a" or "max_step_a") of ``actuator`` (0..5); actuator -1: a cut
    of the whole table (the generator's envelope, ``limit_value`` the fraction of the step kept)."""

    limit: str
    actuator: int
    limit_value: float
    requested: float

    def describe(self) -> str:
        if self.actuator < 0:  # a limit on the whole table (the generator's envelope): value = the scale kept
            return f"{self.limit}: step scaled by {self.limit_value:.3g}"
        return (
            f"actuator {self.actuator}: {self.limit} {self.limit_value:g} A, requested {self.requested:.4g} A"
        )


@dataclass(frozen=True)
class LimitReport:
    events: tuple[LimitEvent, ...] = ()

    @property
    def clipped(self) -> bool:
        return bool(self.events)

    def describe(self) -> str:
        return "; ".join(e.describe() for e in self.events) if self.events else "within limits"


#: The limits callable's signature: (previous (K, 6), proposed (K, 6), feedforward (K, 6)) ->
#: (command (K, 6), report). Commands are corrections; limits apply to feedforward + correction.
LimitFunction = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, LimitReport]]


def peak_a(currents: np.ndarray) -> np.ndarray:
    """Peak bound per actuator, sum over harmonics of |I_kj|, shape (6,), of phasors (K, 6)."""
    return np.abs(np.asarray(currents, complex)).sum(axis=0)


@dataclass(frozen=True)
class DeviceLimits:
    """Per-actuator limits (A); scalars apply to all six actuators.

    Parameters
    ----------
    max_current_a : float or array_like, shape (6,)
        Peak coil current, feed-forward plus correction.
    max_step_a : float or array_like, shape (6,)
        Largest peak change of an actuator's correction in one iteration.
    """

    max_current_a: np.ndarray
    max_step_a: np.ndarray

    def __post_init__(self) -> None:
        for name in ("max_current_a", "max_step_a"):
            v = check_array(getattr(self, name), f"limits.{name}", unit="A")
            if v.shape not in ((), (6,)):
                raise ConfigError(f"limits.{name}: expected 1 value or 6 (per actuator), got shape {v.shape}")
            v = np.broadcast_to(v, (6,)).copy()
            if np.any(v <= 0):
                raise ConfigError(f"limits.{name}: must be > 0 A, got {v.tolist()}")
            v.setflags(write=False)
            object.__setattr__(self, name, v)

    def __call__(
        self, previous: np.ndarray, proposed: np.ndarray, feedforward: np.ndarray
    ) -> tuple[np.ndarray, LimitReport]:
        return self.apply(previous, proposed, feedforward)

    def apply(
        self, previous: np.ndarray, proposed: np.ndarray, feedforward: np.ndarray | None = None
    ) -> tuple[np.ndarray, LimitReport]:
        """Limit the move from correction ``previous`` to ``proposed`` (both (K, 6) complex, A).

        Returns the correction to send and the report of cuts. If ``previous`` itself is over the
        current limit (the limits were lowered), that actuator's total is scaled down onto the limit.
        """
        prev = np.asarray(previous, complex)
        prop = np.asarray(proposed, complex)
        ff = np.zeros_like(prev) if feedforward is None else np.asarray(feedforward, complex)
        if prev.shape != prop.shape or prev.shape != ff.shape or prev.ndim != 2 or prev.shape[1] != 6:
            raise ConfigError(
                f"limits: previous, proposed and feedforward must share shape (K, 6), got "
                f"{prev.shape}, {prop.shape}, {ff.shape}"
            )
        if not (np.all(np.isfinite(prop)) and np.all(np.isfinite(prev))):
            raise ConfigError("limits: commands must be finite")
        events: list[LimitEvent] = []
        out = prop.copy()
        for j in range(6):
            total_prev = peak_a(ff[:, j : j + 1] + prev[:, j : j + 1])[0]
            if total_prev > self.max_current_a[j]:
                total = (ff[:, j] + prev[:, j]) * (self.max_current_a[j] / total_prev)
                out[:, j] = total - ff[:, j]
                events.append(LimitEvent("max_current_a", j, self.max_current_a[j], float(total_prev)))
                continue
            step = prop[:, j] - prev[:, j]
            size = float(np.abs(step).sum())
            if size > self.max_step_a[j]:
                events.append(LimitEvent("max_step_a", j, self.max_step_a[j], size))
                step = step * (self.max_step_a[j] / size)
            want = float(np.abs(ff[:, j] + prev[:, j] + step).sum())
            if want > self.max_current_a[j]:
                events.append(LimitEvent("max_current_a", j, self.max_current_a[j], want))
                step = step * self._fraction(ff[:, j] + prev[:, j], step, self.max_current_a[j])
            out[:, j] = prev[:, j] + step
        return out, LimitReport(tuple(events))

    @staticmethod
    def _fraction(start: np.ndarray, step: np.ndarray, limit: float) -> float:
        # sum_k |start_k + t step_k| is convex in t and within the limit at t = 0: bisect for the
        # largest t in [0, 1] that stays within it (50 halvings: below 1e-15 of the step).
        lo, hi = 0.0, 1.0
        for _ in range(50):
            mid = 0.5 * (lo + hi)
            if np.abs(start + mid * step).sum() <= limit:
                lo = mid
            else:
                hi = mid
        return lo


def check_within(limits: DeviceLimits, correction: np.ndarray, feedforward: np.ndarray) -> None:
    """Raise LimitError if feed-forward plus ``correction`` exceeds ``limits.max_current_a``."""
    total = peak_a(np.asarray(feedforward, complex) + np.asarray(correction, complex))
    over = np.flatnonzero(total > limits.max_current_a * (1 + 1e-12))
    if over.size:
        j = int(over[np.argmax(total[over] / limits.max_current_a[over])])
        raise LimitError(
            f"command peak current {total[j]:.4g} A of actuator {j} exceeds limits.max_current_a "
            f"{limits.max_current_a[j]:g} A (actuators over: {over.tolist()})",
            limit="limits.max_current_a",
            limit_value=limits.max_current_a[j],
            requested=total[j],
        )


__all__ = ["DeviceLimits", "LimitEvent", "LimitFunction", "LimitReport", "check_within", "peak_a"]

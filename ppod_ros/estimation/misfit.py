"""Per-channel misfit learned from operation, stored per device next to its calibration.

A real array misfits its rigid-body model by each sensor's gain and axis errors and the plate's
bending (docs/feedback.md). A calibration (:mod:`~ppod_ros.estimation.calibration`) measures that
misfit from dedicated motions; a device without one learns it while it runs: every estimate in which
no channel was dropped adds each channel's misfit (its in-sample residual as a fraction of its own
reading, :attr:`PlateEstimate.channel_misfit`) to :class:`MisfitHistory`. Once ``min_estimates``
healthy estimates are in, :meth:`MisfitHistory.allowance` gives the estimator's per-channel misfit
allowance: ``ALLOWANCE_FACTOR`` times a high quantile of the channel's own misfit (its typical misfit
plus ``SPREAD_SIGMAS`` standard deviations), never below ``MIN_ALLOWANCE`` (the calibration's rule,
so both paths agree).

Only healthy estimates teach it (nothing dropped): a broken channel is excluded from the estimate
before it could widen its own allowance, and a history never learns from a cycle it did not trust.

Stored as JSON: ``<cache_dir>/<device_id>/accel_misfit.json`` (:func:`save_misfit`,
:func:`load_misfit`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.estimation.calibration import ALLOWANCE_FACTOR, MIN_ALLOWANCE
from ppod_ros.estimation.device_store import device_file, read_json, write_json

#: File name of a device's learned misfit in its cache folder.
MISFIT_FILE = "accel_misfit.json"
#: Standard deviations above the mean misfit that the allowance covers (before ALLOWANCE_FACTOR).
SPREAD_SIGMAS = 2.0
#: Healthy estimates needed before a learned allowance is used (fewer: the settings' default).
MIN_ESTIMATES = 20


@dataclass(frozen=True)
class MisfitSettings:
    """When a learned misfit is trusted (estimates, not seconds: the loop's own pace)."""

    min_estimates: int = MIN_ESTIMATES

    def __post_init__(self) -> None:
        if not (isinstance(self.min_estimates, int) and self.min_estimates >= 2):
            raise ConfigError(f"misfit.min_estimates: expected an integer >= 2 (estimates), got {self.min_estimates!r}")


class MisfitHistory:
    """Running per-channel misfit statistics over healthy estimates (Welford mean and variance).

    Parameters
    ----------
    names : sequence of str
        The layout's channel names (every channel of the device, in layout order).
    settings : MisfitSettings, optional
    """

    def __init__(self, names: Sequence[str], settings: MisfitSettings | None = None):
        self.names = tuple(names)
        if not self.names or len(set(self.names)) != len(self.names):
            raise ConfigError(f"names: expected distinct channel names, got {list(names)}")
        self.settings = settings or MisfitSettings()
        C = len(self.names)
        self.count = np.zeros(C, dtype=int)
        self.mean = np.zeros(C)
        self._m2 = np.zeros(C)

    def add(self, estimate) -> bool:
        """Learn from one estimate; returns whether it was used (healthy: nothing dropped)."""
        misfit = getattr(estimate, "channel_misfit", None)
        if misfit is None or any(s != "ok" for s in estimate.status):
            return False
        for name, value in zip(estimate.channels, misfit):
            if name not in self.names or not math.isfinite(float(value)):
                continue
            c = self.names.index(name)
            self.count[c] += 1
            delta = float(value) - self.mean[c]
            self.mean[c] += delta / self.count[c]
            self._m2[c] += delta * (float(value) - self.mean[c])
        return True

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(self._m2 / np.maximum(self.count - 1, 1))

    @property
    def ready(self) -> bool:
        """Every channel has ``min_estimates`` healthy estimates behind it."""
        return bool(np.all(self.count >= self.settings.min_estimates))

    def allowance(self) -> np.ndarray | None:
        """Per-channel misfit allowance for the estimator, or None until :attr:`ready`."""
        if not self.ready:
            return None
        return np.maximum(ALLOWANCE_FACTOR * (self.mean + SPREAD_SIGMAS * self.std), MIN_ALLOWANCE)

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": "ppod accel misfit 1",
            "channels": [
                {"name": n, "count": int(self.count[i]), "mean": float(self.mean[i]), "m2": float(self._m2[i])}
                for i, n in enumerate(self.names)
            ],
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str = "misfit", settings: MisfitSettings | None = None
                  ) -> MisfitHistory:
        try:
            ch = data["channels"]
            out = cls([c["name"] for c in ch], settings)
            out.count = np.array([int(c["count"]) for c in ch])
            out.mean = np.array([float(c["mean"]) for c in ch])
            out._m2 = np.array([float(c["m2"]) for c in ch])
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(f"{where}: not an accelerometer misfit history ({exc})") from exc
        if np.any(out.count < 0) or not np.all(np.isfinite(out.mean)) or np.any(~(out._m2 >= 0)):
            raise ConfigError(f"{where}: misfit history has negative counts or non-finite statistics")
        return out


def misfit_path(cache_dir: str | Path, device_id: str) -> Path:
    return device_file(cache_dir, device_id, MISFIT_FILE)


def save_misfit(history: MisfitHistory, cache_dir: str | Path, device_id: str) -> Path:
    """Write the device's learned misfit atomically; returns its path."""
    return write_json(misfit_path(cache_dir, device_id), history.to_dict())


def load_misfit(cache_dir: str | Path, device_id: str, settings: MisfitSettings | None = None
                ) -> MisfitHistory | None:
    """The device's stored misfit history, or None when it has none."""
    path = misfit_path(cache_dir, device_id)
    data = read_json(path, "misfit history")
    return None if data is None else MisfitHistory.from_dict(data, str(path), settings)


__all__ = ["MisfitHistory", "MisfitSettings", "load_misfit", "misfit_path", "save_misfit"]

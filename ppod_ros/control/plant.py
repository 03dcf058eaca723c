"""The plate plant per harmonic: complex 6 x 6 matrices from coil currents to plate acceleration.

At fundamental f, harmonic k of the six coil-current phasors I_k (A) produces harmonic k of the plate
acceleration U_k = G_k I_k, U = [p''x, p''y, p''z, alpha_x, alpha_y, alpha_z] (m/s^2, rad/s^2), both
in the PHYSICS.md phasor convention. G_k is the plant's frequency response at k f, so a model is
built from any frequency-response callable (the nominal model's
``NominalPlant(config).frequency_response(freq_hz) -> (..., 6, 6)``), from a table of matrices, or
by an identification run (:mod:`ppod_ros.control.identification`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.motion import DEFAULT_LENGTH_SCALE_M

#: Largest condition number (angular rows scaled by the length scale) of a usable G_k.
DEFAULT_MAX_PLANT_CONDITION = 1.0e6

PlantSource = Callable[[np.ndarray], np.ndarray]


def _row_scale(length_scale_m: float) -> np.ndarray:
    L = length_scale_m
    return np.array([1.0, 1.0, 1.0, L, L, L])


@dataclass(frozen=True, eq=False)
class PlantModel:
    """G_k per harmonic at one fundamental frequency, validated and pre-factorised.

    Parameters
    ----------
    frequency_hz : float
        Fundamental f (Hz).
    k : array_like of int, shape (K,)
        Harmonics, distinct, >= 1.
    G : complex array_like, shape (K, 6, 6)
        G[i] maps coil-current phasors (A) of harmonic k[i] to plate-acceleration phasors.
    source : str
        Where the model came from ("nominal", "identified", "table", ...), for reports.
    max_condition : float
        A G_k whose condition number (angular rows scaled by ``length_scale_m``) exceeds this is
        rejected: inverting it would amplify measurement noise into large currents.
    """

    frequency_hz: float
    k: np.ndarray
    G: np.ndarray
    source: str = "table"
    max_condition: float = DEFAULT_MAX_PLANT_CONDITION
    length_scale_m: float = DEFAULT_LENGTH_SCALE_M
    _inv: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        f = self.frequency_hz
        if not (isinstance(f, (int, float, np.integer, np.floating)) and math.isfinite(f) and f > 0):
            raise ConfigError(f"plant.frequency_hz: must be a finite number > 0 Hz, got {f!r}")
        ks = np.asarray(self.k)
        if ks.ndim != 1 or ks.size == 0 or ks.dtype.kind not in "iu" or np.any(ks < 1):
            raise ConfigError(f"plant.k: expected harmonic numbers >= 1, got {np.asarray(self.k).tolist()}")
        if len(set(ks.tolist())) != ks.size:
            raise ConfigError(f"plant.k: each harmonic at most once, got {ks.tolist()}")
        G = np.asarray(self.G, dtype=complex)
        if G.shape != (ks.size, 6, 6):
            raise ConfigError(f"plant.G: expected shape ({ks.size}, 6, 6) complex, got {np.shape(self.G)}")
        if not np.all(np.isfinite(G)):
            raise ConfigError("plant.G: all entries must be finite")
        scale = _row_scale(self.length_scale_m)
        for i, k in enumerate(ks):
            cond = np.linalg.cond(G[i] * scale[:, None])
            if not cond <= self.max_condition:
                raise ConfigError(
                    f"plant.G: harmonic {k} ({k * f:g} Hz) is singular or ill-conditioned (condition "
                    f"{cond:.3g} > {self.max_condition:g}); the plate cannot be steered in all six axes there"
                )
        order = np.argsort(ks)
        ks, G = ks[order].astype(int), G[order]
        inv = np.linalg.inv(G)
        for arr in (ks, G, inv):
            arr.setflags(write=False)
        object.__setattr__(self, "frequency_hz", float(f))
        object.__setattr__(self, "k", ks)
        object.__setattr__(self, "G", G)
        object.__setattr__(self, "_inv", inv)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_response(
        cls, response: PlantSource, frequency_hz: float, k: Sequence[int], source: str = "nominal", **kw: Any
    ) -> PlantModel:
        """Evaluate a frequency-response callable ``response(freq_hz (K,)) -> (K, 6, 6)`` at k f."""
        ks = np.asarray(k, dtype=int)
        try:
            G = np.asarray(response(ks * float(frequency_hz)), dtype=complex)
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"plant response at {ks.tolist()} x {frequency_hz} Hz failed: {exc}") from exc
        if G.shape != (ks.size, 6, 6):
            raise ConfigError(
                f"plant response: expected shape ({ks.size}, 6, 6) for {ks.size} frequencies, got {G.shape}"
            )
        return cls(frequency_hz, ks, G, source=source, **kw)

    @classmethod
    def from_table(
        cls, frequency_hz: float, table: Mapping[int, Any], source: str = "table", **kw: Any
    ) -> PlantModel:
        """From a mapping harmonic -> 6 x 6 complex matrix."""
        if not isinstance(table, Mapping) or not table:
            raise ConfigError("plant table: expected a non-empty mapping of harmonic to 6 x 6 matrix")
        ks = sorted(table)
        return cls(
            frequency_hz, np.array(ks, dtype=int), np.stack([np.asarray(table[k]) for k in ks]), source, **kw
        )

    # ------------------------------------------------------------------ use
    def _row(self, k: int) -> int:
        hit = np.flatnonzero(self.k == k)
        if not hit.size:
            raise ConfigError(
                f"plant ({self.source}) has no matrix for harmonic {k}; it has {self.k.tolist()}"
            )
        return int(hit[0])

    def matrix(self, k: int) -> np.ndarray:
        """G_k, shape (6, 6)."""
        return self.G[self._row(k)]

    def condition(self, k: int) -> float:
        return float(np.linalg.cond(self.matrix(k) * _row_scale(self.length_scale_m)[:, None]))

    def covers(self, ks: Sequence[int]) -> bool:
        return set(int(k) for k in ks) <= set(self.k.tolist())

    def response(self, currents_a: np.ndarray, ks: Sequence[int]) -> np.ndarray:
        """Predicted acceleration phasors (K, 6) of current phasors (K, 6) at harmonics ``ks``."""
        I = np.asarray(currents_a, dtype=complex)
        return np.stack([self.matrix(k) @ I[i] for i, k in enumerate(ks)])

    def solve(self, accel: np.ndarray, ks: Sequence[int]) -> np.ndarray:
        """Currents (K, 6) that produce acceleration phasors ``accel`` (K, 6): G_k^-1 U_k per harmonic."""
        U = np.asarray(accel, dtype=complex)
        return np.stack([self._inv[self._row(k)] @ U[i] for i, k in enumerate(ks)])

    def restricted(self, ks: Sequence[int]) -> PlantModel:
        rows = [self._row(int(k)) for k in ks]
        return PlantModel(
            self.frequency_hz,
            self.k[rows],
            self.G[rows],
            self.source,
            self.max_condition,
            self.length_scale_m,
        )


def as_plant(
    plant: PlantModel | PlantSource | Mapping[int, Any], frequency_hz: float, ks: Sequence[int]
) -> PlantModel:
    """A :class:`PlantModel` covering harmonics ``ks`` at ``frequency_hz`` from a model, callable or table."""
    if isinstance(plant, PlantModel):
        if not math.isclose(plant.frequency_hz, frequency_hz, rel_tol=1e-9):
            raise ConfigError(f"plant is for {plant.frequency_hz:g} Hz, the goal for {frequency_hz:g} Hz")
        if not plant.covers(ks):
            raise ConfigError(f"plant ({plant.source}) covers harmonics {plant.k.tolist()}, needs {list(ks)}")
        return plant
    if isinstance(plant, Mapping):
        model = PlantModel.from_table(frequency_hz, plant)
        return as_plant(model, frequency_hz, ks)
    if callable(plant):
        return PlantModel.from_response(plant, frequency_hz, ks)
    raise ConfigError(
        f"plant: expected a PlantModel, a frequency-response callable or a table, got {type(plant).__name__}"
    )


__all__ = ["DEFAULT_MAX_PLANT_CONDITION", "PlantModel", "as_plant"]

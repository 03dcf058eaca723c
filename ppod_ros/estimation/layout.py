"""Accelerometer layouts: single-axis channels on the plate and the first-order measurement model.

A channel sits at plate-frame position ``l`` (m) and reads along a unit sensing axis ``e`` fixed in
the plate. To first order (PHYSICS.md, "Accelerometers") it reads ``e . (p'' + alpha x l)``, i.e.
the row ``[e, l x e]`` applied to ``u = [p''x, p''y, p''z, alpha_x, alpha_y, alpha_z]``. Dual- and
tri-axial units are several channels at one position.

The plate's tilt also turns gravity into the in-plane axes at the plate's own frequencies. With the
specific force ``f = a - g_vec`` (``g_vec = -g z``) expressed in the tilted plate frame,
``R^T z ~ z - theta x z``, a channel gains ``-g e . (theta x z)``; per harmonic the tilt is
``theta_k = -alpha_k / (k Omega)^2``, so the gain is ``(g / (k Omega)^2) e . (alpha_k x z)
= alpha_k . ((g / (k Omega)^2) z x e)``. That is linear in ``alpha_k``: it is exactly a lever arm
lengthened by ``g / (k Omega)^2`` along +z, and :meth:`AccelerometerLayout.measurement_matrix`
includes it per harmonic (docs/feedback.md has the full derivation and the second-order terms).

Layouts are loaded from the ``accelerometers`` mapping of the device YAML (docs/feedback.md)::

    channels:
      - {name: u1, position_m: [0.167, 0.030, -0.025], axes: {t: [-0.174, 0.985, 0], z: [0, 0, 1]}}
      - {name: x0, position_m: [0.1, 0, 0], axis: [1, 0, 0], full_scale_mps2: 160}
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ppod_ros.config.fields import Fields, check_array, load_yaml_file
from ppod_ros.errors import ConfigError
from ppod_ros.motion import AXES, DEFAULT_LENGTH_SCALE_M, GRAVITY_MPS2

#: Largest condition number (angular axes scaled by the length scale) a usable channel set may have.
DEFAULT_MAX_CONDITION = 1.0e3
#: PHYSICS.md's common layout: six dual-axis units at radius 0.17 m, 0.025 m below the surface.
DEFAULT_RADIUS_M = 0.17
DEFAULT_DEPTH_M = -0.025
DEFAULT_ANGLES_DEG = (10.0, 110.0, 130.0, 230.0, 250.0, 350.0)


@dataclass(frozen=True)
class Observability:
    """How well a set of channels determines the six plate-acceleration components.

    Attributes
    ----------
    condition : float
        Ratio of the largest to the smallest singular value of the measurement matrix with the
        angular columns scaled by the length scale (inf when rank-deficient).
    singular_values : ndarray, shape (6,)
        Singular values, descending (m/s^2 read per m/s^2 of scaled motion).
    weakest : ndarray, shape (6,)
        Unit combination of [p''x, p''y, p''z, L alpha_x, L alpha_y, L alpha_z] that the channels
        see least (the right singular vector of the smallest singular value).
    """

    condition: float
    singular_values: np.ndarray
    weakest: np.ndarray
    length_scale_m: float = DEFAULT_LENGTH_SCALE_M

    def ok(self, max_condition: float = DEFAULT_MAX_CONDITION) -> bool:
        return bool(self.condition <= max_condition)

    def describe_weakest(self) -> str:
        """The least observable combination in words, e.g. ``0.71 alpha_z + 0.71 ddpx``."""
        w = self.weakest * np.sign(self.weakest[np.argmax(np.abs(self.weakest))])
        order = np.argsort(-np.abs(w))
        terms = [f"{w[j]:+.2f} {AXES[j]}" for j in order if abs(w[j]) >= 0.05]
        text = " ".join(terms).lstrip("+")
        return f"{text} (angular axes scaled by L = {self.length_scale_m:g} m)"


@dataclass(frozen=True, eq=False)
class AccelerometerLayout:
    """Single-axis accelerometer channels fixed in the plate frame.

    Parameters
    ----------
    names : sequence of str, length C
        Unique channel names (they name channels in reports and recordings).
    position_m : array_like, shape (C, 3)
        Channel positions l in the plate frame (m).
    axis : array_like, shape (C, 3)
        Sensing axes e in the plate frame; each must have unit length (within 1e-3, then renormalised).
    full_scale_mps2 : array_like, shape (C,), optional
        Saturation level of each channel (m/s^2); inf where unknown.
    max_condition : float
        The layout is rejected when all its channels together cannot determine the six components
        with at most this condition number (angular axes scaled by ``length_scale_m``).
    """

    names: tuple[str, ...]
    position_m: np.ndarray
    axis: np.ndarray
    full_scale_mps2: np.ndarray | None = None
    max_condition: float = DEFAULT_MAX_CONDITION
    length_scale_m: float = DEFAULT_LENGTH_SCALE_M
    _rows: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        names = tuple(self.names)
        C = len(names)
        if not all(isinstance(n, str) and n for n in names):
            raise ConfigError(f"accelerometers: channel names must be non-empty strings, got {names}")
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ConfigError(f"accelerometers: duplicate channel names {dup}")
        pos = check_array(self.position_m, "accelerometers.position_m", shape=(C, 3), unit="m")
        ax = check_array(self.axis, "accelerometers.axis", shape=(C, 3))
        norms = np.linalg.norm(ax, axis=1)
        bad = np.flatnonzero(np.abs(norms - 1.0) > 1e-3)
        if bad.size:
            raise ConfigError(
                f"accelerometers: sensing axis of {[names[i] for i in bad]} must be a unit vector, "
                f"got lengths {norms[bad].round(4).tolist()}"
            )
        ax = ax / norms[:, None]
        fs = np.full(C, np.inf) if self.full_scale_mps2 is None else np.asarray(self.full_scale_mps2, float)
        if fs.shape != (C,) or np.any(np.isnan(fs)) or np.any(fs <= 0):
            raise ConfigError(
                f"accelerometers.full_scale_mps2: expected {C} values > 0 m/s^2, got {fs.tolist()}"
            )
        if not (self.max_condition > 1 and self.length_scale_m > 0):
            raise ConfigError("accelerometers: max_condition must be > 1 and length_scale_m > 0")
        for arr in (pos, ax, fs):
            arr.setflags(write=False)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "position_m", pos)
        object.__setattr__(self, "axis", ax)
        object.__setattr__(self, "full_scale_mps2", fs)
        object.__setattr__(self, "_rows", np.hstack([ax, np.cross(pos, ax)]))
        if C < 6:
            raise ConfigError(f"accelerometers: {C} channels cannot determine 6 components; need at least 6")
        obs = self.observability()
        if not obs.ok(self.max_condition):
            raise ConfigError(
                f"accelerometers: the layout cannot determine all six plate-acceleration components "
                f"(condition number {obs.condition:.3g} > {self.max_condition:g}); unobservable: "
                f"{obs.describe_weakest()}"
            )

    # ------------------------------------------------------------------ construction
    @classmethod
    def default(cls) -> AccelerometerLayout:
        """PHYSICS.md's common layout: six dual-axis units (tangential ``.t`` and vertical ``.z``)."""
        names, pos, ax = [], [], []
        for deg in DEFAULT_ANGLES_DEG:
            th = math.radians(deg)
            p = [DEFAULT_RADIUS_M * math.cos(th), DEFAULT_RADIUS_M * math.sin(th), DEFAULT_DEPTH_M]
            for suffix, e in (("t", [-math.sin(th), math.cos(th), 0.0]), ("z", [0.0, 0.0, 1.0])):
                names.append(f"u{deg:g}.{suffix}")
                pos.append(p)
                ax.append(e)
        return cls(tuple(names), np.array(pos), np.array(ax))

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = "accelerometers") -> AccelerometerLayout:
        """Parse the ``accelerometers`` mapping strictly (unknown keys are errors naming the key)."""
        f = Fields(data, where)
        max_cond = f.number("max_condition", DEFAULT_MAX_CONDITION, min_value=1.0, exclusive_min=True)
        length = f.number(
            "length_scale_m", DEFAULT_LENGTH_SCALE_M, min_value=0.0, exclusive_min=True, unit="m"
        )
        names, pos, ax, fs = [], [], [], []
        for item in f.items("channels"):
            name = item.string("name")
            p = item.array("position_m", shape=(3,), unit="m")
            full = (
                item.number("full_scale_mps2", math.inf, min_value=0.0, exclusive_min=True, unit="m/s^2")
                if item.has("full_scale_mps2")
                else math.inf
            )
            if item.has("axis") == item.has("axes"):
                raise ConfigError(
                    f"{item.path}: give exactly one of 'axis' (one channel) or 'axes' "
                    f"(a mapping of suffix to axis for a multi-axis unit)"
                )
            if item.has("axis"):
                axes = {"": item.array("axis", shape=(3,))}
            else:
                raw = item.raw("axes")
                if not isinstance(raw, Mapping) or not raw:
                    raise ConfigError(
                        f"{item.key_path('axes')}: expected a non-empty mapping of suffix to "
                        f"[ex, ey, ez], got {raw!r}"
                    )
                sub = Fields(raw, item.key_path("axes"))
                axes = {str(s): sub.array(s, shape=(3,)) for s in raw}
                sub.finish()
            item.finish()
            for suffix, e in axes.items():
                names.append(f"{name}.{suffix}" if suffix else name)
                pos.append(p)
                ax.append(e)
                fs.append(full)
        f.finish()
        if not names:
            raise ConfigError(f"{f.key_path('channels')}: no channels given")
        try:
            return cls(
                tuple(names),
                np.array(pos),
                np.array(ax),
                np.array(fs),
                max_condition=max_cond,
                length_scale_m=length,
            )
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from exc

    @classmethod
    def from_yaml(cls, path: str | Path, key: str | None = "accelerometers") -> AccelerometerLayout:
        """Load from a YAML file: the mapping under ``key`` (None: the whole file is the layout)."""
        data = load_yaml_file(path, "accelerometer layout")
        if key is not None:
            if key not in data:
                raise ConfigError(f"{path}: required key '{key}' is missing")
            data = data[key]
        try:
            return cls.from_dict(data, key or "accelerometers")
        except ConfigError as exc:
            raise ConfigError(f"{path}: {exc}") from exc

    def to_dict(self) -> dict[str, Any]:
        """The ``accelerometers`` mapping, one single-axis entry per channel (round-trips)."""
        chans = []
        for i, name in enumerate(self.names):
            entry: dict[str, Any] = {
                "name": name,
                "position_m": [float(v) for v in self.position_m[i]],
                "axis": [float(v) for v in self.axis[i]],
            }
            if math.isfinite(self.full_scale_mps2[i]):
                entry["full_scale_mps2"] = float(self.full_scale_mps2[i])
            chans.append(entry)
        return {"max_condition": self.max_condition, "length_scale_m": self.length_scale_m, "channels": chans}

    # ------------------------------------------------------------------ model
    @property
    def num_channels(self) -> int:
        return len(self.names)

    def index(self, names: Sequence[str]) -> np.ndarray:
        """Channel indices of ``names`` (ConfigError naming any unknown channel)."""
        lookup = {n: i for i, n in enumerate(self.names)}
        missing = [n for n in names if n not in lookup]
        if missing:
            raise ConfigError(f"channels {missing} are not in the accelerometer layout {list(self.names)}")
        return np.array([lookup[n] for n in names], dtype=int)

    def measurement_matrix(
        self, omega_k: float | None = None, gravity_mps2: float = GRAVITY_MPS2
    ) -> np.ndarray:
        """Readings per unit plate acceleration, shape (C, 6).

        Parameters
        ----------
        omega_k : float or None
            Angular frequency k Omega (rad/s) of the harmonic; None gives the pure first-order
            model ``[e, l x e]``; otherwise the tilted-gravity term of that harmonic is included.
        gravity_mps2 : float
            g used for the tilt term (m/s^2).
        """
        if omega_k is None:
            return self._rows.copy()
        if not omega_k > 0:
            raise ConfigError(f"omega_k: must be > 0 rad/s, got {omega_k}")
        lever = self.position_m + np.array([0.0, 0.0, gravity_mps2 / omega_k**2])
        return np.hstack([self.axis, np.cross(lever, self.axis)])

    def observability(
        self, use: np.ndarray | None = None, omega_k: float | None = None, gravity_mps2: float = GRAVITY_MPS2
    ) -> Observability:
        """Conditioning of the channels selected by the boolean mask ``use`` (C,) (default all)."""
        H = self.measurement_matrix(omega_k, gravity_mps2)
        if use is not None:
            H = H[np.asarray(use, dtype=bool)]
        return observability_of(H, self.length_scale_m)


def observability_of(H: np.ndarray, length_scale_m: float = DEFAULT_LENGTH_SCALE_M) -> Observability:
    """Observability of a measurement matrix H, shape (C, 6)."""
    scale = np.array([1, 1, 1, 1 / length_scale_m, 1 / length_scale_m, 1 / length_scale_m])
    Hs = H * scale
    if Hs.shape[0] < 6:
        # Fewer rows than unknowns: pad so the SVD still names a combination nobody sees.
        Hs = np.vstack([Hs, np.zeros((6 - Hs.shape[0], 6))])
    _, s, vt = np.linalg.svd(Hs)
    cond = math.inf if s[-1] <= s[0] * 1e-12 else float(s[0] / s[-1])
    return Observability(cond, s, vt[-1], length_scale_m)


__all__ = ["AccelerometerLayout", "DEFAULT_MAX_CONDITION", "Observability", "observability_of"]

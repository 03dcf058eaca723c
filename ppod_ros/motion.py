"""Periodic plate motions: the control vector of the PPOD (PHYSICS.md, "Plate motion").

A plate motion is the acceleration of the plate frame's origin and the plate's angular acceleration,

    u_j(t) = sum_k A_jk sin(k Omega t + phi_jk),   j over AXES,  Omega = 2 pi f,

with velocity and displacement the zero-mean integrals. :class:`PlateMotion` holds it as arrays,
validates it (the MOTION.yaml format of docs/formats.md), converts to and from phasors
``X_jk = A_jk exp(i phi_jk)`` (so ``u_j(t) = Im(X_jk exp(i k Omega t))``), evaluates it in time,
and evaluates the plate's kinematics at plate points.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ppod_ros.config.fields import Fields, check_array, check_number, load_yaml_file, parse_yaml_text
from ppod_ros.errors import ConfigError

#: Axis order of every 6-vector of plate motion: linear acceleration of P's origin (m/s^2),
#: then angular acceleration (rad/s^2), all in the plate frame.
AXES = ("ddpx", "ddpy", "ddpz", "alpha_x", "alpha_y", "alpha_z")
AXIS_UNITS = ("m/s^2", "m/s^2", "m/s^2", "rad/s^2", "rad/s^2", "rad/s^2")
MAX_HARMONIC = 10
GRAVITY_MPS2 = 9.81
#: Length that scales angular components into m/s^2 for the acceleration error measure.
DEFAULT_LENGTH_SCALE_M = 0.1


@dataclass(frozen=True, eq=False)
class PlateMotion:
    """A periodic 6-DoF plate motion, validated on construction.

    Parameters
    ----------
    frequency_hz : float
        Fundamental frequency f (Hz), finite and > 0.
    k : array_like of int, shape (K,)
        Harmonic numbers, each in 1..10 and at most once. Stored sorted ascending.
    amplitude : array_like, shape (K, 6)
        A_jk >= 0 per harmonic and axis (m/s^2 for the first three axes, rad/s^2 for the rest).
    phase : array_like, shape (K, 6)
        phi_jk (rad), absolute per axis, referenced to the device's cycle start.
    name : str
        Free text.
    ramp_time_s : float or None
        How long the device takes to reach this motion (goals only); None = device default.
    """

    frequency_hz: float
    k: np.ndarray
    amplitude: np.ndarray
    phase: np.ndarray
    name: str = ""
    ramp_time_s: float | None = None
    _key: bytes = field(init=False, repr=False, compare=False)
    _zero: bool = field(init=False, repr=False, compare=False)
    _memo: dict = field(init=False, repr=False, compare=False)   # values derived from the (immutable)
    # arrays by other modules, e.g. the solver's coefficient table

    def __post_init__(self) -> None:
        if not self._init_checked_arrays():
            self._init_validated()
        object.__setattr__(self, "_key", _motion_key(self.frequency_hz, self.k, self.amplitude, self.phase))
        object.__setattr__(self, "_zero", not np.any(self.amplitude > 0))
        object.__setattr__(self, "_memo", {})

    def _init_checked_arrays(self) -> bool:
        """The common construction from arrays (the planner builds about 90 motions per replanning
        step): float64 amplitudes and phases (K, 6), int64 harmonics already ascending, no ramp time.
        The same checks as :meth:`_init_validated` in fewer steps; False (nothing set) for any input
        outside that case or failing a check, which the validated path then reports."""
        f, k, amp, ph = self.frequency_hz, self.k, self.amplitude, self.phase
        if not (type(f) in (float, np.float64) and math.isfinite(f) and f > 0.0 and self.ramp_time_s is None
                and type(self.name) is str and type(k) is np.ndarray and k.dtype == np.int64 and k.ndim == 1
                and type(amp) is np.ndarray and amp.dtype == np.float64
                and type(ph) is np.ndarray and ph.dtype == np.float64):
            return False
        K = k.shape[0]
        if amp.shape != (K, 6) or ph.shape != (K, 6):
            return False
        ks = k.tolist()
        last = 0
        for kk in ks:   # each in 1..MAX_HARMONIC, strictly ascending (so each at most once)
            if not last < kk <= MAX_HARMONIC:
                return False
            last = kk
        if K and not (np.isfinite(amp).all() and np.isfinite(ph).all() and (amp >= 0.0).all()):
            return False
        self._set_arrays(f, k.copy(), amp.copy(), ph.copy())
        return True

    def _set_arrays(self, f: float, k: np.ndarray, amp: np.ndarray, ph: np.ndarray) -> None:
        """Store checked, owned arrays read-only (and the frequency as a float)."""
        for arr in (k, amp, ph):
            arr.setflags(write=False)
        object.__setattr__(self, "frequency_hz", float(f))
        object.__setattr__(self, "k", k)
        object.__setattr__(self, "amplitude", amp)
        object.__setattr__(self, "phase", ph)

    def _init_validated(self) -> None:
        """Validate and normalise any input (the MOTION.yaml rules); ConfigError naming the field."""
        f = check_number(self.frequency_hz, "frequency_hz", min_value=0.0, exclusive_min=True, unit="Hz")
        k = np.asarray(self.k)
        if k.ndim != 1:
            raise ConfigError(f"harmonics: k must be a 1-D list of harmonic numbers, got shape {k.shape}")
        if k.size and (k.dtype.kind not in "iuf" or not np.all(np.isfinite(k)) or not np.all(k == np.round(k))):
            raise ConfigError(f"harmonics: k must be integers, got {k.tolist()}")
        k = k.astype(np.int64)
        K = k.size
        if np.any((k < 1) | (k > MAX_HARMONIC)):
            raise ConfigError(f"harmonics: k must lie in 1..{MAX_HARMONIC}, got {k.tolist()}")
        if len(set(k.tolist())) != K:
            raise ConfigError(f"harmonics: each k may appear at most once, got {k.tolist()}")
        amp = check_array(self.amplitude, "harmonics.amplitude", shape=(K, 6)) if K else np.zeros((0, 6))
        ph = check_array(self.phase, "harmonics.phase", shape=(K, 6)) if K else np.zeros((0, 6))
        if np.any(amp < 0):
            raise ConfigError(
                f"harmonics.amplitude: amplitudes must be >= 0 (use the phase for sign), got {amp.tolist()}")
        if self.ramp_time_s is not None:
            ramp = check_number(self.ramp_time_s, "ramp_time_s", min_value=0.0, unit="s")
            object.__setattr__(self, "ramp_time_s", ramp)
        if not isinstance(self.name, str):
            raise ConfigError(f"name: expected a string, got {self.name!r}")
        order = np.argsort(k)
        self._set_arrays(f, np.array(k[order]), np.array(amp[order], dtype=float), np.array(ph[order], dtype=float))

    # ------------------------------------------------------------------ construction
    @classmethod
    def zero(cls, frequency_hz: float = 30.0, name: str = "zero") -> PlateMotion:
        """The motion with no harmonics (the plate at rest)."""
        return cls(frequency_hz, np.zeros(0, int), np.zeros((0, 6)), np.zeros((0, 6)), name=name)

    @classmethod
    def from_phasors(cls, frequency_hz: float, k: Any, phasors: Any, *, name: str = "",
                     ramp_time_s: float | None = None) -> PlateMotion:
        """Build from complex phasors ``X_jk = A_jk exp(i phi_jk)``, shape (K, 6)."""
        X = np.asarray(phasors, dtype=complex)
        if X.ndim != 2 or X.shape[1] != 6:
            raise ConfigError(f"phasors: expected shape (K, 6), got {X.shape}")
        if not np.all(np.isfinite(X)):
            raise ConfigError("phasors: all values must be finite")
        return cls(frequency_hz, np.asarray(k), np.abs(X), np.angle(X), name=name, ramp_time_s=ramp_time_s)

    @classmethod
    def single(cls, frequency_hz: float, amplitude: Any, phase: Any = None, *, name: str = "",
               ramp_time_s: float | None = None) -> PlateMotion:
        """A one-harmonic (k = 1) motion from 6 amplitudes and 6 phases."""
        amp = np.asarray(amplitude, dtype=float).reshape(1, -1)
        ph = np.zeros_like(amp) if phase is None else np.asarray(phase, dtype=float).reshape(1, -1)
        return cls(frequency_hz, np.array([1]), amp, ph, name=name, ramp_time_s=ramp_time_s)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = "") -> PlateMotion:
        """Parse the MOTION.yaml mapping (docs/formats.md), strictly: unknown keys are errors."""
        f = Fields(data, where)
        name = f.string("name", "")
        if name is None:
            name = ""
        freq = f.number("frequency_hz", exclusive_min=True, min_value=0.0, unit="Hz")
        ramp = f.number("ramp_time_s", None, min_value=0.0, unit="s")
        ks, amps, phases = [], [], []
        items = f.items("harmonics", [])
        if len(items) > MAX_HARMONIC:
            raise ConfigError(f"{f.key_path('harmonics')}: at most {MAX_HARMONIC} harmonics, got {len(items)}")
        for item in items:
            k = item.integer("k", min_value=1, max_value=MAX_HARMONIC)
            if k in ks:
                raise ConfigError(f"{item.key_path('k')}: harmonic {k} appears more than once")
            amp = item.array("amplitude", shape=(6,), min_value=0.0, unit="m/s^2 or rad/s^2")
            ph = item.array("phase", [0.0] * 6, shape=(6,), unit="rad")
            item.finish()
            ks.append(k)
            amps.append(amp)
            phases.append(ph)
        f.finish()
        return cls(freq, np.array(ks, dtype=np.int64), np.array(amps).reshape(-1, 6),
                   np.array(phases).reshape(-1, 6), name=name, ramp_time_s=ramp)

    @classmethod
    def from_yaml(cls, path: str | Path) -> PlateMotion:
        """Load a MOTION.yaml file; errors name the file and the key."""
        data = load_yaml_file(path, "motion")
        try:
            return cls.from_dict(data)
        except ConfigError as exc:
            raise ConfigError(f"{path}: {exc}") from exc

    @classmethod
    def from_yaml_text(cls, text: str, origin: str = "motion") -> PlateMotion:
        data = parse_yaml_text(text, origin)
        try:
            return cls.from_dict(data)
        except ConfigError as exc:
            raise ConfigError(f"{origin}: {exc}") from exc

    def to_dict(self) -> dict[str, Any]:
        """The MOTION.yaml mapping (round-trips through :meth:`from_dict`)."""
        out: dict[str, Any] = {}
        if self.name:
            out["name"] = self.name
        out["frequency_hz"] = self.frequency_hz
        if self.ramp_time_s is not None:
            out["ramp_time_s"] = self.ramp_time_s
        out["harmonics"] = [
            {"k": int(k), "amplitude": [float(a) for a in amp], "phase": [float(p) for p in ph]}
            for k, amp, ph in zip(self.k, self.amplitude, self.phase)
        ]
        return out

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.to_dict(), sort_keys=False, default_flow_style=None)

    # ------------------------------------------------------------------ derived quantities
    @property
    def omega(self) -> float:
        """Fundamental angular frequency Omega = 2 pi f (rad/s)."""
        return 2.0 * math.pi * self.frequency_hz

    @property
    def period_s(self) -> float:
        return 1.0 / self.frequency_hz

    @property
    def num_harmonics(self) -> int:
        return int(self.k.size)

    @property
    def key(self) -> bytes:
        """A hashable identity of the physical motion (for caches): frequency and nonzero phasors."""
        return self._key

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, PlateMotion):
            return NotImplemented
        return self._key == other._key

    def __hash__(self) -> int:
        return hash(self._key)

    def phasors(self) -> np.ndarray:
        """Complex phasors X_jk = A_jk exp(i phi_jk), shape (K, 6)."""
        return self.amplitude * np.exp(1j * self.phase)

    def phasor_table(self, kmax: int | None = None) -> np.ndarray:
        """Phasors on a dense harmonic axis: row k-1 holds harmonic k, shape (kmax, 6)."""
        kmax = int(self.k.max()) if kmax is None and self.k.size else (kmax or 0)
        out = np.zeros((kmax, 6), dtype=complex)
        X = self.phasors()
        for row, k in enumerate(self.k):
            if k <= kmax:
                out[k - 1] = X[row]
        return out

    def active_axes(self) -> np.ndarray:
        """Boolean mask (6,) of axes with any nonzero amplitude."""
        return np.any(self.amplitude > 0, axis=0) if self.k.size else np.zeros(6, bool)

    def is_zero(self) -> bool:
        return self._zero

    def pruned(self) -> PlateMotion:
        """The same motion without harmonics whose six amplitudes are all zero (this motion itself
        when it has none: motions are immutable)."""
        keep = np.any(self.amplitude > 0, axis=1)
        if keep.all():
            return self
        return PlateMotion(self.frequency_hz, self.k[keep], self.amplitude[keep], self.phase[keep],
                           name=self.name, ramp_time_s=self.ramp_time_s)

    def _series(self, t: Any, power: int) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        out = np.zeros(t.shape + (6,))
        if not self.k.size:
            return out
        w = self.omega * self.k.astype(float)  # (K,)
        arg = t[..., None, None] * w[:, None] + self.phase  # (..., K, 6)
        if power == 0:
            terms = self.amplitude * np.sin(arg)
        elif power == 1:
            terms = -(self.amplitude / w[:, None]) * np.cos(arg)
        else:
            terms = -(self.amplitude / (w[:, None] ** 2)) * np.sin(arg)
        return terms.sum(axis=-2)

    def acceleration(self, t: Any) -> np.ndarray:
        """u(t) = [p''x, p''y, p''z, alpha_x, alpha_y, alpha_z], shape t.shape + (6,)."""
        return self._series(t, 0)

    def velocity(self, t: Any) -> np.ndarray:
        """Zero-mean velocity [p'x, p'y, p'z, omega_x, omega_y, omega_z], shape t.shape + (6,)."""
        return self._series(t, 1)

    def displacement(self, t: Any) -> np.ndarray:
        """Zero-mean displacement [px, py, pz, phi_x, phi_y, phi_z] (small angles), t.shape + (6,)."""
        return self._series(t, 2)

    def time_shifted(self, tau_s: float) -> PlateMotion:
        """The motion u(t + tau): every harmonic k's phase advanced by k Omega tau."""
        ph = self.phase + self.omega * tau_s * self.k[:, None]
        return PlateMotion(self.frequency_hz, self.k, self.amplitude, ph, name=self.name,
                           ramp_time_s=self.ramp_time_s)

    def mirrored_x(self) -> PlateMotion:
        """The motion reflected in x -> -x (alpha is a pseudovector; PHYSICS.md mirror rule).

        (p''x, p''y, p''z, ax, ay, az) -> (-p''x, p''y, p''z, ax, -ay, -az); a sign flip is a
        phase shift of pi.
        """
        flip = np.array([True, False, False, False, True, True])
        ph = self.phase + np.where(flip, math.pi, 0.0)
        return PlateMotion(self.frequency_hz, self.k, self.amplitude, ph, name=f"{self.name} mirrored",
                           ramp_time_s=self.ramp_time_s)

    def scaled(self, factor: float) -> PlateMotion:
        if not math.isfinite(factor) or factor < 0:
            raise ConfigError(f"factor: must be finite and >= 0, got {factor}")
        return PlateMotion(self.frequency_hz, self.k, self.amplitude * factor, self.phase, name=self.name,
                           ramp_time_s=self.ramp_time_s)

    def describe(self) -> str:
        """A one-line human description, e.g. for plot titles."""
        parts = []
        for k, amp, ph in zip(self.k, self.amplitude, self.phase):
            terms = [f"{AXES[j]}={amp[j]:g}∠{ph[j]:.2f}" for j in range(6) if amp[j] > 0]
            if terms:
                parts.append(f"k={k}: " + ", ".join(terms))
        body = "; ".join(parts) if parts else "zero motion"
        label = f"{self.name}: " if self.name else ""
        return f"{label}f={self.frequency_hz:g} Hz, {body}"


def point_kinematics(motion: PlateMotion, x: Any, y: Any, t: Any) -> dict[str, np.ndarray]:
    """Plate kinematics at plate points r = (x, y, 0) (PHYSICS.md), broadcasting x, y against t.

    Returns a dict with ``a_h`` (..., 2) horizontal acceleration, ``a_n`` (...) vertical
    acceleration and ``v_h`` (..., 2) horizontal velocity, without centripetal terms.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    u = motion.acceleration(t)
    v = motion.velocity(t)
    a_h = np.stack([u[..., 0] - u[..., 5] * y, u[..., 1] + u[..., 5] * x], axis=-1)
    a_n = u[..., 2] + u[..., 3] * y - u[..., 4] * x
    v_h = np.stack([v[..., 0] - v[..., 5] * y, v[..., 1] + v[..., 5] * x], axis=-1)
    return {"a_h": a_h, "a_n": a_n, "v_h": v_h}


def acceleration_error(goal: np.ndarray, achieved: np.ndarray, length_scale_m: float = DEFAULT_LENGTH_SCALE_M
                       ) -> tuple[float, float]:
    """The PHYSICS.md acceleration error measure between two phasor tables.

    Parameters
    ----------
    goal, achieved : complex arrays, shape (K, 6)
        Phasor tables on the same harmonic axis (rows are harmonics; include rows for harmonics
        the goal lacks, with zero goal). Angular components are scaled by ``length_scale_m``.

    Returns
    -------
    (absolute, relative): ||e|| in m/s^2 and ||e|| / ||goal||, norms over all harmonics and axes.
    """
    goal = np.asarray(goal, dtype=complex)
    achieved = np.asarray(achieved, dtype=complex)
    if goal.shape != achieved.shape or goal.ndim != 2 or goal.shape[1] != 6:
        raise ConfigError(f"goal, achieved: expected equal shapes (K, 6), got {goal.shape} and {achieved.shape}")
    scale = np.array([1, 1, 1, length_scale_m, length_scale_m, length_scale_m])
    e = np.linalg.norm((achieved - goal) * scale)
    g = np.linalg.norm(goal * scale)
    return float(e), float(e / g) if g > 0 else (0.0 if e == 0 else math.inf)


def crossfade(old: PlateMotion | None, new: PlateMotion, a: float) -> PlateMotion:
    """The plate motion the generator's ramp from ``old`` to ``new`` plays at fraction ``a`` (0..1):
    the two tables mixed, ``(1 - a) old + a new`` (the plant is linear, so the plate motion mixes as
    the currents do); from rest (``old`` None or zero) ``new`` scaled by ``a``; to rest ``old`` by
    ``1 - a``; between two frequencies ``old`` faded out over the first half and ``new`` in over the
    second. Velocity fields are far from linear in the motion, so the parts' velocity under the mix
    is not the mix of their velocities (``MpcSettings.ramp_midpoint``)."""
    if a >= 1.0 or old is None:
        return new.scaled(a) if old is None and a < 1.0 else new
    if new.is_zero() or old.is_zero() or abs(new.frequency_hz - old.frequency_hz) > 1e-9:
        if new.is_zero() and not old.is_zero():
            return old.scaled(1.0 - a)
        if old.is_zero():
            return new.scaled(a)
        return old.scaled(1.0 - 2 * a) if a < 0.5 else new.scaled(2 * a - 1.0)
    k = sorted(set(old.k.tolist()) | set(new.k.tolist()))
    Xo, Xn = old.phasor_table(max(k)), new.phasor_table(max(k))
    X = (1 - a) * Xo + a * Xn
    return PlateMotion.from_phasors(new.frequency_hz, np.arange(1, max(k) + 1), X, name=new.name)


def _motion_key(frequency_hz: float, k: np.ndarray, amplitude: np.ndarray, phase: np.ndarray) -> bytes:
    """:attr:`PlateMotion.key` of validated arrays."""
    h = hashlib.sha1()
    h.update(np.float64(frequency_hz).tobytes())
    # The key identifies the motion physically: zero-amplitude entries and their phases do not
    # change the motion, and phases are compared modulo 2 pi.
    X = amplitude * np.exp(1j * phase)   # PlateMotion.phasors
    X = np.where(np.abs(X) > 0, X, 0.0)
    keep = (X != 0).any(axis=1)   # (the methods np.any and np.round call, without their wrappers)
    h.update(k[keep].tobytes())
    h.update((X[keep].view(float).round(10) + 0.0).tobytes())
    return h.digest()


__all__ = [
    "AXES",
    "AXIS_UNITS",
    "DEFAULT_LENGTH_SCALE_M",
    "GRAVITY_MPS2",
    "MAX_HARMONIC",
    "PlateMotion",
    "acceleration_error",
    "crossfade",
    "point_kinematics",
]

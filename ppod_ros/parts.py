"""Part descriptions: point parts and rigid parts with three point contacts (PHYSICS.md).

Both load from the PART.yaml format (docs/formats.md), strictly validated. A footprint (disk,
rectangle or polygon, metres, body frame) is optional and used by the renderer and the tracker.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ppod_ros.config.fields import Fields, check_array, load_yaml_file, parse_yaml_text
from ppod_ros.errors import ConfigError


@dataclass(frozen=True, eq=False)
class Footprint:
    """The outline of a part seen from above, in its body frame (metres).

    kind is ``"disk"`` (``size`` = (radius,)), ``"rect"`` (``size`` = (width along x, length along
    y)) or ``"polygon"`` (``vertices`` (M, 2), counter-clockwise after loading).
    """

    kind: str
    size: tuple[float, ...] = ()
    vertices: np.ndarray | None = None

    @classmethod
    def from_value(cls, value: Any, name: str = "footprint") -> Footprint:
        if not isinstance(value, Mapping) or len(value) != 1:
            raise ConfigError(f"{name}: expected exactly one of {{disk: r}}, {{rect: [w, l]}} or "
                              f"{{polygon: [[x, y], ...]}}, got {value!r}")
        (kind, arg), = value.items()
        if kind == "disk":
            r = check_array(arg, f"{name}.disk", shape=(), unit="m")
            if r <= 0:
                raise ConfigError(f"{name}.disk: radius must be > 0 m, got {float(r)}")
            return cls("disk", (float(r),))
        if kind == "rect":
            wl = check_array(arg, f"{name}.rect", shape=(2,), unit="m")
            if np.any(wl <= 0):
                raise ConfigError(f"{name}.rect: width and length must be > 0 m, got {wl.tolist()}")
            return cls("rect", (float(wl[0]), float(wl[1])))
        if kind == "polygon":
            v = check_array(arg, f"{name}.polygon", shape=(None, 2), unit="m")
            if len(v) < 3:
                raise ConfigError(f"{name}.polygon: needs at least 3 vertices, got {len(v)}")
            area = _signed_area(v)
            if abs(area) < 1e-12:
                raise ConfigError(f"{name}.polygon: vertices enclose no area")
            if area < 0:
                v = v[::-1].copy()
            v.setflags(write=False)
            return cls("polygon", (), v)
        raise ConfigError(f"{name}: unknown footprint kind {kind!r}; expected disk, rect or polygon")

    def outline(self, n_disk: int = 48) -> np.ndarray:
        """Vertices (M, 2) of the outline in the body frame, counter-clockwise."""
        if self.kind == "disk":
            a = np.linspace(0, 2 * math.pi, n_disk, endpoint=False)
            return self.size[0] * np.stack([np.cos(a), np.sin(a)], axis=1)
        if self.kind == "rect":
            w, l = self.size
            return np.array([[-w / 2, -l / 2], [w / 2, -l / 2], [w / 2, l / 2], [-w / 2, l / 2]])
        assert self.vertices is not None
        return np.array(self.vertices)

    @property
    def area_m2(self) -> float:
        if self.kind == "disk":
            return math.pi * self.size[0] ** 2
        return abs(_signed_area(self.outline()))

    @property
    def symmetry_rad(self) -> float:
        """Rotational symmetry period of the outline: 0 for a disk (orientation undefined),
        pi for a non-square rectangle, pi/2 for a square, 2 pi/n for a regular n-gon, 2 pi if none."""
        if self.kind == "disk":
            return 0.0
        if self.kind == "rect":
            w, l = self.size
            return math.pi / 2 if math.isclose(w, l, rel_tol=1e-9) else math.pi
        v = self.outline()
        c = _centroid(v)
        for n in range(len(v), 1, -1):
            if len(v) % n:
                continue
            a = 2 * math.pi / n
            R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
            rotated = (v - c) @ R.T
            d = np.linalg.norm(rotated[:, None, :] - (v - c)[None, :, :], axis=2).min(axis=1)
            if np.all(d < 1e-9 + 1e-6 * np.abs(v).max()):
                return a
        return 2 * math.pi

    def to_value(self) -> dict[str, Any]:
        if self.kind == "disk":
            return {"disk": self.size[0]}
        if self.kind == "rect":
            return {"rect": list(self.size)}
        return {"polygon": np.asarray(self.vertices).tolist()}


def _signed_area(v: np.ndarray) -> float:
    x, y = v[:, 0], v[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _centroid(v: np.ndarray) -> np.ndarray:
    x, y = v[:, 0], v[:, 1]
    cross = x * np.roll(y, -1) - np.roll(x, -1) * y
    a = cross.sum() / 2
    return np.array([((x + np.roll(x, -1)) * cross).sum(), ((y + np.roll(y, -1)) * cross).sum()]) / (6 * a)


@dataclass(frozen=True, eq=False)
class PointPart:
    """A point part with kinetic friction ``mu`` and static friction ``mu_static`` (>= mu)."""

    mu: float = 0.3
    mu_static: float | None = None
    footprint: Footprint | None = None

    def __post_init__(self) -> None:
        mu = _check_mu(self.mu, "mu")
        ms = mu if self.mu_static is None else _check_mu(self.mu_static, "mu_static")
        if ms < mu:
            raise ConfigError(f"mu_static: must be >= mu ({mu}), got {ms}")
        object.__setattr__(self, "mu", mu)
        object.__setattr__(self, "mu_static", ms)

    @property
    def kind(self) -> str:
        return "point"

    @property
    def key(self) -> tuple:
        return ("point", self.mu, self.mu_static)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "point", "mu": self.mu, "mu_static": self.mu_static}
        if self.footprint is not None:
            out["footprint"] = self.footprint.to_value()
        return out


@dataclass(frozen=True, eq=False)
class RigidPart:
    """A rigid part resting on three point contacts (PHYSICS.md, "Rigid part").

    Parameters
    ----------
    mass : float
        kg, > 0.
    inertia : array_like, shape (3, 3) or (3,)
        Inertia about the centre of mass in the body frame (kg m^2), symmetric positive definite;
        three values are a diagonal.
    contacts : array_like, shape (3, 3)
        Contact points r_i in the body frame relative to the centre of mass (m). All share the
        z-component -h <= 0; they must not be collinear.
    mu, mu_static : array_like, shape (3,) or scalar
        Per-contact kinetic and static friction (mu_static >= mu; defaults to mu).
    footprint : Footprint, optional
        Outline for rendering and tracking; defaults to the triangle of the contacts.
    """

    mass: float
    inertia: np.ndarray
    contacts: np.ndarray
    mu: np.ndarray
    mu_static: np.ndarray | None = None
    footprint: Footprint | None = None

    def __post_init__(self) -> None:
        from ppod_ros.config.fields import check_number

        mass = check_number(self.mass, "mass", min_value=0.0, exclusive_min=True, unit="kg")
        I = np.asarray(self.inertia, dtype=float) if not isinstance(self.inertia, np.ndarray) else self.inertia
        I = check_array(I, "inertia", unit="kg m^2")
        if I.shape == (3,):
            I = np.diag(I)
        if I.shape != (3, 3):
            raise ConfigError(f"inertia: expected 3 diagonal values or a 3x3 matrix, got shape {I.shape}")
        if not np.allclose(I, I.T, rtol=1e-9, atol=1e-15):
            raise ConfigError("inertia: the 3x3 matrix must be symmetric")
        if np.linalg.eigvalsh(I).min() <= 0:
            raise ConfigError(f"inertia: must be positive definite, eigenvalues {np.linalg.eigvalsh(I).tolist()}")
        c = check_array(self.contacts, "contacts", shape=(3, 3), unit="m")
        if not np.allclose(c[:, 2], c[0, 2], rtol=0, atol=1e-12):
            raise ConfigError(f"contacts: all three contacts must share the same z (the contact plane), "
                              f"got z = {c[:, 2].tolist()}")
        if c[0, 2] > 0:
            raise ConfigError(f"contacts: z must be <= 0 (the centre of mass is h = -z above the plate), "
                              f"got {c[0, 2]}")
        e1 = c[1, :2] - c[0, :2]
        e2 = c[2, :2] - c[0, :2]
        tri_area = 0.5 * abs(e1[0] * e2[1] - e1[1] * e2[0])
        scale = max(np.linalg.norm(e1), np.linalg.norm(e2), 1e-300)
        if tri_area <= 1e-9 * scale**2:
            raise ConfigError("contacts: the three contacts are collinear (degenerate part: it cannot rest "
                              "on them)")
        mu = _mu_array(self.mu, "mu")
        ms = mu if self.mu_static is None else _mu_array(self.mu_static, "mu_static")
        if np.any(ms < mu):
            raise ConfigError(f"mu_static: must be >= mu per contact, got {ms.tolist()} vs {mu.tolist()}")
        for arr in (I, c, mu, ms):
            arr.setflags(write=False)
        object.__setattr__(self, "mass", mass)
        object.__setattr__(self, "inertia", I)
        object.__setattr__(self, "contacts", c)
        object.__setattr__(self, "mu", mu)
        object.__setattr__(self, "mu_static", ms)

    @property
    def kind(self) -> str:
        return "rigid"

    @property
    def h(self) -> float:
        """Height of the centre of mass above the contact plane (m)."""
        return float(-self.contacts[0, 2])

    @property
    def key(self) -> tuple:
        return ("rigid", self.mass, self.inertia.tobytes(), self.contacts.tobytes(), self.mu.tobytes(),
                self.mu_static.tobytes())

    def outline(self) -> np.ndarray:
        """Footprint outline (M, 2) in the body frame (the contact triangle if none was given)."""
        if self.footprint is not None:
            return self.footprint.outline()
        tri = np.array(self.contacts[:, :2])
        return tri if _signed_area(tri) > 0 else tri[::-1]

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "type": "rigid",
            "mass": self.mass,
            "inertia": self.inertia.tolist(),
            "contacts": self.contacts.tolist(),
            "mu": self.mu.tolist(),
            "mu_static": self.mu_static.tolist(),
        }
        if self.footprint is not None:
            out["footprint"] = self.footprint.to_value()
        return out


Part = PointPart | RigidPart


def _check_mu(value: Any, name: str) -> float:
    from ppod_ros.config.fields import check_number

    return check_number(value, name, min_value=0.0)


def _mu_array(value: Any, name: str) -> np.ndarray:
    arr = check_array(value, name)
    if arr.shape == ():
        arr = np.full(3, float(arr))
    if arr.shape != (3,):
        raise ConfigError(f"{name}: expected one value per contact (3), got shape {arr.shape}")
    if np.any(arr < 0):
        raise ConfigError(f"{name}: friction coefficients must be >= 0, got {arr.tolist()}")
    return arr.astype(float)


def part_from_dict(data: Mapping[str, Any], where: str = "") -> Part:
    """Parse the PART.yaml mapping (docs/formats.md), strictly."""
    f = Fields(data, where)
    kind = f.string("type", choices=("point", "rigid"))
    fp_raw = f.raw("footprint", None)
    footprint = None if fp_raw is None else Footprint.from_value(fp_raw, f.key_path("footprint"))
    if kind == "point":
        mu = f.number("mu", 0.3, min_value=0.0)
        ms = f.number("mu_static", None, min_value=0.0)
        f.finish()
        try:
            return PointPart(mu, ms, footprint)
        except ConfigError as exc:
            raise ConfigError(f"{f.path + ': ' if f.path else ''}{exc}") from exc
    mass = f.number("mass", min_value=0.0, exclusive_min=True, unit="kg")
    inertia = f.array("inertia", unit="kg m^2")
    contacts_raw = f.raw("contacts")
    contacts = check_array(contacts_raw, f.key_path("contacts"), unit="m")
    if contacts.shape != (3, 3):
        raise ConfigError(f"{f.key_path('contacts')}: expected exactly three contacts [x, y, z], "
                          f"got shape {contacts.shape}")
    mu = f.raw("mu", 0.3)
    ms = f.raw("mu_static", None)
    f.finish()
    try:
        return RigidPart(mass, inertia, contacts, mu, ms, footprint)
    except ConfigError as exc:
        raise ConfigError(f"{f.path + ': ' if f.path else ''}{exc}") from exc


def load_part(path: str | Path) -> Part:
    """Load a PART.yaml file; errors name the file and the key."""
    data = load_yaml_file(path, "part")
    try:
        return part_from_dict(data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from exc


def part_from_yaml_text(text: str, origin: str = "part") -> Part:
    data = parse_yaml_text(text, origin)
    try:
        return part_from_dict(data)
    except ConfigError as exc:
        raise ConfigError(f"{origin}: {exc}") from exc


#: The rigid part of PHYSICS.md's published example.
def published_rigid_part() -> RigidPart:
    return RigidPart(
        mass=0.0216,
        inertia=np.diag([1.084e-5, 0.123e-5, 1.20e-5]),
        contacts=np.array([[0.01, -0.03, -0.002], [0.0, 0.03, -0.002], [-0.01, -0.03, -0.002]]),
        mu=np.array([0.3, 0.3, 0.3]),
    )


__all__ = [
    "Footprint",
    "Part",
    "PointPart",
    "RigidPart",
    "load_part",
    "part_from_dict",
    "part_from_yaml_text",
    "published_rigid_part",
]

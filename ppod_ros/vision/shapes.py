"""Part types for the tracker and the pose of a blob that matches one.

A :class:`PartSpec` is a label, a footprint (FORMATS.md: disk, rect, polygon; a rigid part without
one uses its contact triangle) and the height of its visible top face. From the footprint it
precomputes reference moments R_n = integral of (z - c)^n over the outline at theta = 0 (z = x + iy,
c the outline's centroid), exactly, by Green's theorem.

Pose from a blob: the blob is first moved to the plane of the part's top face (a top face at
height h is seen where rays meet z = h, which scales the blob about the camera's foot point). A
part rotated by theta has moments e^{i n theta} R_n, so each order n with a non-zero R_n gives theta
modulo 2 pi / n. The order that determines theta best (largest n |R_n| relative to its noise) gives
the fine angle; all orders together pick among its 2 pi / n ambiguities, down to the footprint's
own symmetry (``Footprint.symmetry_rad``): a rectangle's theta is known modulo pi, a square's
modulo pi / 2, a disk's not at all (reported as 0 with symmetry 0). The body origin is then
c_observed - R(theta) c_reference.
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ppod_ros.config.fields import Fields, check_number
from ppod_ros.errors import ConfigError
from ppod_ros.parts import Footprint, PointPart, RigidPart, part_from_dict
from ppod_ros.vision.detection import Blob
from ppod_ros.vision.geometry import PlateCalibration

#: Highest complex-moment order used for orientation.
MAX_ORDER = 6
_GL_T, _GL_W = np.polynomial.legendre.leggauss(10)
_GL_T = (_GL_T + 1) / 2
_GL_W = _GL_W / 2


@dataclass(frozen=True, eq=False)
class PartSpec:
    """A part type the tracker looks for.

    Parameters
    ----------
    label : str
        Name reported with each track (e.g. ``"washer"``).
    footprint : Footprint
        Outline in the body frame (m); the pose is that of the body origin.
    height_m : float
        Height of the visible top face above the plate surface (m).
    """

    label: str
    footprint: Footprint
    height_m: float = 0.0
    _ref: dict[str, Any] = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.label, str) or not self.label:
            raise ConfigError(f"part label: expected a non-empty string, got {self.label!r}")
        if not isinstance(self.footprint, Footprint):
            raise ConfigError(
                f"part {self.label!r} footprint: expected a Footprint, got {type(self.footprint).__name__}"
            )
        object.__setattr__(
            self,
            "height_m",
            check_number(
                self.height_m, f"part {self.label!r} height_m", min_value=0.0, max_value=0.2, unit="m"
            ),
        )
        self._ref.update(_reference(self.footprint))

    @classmethod
    def from_part(cls, label: str, part: PointPart | RigidPart, height_m: float = 0.0) -> PartSpec:
        """From a loaded part: its footprint, or a rigid part's contact triangle."""
        if part.footprint is not None:
            return cls(label, part.footprint, height_m)
        if isinstance(part, RigidPart):
            return cls(
                label,
                Footprint.from_value({"polygon": part.outline().tolist()}, f"{label}.outline"),
                height_m,
            )
        raise ConfigError(f"part {label!r}: a point part needs a footprint to be tracked")

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = "part") -> PartSpec:
        """``{label: str, footprint: {...} | part: {PART.yaml mapping}, height_m: float}``."""
        f = Fields(data, where)
        label = f.string("label")
        height = f.number("height_m", 0.0, min_value=0.0, unit="m")
        fp, part = f.raw("footprint", None), f.raw("part", None)
        f.finish()
        if (fp is None) == (part is None):
            raise ConfigError(f"{where}: give exactly one of footprint or part")
        if fp is not None:
            return cls(label, Footprint.from_value(fp, f.key_path("footprint")), height)
        return cls.from_part(label, part_from_dict(part, f.key_path("part")), height)

    # -- reference geometry --------------------------------------------------------------------
    @property
    def area_m2(self) -> float:
        return self._ref["area"]

    @property
    def symmetry_rad(self) -> float:
        """theta is reported modulo this; 0 means orientation is undefined (disks)."""
        return self._ref["symmetry"]

    @property
    def centroid_m(self) -> np.ndarray:
        """Outline centroid in the body frame (m)."""
        return np.array(self._ref["centroid"])

    @property
    def radius_m(self) -> float:
        """Largest distance of the outline from its centroid (m)."""
        return self._ref["radius"]

    @property
    def orders(self) -> tuple[int, ...]:
        """Complex-moment orders this part type's fit uses: 2 (classification) and those that
        carry its orientation (multiples of its symmetry order with a useful signal)."""
        return self._ref["orders"]

    def signature(self) -> np.ndarray:
        """Scale-free rotation invariants: |R_2| / A^2 and the radial moment / A^2."""
        return self._ref["signature"]

    def area_ratio(self, blob: Blob, calibration: PlateCalibration) -> float:
        """Blob area, moved to this part's top-face plane, over the part's area (cheap pre-check)."""
        return blob.area_m2 * self._view(calibration)[3][0] / self._ref["area"]

    def _view(self, calibration: PlateCalibration) -> tuple:
        """(calibration, camera foot point x, y, [hs^(n + 2)]) for this part's top-face height,
        kept for the last calibration used: a tracker fits every frame with the same one."""
        view = self._ref.get("view")
        if view is None or view[0] is not calibration:
            hs = calibration.height_scale(self.height_m)
            foot = calibration.camera_centre_m
            view = (
                calibration,
                float(foot[0]),
                float(foot[1]),
                [hs ** (n + 2) for n in range(MAX_ORDER + 7)],
                hs,
            )
            self._ref["view"] = view
        return view

    def fit(self, blob: Blob, calibration: PlateCalibration, shape_limit: float = math.inf) -> PoseFit:
        """Pose of this part type that best explains ``blob`` (measured on z = 0).

        With ``shape_limit``, a blob whose shape invariants differ by more is not fitted: the
        result then has theta NaN and an infinite moment residual (a cheap rejection).
        """
        ref = self._ref
        _, fx, fy, scale, hs = self._view(calibration)
        # A top face at height h is seen scaled by hs about the camera's foot point: the centroid
        # moves towards it and a moment of order n scales by hs^(n + 2).
        bx, by = blob.centroid_m.tolist()
        cx, cy = fx + (bx - fx) * hs, fy + (by - fy) * hs
        raw = blob.moments.tolist()
        used = [n for n in ref["orders"] if n < len(raw)]
        M = {n: raw[n] * scale[n] for n in used}
        area = blob.area_m2 * scale[0]
        shape = max(
            abs(abs(M[2]) / area**2 - ref["signature"][0]),
            abs(blob.radial2 * scale[2] / area**2 - ref["signature"][1]),
        )
        if shape > shape_limit:
            return PoseFit(math.nan, math.nan, math.nan, area / ref["area"], math.inf, float(shape))
        R = ref["moments_list"]
        theta = 0.0 if ref["symmetry"] == 0.0 else _orientation(M, ref)
        # Misfit per order, relative to the size of a moment of that order (area * radius^n),
        # so that it reads the same for every part type: 0.01 is a 1 % mismatch.
        resid = max(
            (abs(M[n] - cmath.exp(1j * n * theta) * R[n]) / ref["scale"][n] for n in used), default=0.0
        )
        c, sn = math.cos(theta), math.sin(theta)
        rx, ry = ref["centroid"]
        return PoseFit(
            float(cx - (c * rx - sn * ry)),
            float(cy - (sn * rx + c * ry)),
            theta,
            area / ref["area"],
            float(resid),
            float(shape),
        )


@dataclass(frozen=True)
class PoseFit:
    """A blob explained by a part type: pose, area ratio (observed / expected), the relative misfit
    of the orientation moments, and the largest difference of scale-free shape invariants."""

    x_m: float
    y_m: float
    theta_rad: float
    area_ratio: float
    moment_residual: float
    shape_distance: float


def _orientation(M: dict[int, complex], ref: dict[str, Any]) -> float:
    """theta in [-sym/2, sym/2) with M_n ~ e^{i n theta} R_n.

    The fine order n_f gives theta modulo 2 pi / n_f; among those n_f / n_sym candidates the one
    whose rotated reference moments correlate best with the observed ones (weighted by each
    order's signal-to-noise) is chosen, then refined by the weighted mean of all orders.
    """
    n_f, R = ref["fine_order"], ref["moments_list"]
    base = (cmath.phase(M[n_f]) - cmath.phase(R[n_f])) / n_f
    n_cand = max(1, n_f // ref["n_sym"])
    theta = base
    if n_cand > 1:
        # score(t) = sum_n w_n Re(M_n conj(R_n) e^{-i n t}): the correlation of the observed
        # moments with the reference rotated by t.
        terms = [(n, w * M[n] * R[n].conjugate()) for n, w in ref["weights"]]
        best = -math.inf
        for k in range(n_cand):
            t = base + 2 * math.pi * k / n_f
            e = cmath.exp(-1j * t)
            score = sum((p * e**n).real for n, p in terms)
            if score > best:
                best, theta = score, t
    # Refine with every order: each gives theta modulo 2 pi / n near the chosen candidate; their
    # weighted mean averages out noise and the small order-to-order biases of pixel sampling.
    num = den = 0.0
    for n, w in ref["refine_weights"]:
        d = (cmath.phase(M[n]) - cmath.phase(R[n])) / n - theta
        period = 2 * math.pi / n
        num += w * ((d + period / 2) % period - period / 2)
        den += w
    if den > 0:
        theta += num / den
    return wrap_angle(theta, ref["symmetry"])


def wrap_angle(theta: float, period: float) -> float:
    """theta wrapped into [-period/2, period/2) (period 0: returns 0)."""
    if period <= 0:
        return 0.0
    return float((theta + period / 2) % period - period / 2)


def _reference(fp: Footprint) -> dict[str, Any]:
    n_max = 12
    if fp.kind == "disk":
        r = fp.size[0]
        area = math.pi * r * r
        moments = np.zeros(n_max + 1, dtype=complex)
        moments[0] = area
        radial2 = math.pi * r**4 / 2
        centroid = np.zeros(2)
        quality = np.zeros(n_max + 1)
        radius = r
    else:
        v = fp.outline()
        raw = _polygon_moments(v, 0.0, n_max=1)
        centroid = np.array([raw[1].real, raw[1].imag]) / raw[0].real
        c = complex(centroid[0], centroid[1])
        moments = _polygon_moments(v, c, n_max)
        area = moments[0].real
        radial2 = _polygon_radial2(v, c)
        # Angle noise of order n ~ sqrt(integral |z|^(2n)) / (n |R_n|): quality is its inverse.
        quality = np.array(
            [
                n * abs(moments[n]) / math.sqrt(max(_polygon_abs_power(v, c, 2 * n), 1e-300))
                for n in range(n_max + 1)
            ]
        )
        radius = float(np.abs((v[:, 0] - centroid[0]) + 1j * (v[:, 1] - centroid[1])).max())
    n_sym = 0 if fp.symmetry_rad == 0 else max(1, int(round(2 * math.pi / fp.symmetry_rad)))
    top = max(quality[2 : MAX_ORDER + 1].max(), 1e-300)
    angle_orders = [
        n for n in range(2, MAX_ORDER + 1) if n_sym and n % n_sym == 0 and quality[n] >= 0.2 * top
    ]
    orders = tuple(sorted({2, *angle_orders}))
    fine = max(angle_orders, key=lambda n: quality[n]) if angle_orders else 0
    weights = [(n, float((quality[n] / max(abs(moments[n]), 1e-300)) ** 2)) for n in angle_orders]
    # Measured on rendered parts, higher orders are noisier than the area-only noise model says
    # (pixels outside the part, at the largest radii, weigh most): down-weight them by 1/n.
    refine_weights = [(n, float(quality[n] ** 2 / n)) for n in angle_orders]
    return {
        "area": float(area),
        "moments": moments,
        "moments_list": moments.tolist(),
        "orders": orders,
        "fine_order": fine,
        "n_sym": n_sym,
        "weights": weights,
        "refine_weights": refine_weights,
        "scale": [float(area * radius**n) for n in range(n_max + 1)],
        "centroid": (float(centroid[0]), float(centroid[1])),
        "radial2": float(radial2),
        "symmetry": fp.symmetry_rad,
        "quality": quality,
        "radius": float(radius),
        "signature": _signature(moments, radial2, area),
    }


def _signature(M: np.ndarray, radial2: float, area: float) -> np.ndarray:
    return np.array([abs(M[2]) / area**2, radial2 / area**2])


def _edges(v: np.ndarray, c: complex) -> tuple[np.ndarray, np.ndarray]:
    z = (v[:, 0] + 1j * v[:, 1]) - c
    return z, np.roll(z, -1) - z


def _polygon_moments(v: np.ndarray, c: complex, n_max: int) -> np.ndarray:
    """Exact integrals of (z - c)^n over a counter-clockwise polygon, n = 0..n_max.

    Green's theorem: integral of g(z) dA = 1/(2i) * contour integral of conj(z) g(z) dz; on each
    edge the integrand is a polynomial of degree n + 1 in the edge parameter, integrated exactly
    by 10-point Gauss-Legendre for n <= 18.
    """
    z0, dz = _edges(v, c)
    zt = z0[:, None] + _GL_T[None, :] * dz[:, None]
    out = np.empty(n_max + 1, dtype=complex)
    for n in range(n_max + 1):
        integrand = np.conj(zt) * zt**n
        out[n] = np.sum((integrand @ _GL_W) * dz) / 2j
    return out


def _polygon_radial2(v: np.ndarray, c: complex) -> float:
    return _polygon_abs_power(v, c, 2)


def _polygon_abs_power(v: np.ndarray, c: complex, p: int) -> float:
    """Integral of |z - c|^p (p even) over the polygon, by Green's theorem with x-primitive."""
    # |z|^p = (x^2 + y^2)^(p/2) is a polynomial: integrate dA = d(F) dy with F = integral dx.
    z0, dz = _edges(v, c)
    zt = z0[:, None] + _GL_T[None, :] * dz[:, None]
    x, y = zt.real, zt.imag
    k = p // 2
    F = np.zeros_like(x)
    for j in range(k + 1):
        # (x^2 + y^2)^k = sum_j C(k, j) x^(2j) y^(2(k-j)); primitive in x: x^(2j+1)/(2j+1).
        F += math.comb(k, j) * x ** (2 * j + 1) / (2 * j + 1) * y ** (2 * (k - j))
    return float(np.sum((F @ _GL_W) * dz.imag))


__all__ = ["PartSpec", "PoseFit", "wrap_angle"]

"""The plate-to-image mapping: projection, back-projection and per-pixel plate coordinates.

A :class:`PlateCalibration` is a calibrated camera (intrinsics K, distortion) plus the plate's pose
in the camera frame (rvec, tvec). It maps plate points at any height z above the plate surface to
distorted pixels (``plate_to_image``) and pixels back onto a plane z = const (``image_to_plate``,
by undistorting points, never whole images). For the tracker it precomputes, once per
calibration, the plate coordinates of every pixel centre and the plate area each pixel covers
(:meth:`PlateCalibration.pixel_map`), so that blob moments are computed directly in the plate
frame, free of lens distortion and perspective.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from ppod_ros.config.fields import check_array
from ppod_ros.errors import ConfigError
from ppod_ros.vision.camera import CameraConfig

_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10)


@dataclass(frozen=True)
class PixelMap:
    """Plate coordinates of pixel centres on the plane z = 0, over an image window.

    Attributes
    ----------
    x_m, y_m : ndarray, shape (v1 - v0, u1 - u0), float32
        Plate coordinates (m) of each pixel centre; NaN where the ray misses the plane.
    area_m2 : ndarray, shape (v1 - v0, u1 - u0), float32
        Plate area (m^2) imaged by each pixel (the Jacobian of the pixel-to-plate map).
    window : (u0, v0, u1, v1)
        The image window (exclusive end).
    """

    x_m: np.ndarray
    y_m: np.ndarray
    area_m2: np.ndarray
    window: tuple[int, int, int, int]


@dataclass(frozen=True, eq=False)
class PlateCalibration:
    """Plate-to-image mapping of one camera.

    Parameters
    ----------
    camera_matrix : array_like, shape (3, 3)
        Intrinsics K (pixels).
    dist_coeffs : array_like, shape (5,)
        OpenCV distortion (k1, k2, p1, p2, k3).
    rvec, tvec : array_like, shape (3,)
        Plate frame to camera frame (Rodrigues vector, metres).
    width, height : int
        Image size (pixels).
    rms_px : float
        Reprojection RMS of the points the pose was fitted to (pixels); NaN for a nominal pose.
    n_points : int
        Number of points fitted (0 for a nominal pose).
    source : str
        How it was obtained: ``"nominal"``, ``"markers"`` or ``"checkerboard"``.
    """

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    rvec: np.ndarray
    tvec: np.ndarray
    width: int
    height: int
    rms_px: float = float("nan")
    n_points: int = 0
    source: str = "nominal"
    _cache: dict[str, Any] = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        K = check_array(self.camera_matrix, "camera_matrix", shape=(3, 3), unit="px")
        d = check_array(self.dist_coeffs, "dist_coeffs").reshape(-1)
        if d.size not in (4, 5, 8, 12, 14):
            raise ConfigError(f"dist_coeffs: expected 4, 5, 8, 12 or 14 OpenCV coefficients, got {d.size}")
        r = check_array(self.rvec, "rvec", unit="rad").reshape(-1)
        t = check_array(self.tvec, "tvec", unit="m").reshape(-1)
        if r.size != 3 or t.size != 3:
            raise ConfigError(f"rvec, tvec: expected 3 values each, got {r.size} and {t.size}")
        R, _ = cv2.Rodrigues(r)
        if (-R.T @ t)[2] <= 0:
            raise ConfigError("rvec, tvec: the camera must be above the plate (optical centre at z > 0 m)")
        for name, arr in (("camera_matrix", K), ("dist_coeffs", d), ("rvec", r), ("tvec", t)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        self._cache["R"] = R
        self._cache["centre"] = -R.T @ t
        self._cache["centre"].setflags(write=False)

    @classmethod
    def nominal(cls, config: CameraConfig) -> PlateCalibration:
        """The mapping the configuration states (intrinsics and mount as configured)."""
        rvec, tvec = config.extrinsics()
        return cls(config.camera_matrix, config.dist_coeffs, rvec, tvec, config.width, config.height)

    # -- geometry ----------------------------------------------------------------------------
    @property
    def rotation(self) -> np.ndarray:
        """R (3, 3) taking plate-frame vectors into the camera frame."""
        return self._cache["R"]

    @property
    def camera_centre_m(self) -> np.ndarray:
        """Optical centre (3,) in the plate frame (m)."""
        return self._cache["centre"]

    def plate_to_image(self, xy_m: Any, z_m: float = 0.0) -> np.ndarray:
        """Pixels (N, 2) of plate points (N, 2) at height ``z_m`` above the plate surface."""
        xy = np.asarray(xy_m, dtype=float).reshape(-1, 2)
        pts = np.concatenate([xy, np.full((len(xy), 1), float(z_m))], axis=1)
        uv, _ = cv2.projectPoints(pts, self.rvec, self.tvec, self.camera_matrix, self.dist_coeffs)
        return uv.reshape(-1, 2)

    def image_to_plate(self, uv_px: Any, z_m: float = 0.0) -> np.ndarray:
        """Plate points (N, 2) on the plane at height ``z_m`` seen at pixels (N, 2)."""
        uv = np.asarray(uv_px, dtype=np.float64).reshape(-1, 1, 2)
        if len(uv) == 0:
            return np.zeros((0, 2))
        n = cv2.undistortPoints(uv, self.camera_matrix, self.dist_coeffs, criteria=_UNDISTORT_CRITERIA)
        return self._rays_to_plane(n.reshape(-1, 2), z_m)

    def _rays_to_plane(self, normalized: np.ndarray, z_m: float) -> np.ndarray:
        rays = np.concatenate([normalized, np.ones((len(normalized), 1))], axis=1) @ self.rotation
        c = self.camera_centre_m
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (z_m - c[2]) / rays[:, 2]
        s = np.where(s > 0, s, np.nan)
        return c[:2] + s[:, None] * rays[:, :2]

    def height_scale(self, z_m: float) -> float:
        """Factor by which lengths on the plane z = ``z_m`` shrink, about the camera's foot point,
        relative to where the same pixels meet the plane z = 0 (1 - z / camera height)."""
        return 1.0 - float(z_m) / float(self._cache["centre"][2])

    def lift(self, xy0_m: np.ndarray, z_m: float) -> np.ndarray:
        """Move points found on the plane z = 0 to where the same rays meet the plane z = ``z_m``."""
        if z_m == 0.0:
            return np.asarray(xy0_m, dtype=float)
        c = self._cache["centre"][:2]
        return c + (np.asarray(xy0_m, dtype=float) - c) * self.height_scale(z_m)

    def pixel_map(self, window: tuple[int, int, int, int] | None = None) -> PixelMap:
        """Plate coordinates and area of the pixels of ``window`` = (u0, v0, u1, v1) (exclusive
        end; default the whole image) on z = 0, computed once per window and cached."""
        w = (0, 0, self.width, self.height) if window is None else tuple(int(v) for v in window)
        if not (0 <= w[0] < w[2] <= self.width and 0 <= w[1] < w[3] <= self.height):
            raise ConfigError(
                f"window: expected (u0, v0, u1, v1) inside the {self.width}x{self.height} px image, got {w}"
            )
        key = ("pixel_map", w)
        pm = self._cache.get(key)
        if pm is None:
            pm = self._compute_pixel_map(*w)
            self._cache[key] = pm
        return pm

    def _compute_pixel_map(self, u0: int, v0: int, u1: int, v1: int) -> PixelMap:
        # Plate coordinates of pixel corners: each pixel's area is the exact area of the
        # quadrilateral its corners span, so sums of area-weighted values are plate integrals.
        w, h = u1 - u0, v1 - v0
        u, v = np.meshgrid(
            np.arange(u0, u1 + 1, dtype=np.float64) - 0.5, np.arange(v0, v1 + 1, dtype=np.float64) - 0.5
        )
        corners = self.image_to_plate(np.stack([u.ravel(), v.ravel()], axis=1)).reshape(h + 1, w + 1, 2)
        a, b = corners[:-1, :-1], corners[:-1, 1:]
        c, d = corners[1:, 1:], corners[1:, :-1]
        # Shoelace formula for the quadrilateral a-b-c-d.
        area = 0.5 * np.abs(
            (c[..., 0] - a[..., 0]) * (d[..., 1] - b[..., 1])
            - (d[..., 0] - b[..., 0]) * (c[..., 1] - a[..., 1])
        )
        uc, vc = np.meshgrid(np.arange(u0, u1, dtype=np.float64), np.arange(v0, v1, dtype=np.float64))
        centres = self.image_to_plate(np.stack([uc.ravel(), vc.ravel()], axis=1)).reshape(h, w, 2)
        pm = PixelMap(
            centres[..., 0].astype(np.float32),
            centres[..., 1].astype(np.float32),
            area.astype(np.float32),
            (u0, v0, u1, v1),
        )
        for arr in (pm.x_m, pm.y_m, pm.area_m2):
            arr.setflags(write=False)
        return pm

    def window_of_region(
        self, x_range_m: tuple[float, float], y_range_m: tuple[float, float], margin_px: int = 4
    ) -> tuple[int, int, int, int]:
        """Image window (u0, v0, u1, v1) that holds the plate rectangle, with a margin."""
        (x0, x1), (y0, y1) = x_range_m, y_range_m
        t = np.linspace(0.0, 1.0, 65)
        edge = np.concatenate(
            [
                np.stack([x0 + (x1 - x0) * t, np.full_like(t, y0)], 1),
                np.stack([np.full_like(t, x1), y0 + (y1 - y0) * t], 1),
                np.stack([x1 - (x1 - x0) * t, np.full_like(t, y1)], 1),
                np.stack([np.full_like(t, x0), y1 - (y1 - y0) * t], 1),
            ]
        )
        uv = self.plate_to_image(edge)
        lo = np.floor(uv.min(axis=0)).astype(int) - margin_px
        hi = np.ceil(uv.max(axis=0)).astype(int) + margin_px + 1
        return (
            max(int(lo[0]), 0),
            max(int(lo[1]), 0),
            min(int(hi[0]), self.width),
            min(int(hi[1]), self.height),
        )

    def pixel_size_m(self, xy_m: Any = (0.0, 0.0)) -> float:
        """Side (m) of a pixel's footprint on the plate near ``xy_m`` (square-root of its area)."""
        uv = self.plate_to_image(xy_m)[0]
        quad = self.image_to_plate(uv + np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]]))
        x, y = quad[:, 0], quad[:, 1]
        return float(np.sqrt(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))))

    def describe(self) -> str:
        c = self.camera_centre_m
        return (
            f"{self.source} calibration: camera centre ({c[0] * 1e3:.1f}, {c[1] * 1e3:.1f}, "
            f"{c[2] * 1e3:.1f}) mm, reprojection RMS {self.rms_px:.3f} px over {self.n_points} points"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "camera_matrix": self.camera_matrix.tolist(),
            "dist_coeffs": self.dist_coeffs.tolist(),
            "rvec": self.rvec.tolist(),
            "tvec": self.tvec.tolist(),
            "width": self.width,
            "height": self.height,
            "rms_px": self.rms_px,
            "n_points": self.n_points,
            "source": self.source,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PlateCalibration:
        from ppod_ros.config.fields import Fields

        f = Fields(data, "calibration")
        out = cls(
            f.array("camera_matrix", shape=(3, 3)),
            f.array("dist_coeffs"),
            f.array("rvec", shape=(3,)),
            f.array("tvec", shape=(3,)),
            f.integer("width", min_value=16),
            f.integer("height", min_value=16),
            float(f.raw("rms_px", float("nan"))),
            f.integer("n_points", 0, min_value=0),
            f.string("source", "nominal"),
        )
        f.finish()
        return out


__all__ = ["PixelMap", "PlateCalibration"]

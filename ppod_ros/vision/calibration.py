"""Camera calibration: the plate's pose from its fiducials or a checkerboard, intrinsics from views.

Three entry points, all returning plain results and raising :class:`CalibrationError` with the
reason when the image does not support a trustworthy answer:

- :func:`calibrate_plate_from_markers`: the plate-to-image mapping from the ArUco markers printed
  on the plate (known intrinsics; the pose is fitted to every detected marker corner, outliers
  removed). This is what the tracker runs at start-up and whenever asked to recalibrate.
- :func:`calibrate_plate_from_checkerboard`: the same from a checkerboard laid flat on the plate
  at a known place.
- :func:`calibrate_intrinsics`: K and distortion from several checkerboard views (OpenCV's
  Zhang method), for the camera file.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import cv2
import numpy as np

from ppod_ros.errors import ConfigError, PpodError
from ppod_ros.vision.camera import CameraConfig, PlateLayout
from ppod_ros.vision.frames import to_gray
from ppod_ros.vision.geometry import PlateCalibration


class CalibrationError(PpodError):
    """An image did not yield a trustworthy calibration; the message says why."""


@dataclass(frozen=True)
class Checkerboard:
    """A checkerboard target: ``cols`` x ``rows`` inner corners, squares of ``square_m``.

    Board frame: inner corner (i, j) at (i * square_m, j * square_m, 0), i along x (0..cols-1),
    j along y; the square whose lower-left corner is inner corner (0, 0) is white. ``cols`` and
    ``rows`` must differ so that the board's orientation in an image is unambiguous.
    """

    cols: int = 9
    rows: int = 6
    square_m: float = 0.02

    def __post_init__(self) -> None:
        if self.cols < 3 or self.rows < 3:
            raise ConfigError(
                f"checkerboard: needs at least 3 x 3 inner corners, got {self.cols} x {self.rows}"
            )
        if self.cols == self.rows:
            raise ConfigError(
                "checkerboard: cols and rows must differ (a square board's orientation is ambiguous)"
            )
        if not self.square_m > 0:
            raise ConfigError(f"checkerboard: square_m must be > 0 m, got {self.square_m}")

    def object_points(self) -> np.ndarray:
        """Inner corners (cols*rows, 3) in the board frame, row by row (OpenCV's order)."""
        j, i = np.mgrid[0 : self.rows, 0 : self.cols]
        return np.stack([i.ravel() * self.square_m, j.ravel() * self.square_m, np.zeros(i.size)], axis=1)

    def black_squares(self) -> list[np.ndarray]:
        """Black squares as polygons (4, 2) in the board frame (the board has one square beyond
        the inner corners on each side)."""
        s = self.square_m
        out = []
        for a in range(-1, self.cols):
            for b in range(-1, self.rows):
                if (a + b) % 2 == 0:
                    continue
                x0, y0 = a * s, b * s
                out.append(np.array([[x0, y0], [x0 + s, y0], [x0 + s, y0 + s], [x0, y0 + s]]))
        return out

    def outline(self, margin_squares: float = 1.0) -> np.ndarray:
        """The white card (4, 2) the squares are printed on, with a margin, in the board frame."""
        s = self.square_m
        lo = -s * (1 + margin_squares)
        hx, hy = s * (self.cols + margin_squares), s * (self.rows + margin_squares)
        return np.array([[lo, lo], [hx, lo], [hx, hy], [lo, hy]])


@dataclass(frozen=True)
class IntrinsicsResult:
    """K (3, 3), distortion (5,), overall reprojection RMS (px) and per-view RMS (px)."""

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    rms_px: float
    per_view_rms_px: tuple[float, ...]
    image_size: tuple[int, int]


def marker_dictionary(name: str) -> cv2.aruco.Dictionary:
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))


def detect_markers(image: np.ndarray, layout: PlateLayout) -> dict[int, np.ndarray]:
    """Corners (4, 2) in pixels, ArUco order, of the layout's markers found in ``image``."""
    gray = to_gray(image)
    corners, ids, _ = _marker_detector(layout.marker_dictionary).detectMarkers(gray)
    wanted = {m[0] for m in layout.markers}
    found: dict[int, np.ndarray] = {}
    if ids is None:
        return found
    for c, mid in zip(corners, ids.ravel()):
        mid = int(mid)
        if mid in wanted and mid not in found:
            found[mid] = c.reshape(4, 2).astype(np.float64)
    return found


def calibrate_plate_from_markers(
    image: np.ndarray,
    camera: CameraConfig | PlateCalibration,
    layout: PlateLayout | None = None,
    *,
    min_markers: int = 3,
    max_error_px: float = 1.5,
) -> PlateCalibration:
    """Fit the plate's pose to the fiducial markers seen in ``image``.

    Parameters
    ----------
    image : ndarray, uint8, shape (H, W) or (H, W, 3)
    camera : CameraConfig or PlateCalibration
        Intrinsics and distortion (and a nominal pose, used only to start the fit).
    layout : PlateLayout, optional
        Marker layout; defaults to ``camera.plate`` for a CameraConfig.
    min_markers : int
        Fewer markers than this (after outlier removal) is an error.
    max_error_px : float
        Markers whose corners reproject worse than this (px) are dropped as misdetections.
    """
    nominal = camera if isinstance(camera, PlateCalibration) else PlateCalibration.nominal(camera)
    if layout is None:
        if not isinstance(camera, CameraConfig):
            raise CalibrationError(
                "calibrate_plate_from_markers: pass the plate layout with a PlateCalibration"
            )
        layout = camera.plate
    found = detect_markers(image, layout)
    if len(found) < min_markers:
        raise CalibrationError(
            f"found {len(found)} of the plate's {len(layout.markers)} markers "
            f"(ids {sorted(found)}); need at least {min_markers}"
        )
    plate_corners = layout.marker_corners()
    ids = sorted(found)
    for _ in range(len(ids)):
        obj_xy = np.concatenate([plate_corners[i] for i in ids])
        obj = np.concatenate([obj_xy, np.zeros((len(obj_xy), 1))], axis=1)
        img = np.concatenate([found[i] for i in ids])
        rvec, tvec = _solve_planar_pose(obj, img, nominal)
        err = _reprojection_errors(obj, img, rvec, tvec, nominal).reshape(len(ids), 4).max(axis=1)
        worst = int(np.argmax(err))
        if err[worst] <= max_error_px or len(ids) <= min_markers:
            break
        ids.pop(worst)
    if err.max() > max_error_px:
        raise CalibrationError(
            f"marker corners reproject up to {err.max():.2f} px off (limit {max_error_px} px): "
            f"the intrinsics or the marker layout do not match this camera"
        )
    rms = float(np.sqrt(np.mean(_reprojection_errors(obj, img, rvec, tvec, nominal) ** 2)))
    return PlateCalibration(
        nominal.camera_matrix,
        nominal.dist_coeffs,
        rvec,
        tvec,
        nominal.width,
        nominal.height,
        rms,
        len(obj),
        "markers",
    )


@dataclass(frozen=True)
class PlateShift:
    """Where the plate is in a frame relative to where it was calibrated: an in-plane rigid move.

    A point at ``xy`` on the plate appears at ``R(dtheta) xy + (dx, dy)`` in the calibrated frame.
    The camera is phase-locked to the plate's cycle, so a vibrating plate is caught at the same
    displacement in every frame of one motion, but that displacement changes with the motion (a
    few tenths of a millimetre): left uncorrected it would bias every part pose.
    """

    dx_m: float
    dy_m: float
    dtheta_rad: float
    markers: int
    rms_m: float

    def to_plate(self, xy_m: np.ndarray, theta_rad: np.ndarray | float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Undo the shift: calibrated-frame points (N, 2) and angles to the plate's own frame."""
        c, s = math.cos(self.dtheta_rad), math.sin(self.dtheta_rad)
        d = np.asarray(xy_m, dtype=float).reshape(-1, 2) - (self.dx_m, self.dy_m)
        xy = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
        return xy, np.asarray(theta_rad, dtype=float) - self.dtheta_rad


def measure_plate_shift(
    image: np.ndarray,
    calibration: PlateCalibration,
    layout: PlateLayout,
    *,
    margin_px: int | None = None,
    min_markers: int = 2,
    max_markers: int = 4,
) -> PlateShift | None:
    """The plate's in-plane shift (:class:`PlateShift`) from its markers, or None if too few are seen.

    Each marker is looked for only in a small window around where the calibration puts it (the
    plate moves by a fraction of a millimetre), so this costs a few small detections per frame.
    The marker corners seen are mapped to the calibrated plate frame and fitted with a 2D rigid
    transform (least squares, Kabsch). ``margin_px`` (default: the marker's side in pixels, at
    least 16) is the quiet zone around the expected place that the detector needs. At most
    ``max_markers`` are used, spread over the plate (the farthest apart first).
    """
    gray = to_gray(image)
    h, w = gray.shape[:2]
    detector = _marker_detector(layout.marker_dictionary)
    src, dst, n = [], [], 0
    for mid, corners_m in _spread(layout.marker_corners()):
        if n >= max_markers:
            break
        uv = calibration.plate_to_image(corners_m)
        side = float(np.max(np.ptp(uv, axis=0)))
        margin = int(math.ceil(max(16.0, side))) if margin_px is None else int(margin_px)
        u0, v0 = (np.floor(uv.min(axis=0)) - margin).astype(int)
        u1, v1 = (np.ceil(uv.max(axis=0)) + margin).astype(int)
        u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, w), min(v1, h)
        if u1 - u0 < 8 or v1 - v0 < 8:
            continue
        found, ids, _ = detector.detectMarkers(np.ascontiguousarray(gray[v0:v1, u0:u1]))
        if ids is None:
            continue
        for c, i in zip(found, ids.ravel()):
            if int(i) == mid:
                seen = calibration.image_to_plate(c.reshape(4, 2).astype(np.float64) + (u0, v0))
                src.append(corners_m)
                dst.append(seen)
                n += 1
                break
    if n < min_markers:
        return None
    a, b = np.concatenate(src), np.concatenate(dst)
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    hmat = (a - ca).T @ (b - cb)
    u, _, vt = np.linalg.svd(hmat)
    r = vt.T @ u.T
    if np.linalg.det(r) < 0:
        vt[-1] *= -1
        r = vt.T @ u.T
    t = cb - r @ ca
    resid = b - (a @ r.T + t)
    return PlateShift(float(t[0]), float(t[1]), float(math.atan2(r[1, 0], r[0, 0])), n,
                      float(np.sqrt(np.mean(np.sum(resid**2, axis=1)))))


def _spread(corners: dict[int, np.ndarray]) -> list[tuple[int, np.ndarray]]:
    """Markers ordered so that each next one is the farthest from those before (a spread-out subset)."""
    items = list(corners.items())
    centres = np.array([c.mean(axis=0) for _, c in items])
    order = [int(np.argmax(np.hypot(*centres.T)))]
    while len(order) < len(items):
        d = np.min(np.linalg.norm(centres[:, None] - centres[order][None], axis=2), axis=1)
        d[order] = -1.0
        order.append(int(np.argmax(d)))
    return [items[i] for i in order]


_DETECTORS: dict[str, cv2.aruco.ArucoDetector] = {}


#: Sub-pixel corner refinement window (half-size, px) and its cap relative to one marker bit cell.
#: OpenCV's default cap (0.3 of a cell) shrank the window on the stack's 640 x 512 camera (cells of
#: 4.9 px) so far that the plate's calibration and per-frame shift were off by up to 0.3 mm, the
#: same for every part (measured against ground truth: parts at rest median 0.145 mm, worst 0.415
#: mm; with these 0.030 / 0.097 mm). At 1280 x 1024 (cells of 9.7 px) the result is unchanged.
CORNER_WINDOW_PX = 3
CORNER_WINDOW_CELLS = 1.0


def _marker_detector(dictionary: str) -> cv2.aruco.ArucoDetector:
    if dictionary not in _DETECTORS:
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        params.cornerRefinementWinSize = CORNER_WINDOW_PX
        params.relativeCornerRefinmentWinSize = CORNER_WINDOW_CELLS
        params.cornerRefinementMinAccuracy = 0.005
        params.cornerRefinementMaxIterations = 60
        _DETECTORS[dictionary] = cv2.aruco.ArucoDetector(marker_dictionary(dictionary), params)
    return _DETECTORS[dictionary]


def find_checkerboard(image: np.ndarray, board: Checkerboard) -> np.ndarray | None:
    """Sub-pixel inner corners (cols*rows, 2) of ``board`` in ``image``, or None if not found."""
    gray = to_gray(image)
    ok, corners = cv2.findChessboardCorners(
        gray, (board.cols, board.rows), flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    )
    if not ok:
        return None
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 60, 1e-4)
    corners = cv2.cornerSubPix(gray, corners.astype(np.float32), (5, 5), (-1, -1), crit)
    return corners.reshape(-1, 2).astype(np.float64)


def calibrate_plate_from_checkerboard(
    image: np.ndarray,
    board: Checkerboard,
    camera: CameraConfig | PlateCalibration,
    board_pose_m: tuple[float, float, float],
) -> PlateCalibration:
    """Fit the plate's pose to a checkerboard lying flat on the plate.

    ``board_pose_m`` = (x, y, theta) of the board frame in the plate frame (m, m, rad), e.g. from
    a jig. The detected corner order is matched to the board with the nominal pose, which must be
    right to within a quarter turn.
    """
    nominal = camera if isinstance(camera, PlateCalibration) else PlateCalibration.nominal(camera)
    corners = find_checkerboard(image, board)
    if corners is None:
        raise CalibrationError(f"no {board.cols} x {board.rows} checkerboard found in the image")
    x, y, th = (float(v) for v in board_pose_m)
    c, s = math.cos(th), math.sin(th)
    local = board.object_points()[:, :2]
    obj_xy = local @ np.array([[c, s], [-s, c]]) + np.array([x, y])
    obj = np.concatenate([obj_xy, np.zeros((len(obj_xy), 1))], axis=1)
    # OpenCV may return the rows and the corners within them in either direction: keep the order
    # that matches the nominal projection of the board (corner spacing >> nominal pose error).
    expected = nominal.plate_to_image(obj_xy).reshape(board.rows, board.cols, 2)
    grid = corners.reshape(board.rows, board.cols, 2)
    candidates = [grid, grid[::-1, ::-1], grid[::-1, :], grid[:, ::-1]]
    best = min(candidates, key=lambda g: float(np.mean(np.linalg.norm(g - expected, axis=2))))
    corners = best.reshape(-1, 2).copy()
    rvec, tvec = _solve_planar_pose(obj, corners, nominal)
    rms = float(np.sqrt(np.mean(_reprojection_errors(obj, corners, rvec, tvec, nominal) ** 2)))
    return PlateCalibration(
        nominal.camera_matrix,
        nominal.dist_coeffs,
        rvec,
        tvec,
        nominal.width,
        nominal.height,
        rms,
        len(obj),
        "checkerboard",
    )


def calibrate_intrinsics(
    images: Iterable[np.ndarray], board: Checkerboard, *, min_views: int = 5, fix_k3: bool = True
) -> IntrinsicsResult:
    """K and distortion from checkerboard views at varied tilts and positions.

    Views without a complete board are skipped; fewer than ``min_views`` usable views is an error.
    ``fix_k3`` keeps k3 = 0, which is what a modest lens needs and avoids over-fitting.
    """
    obj_pts, img_pts, size = [], [], None
    for image in images:
        gray = to_gray(image)
        if size is None:
            size = (gray.shape[1], gray.shape[0])
        elif size != (gray.shape[1], gray.shape[0]):
            raise CalibrationError(
                f"calibrate_intrinsics: all views must have one size, got {size} and "
                f"{(gray.shape[1], gray.shape[0])}"
            )
        corners = find_checkerboard(gray, board)
        if corners is not None:
            obj_pts.append(board.object_points().astype(np.float32))
            img_pts.append(corners.astype(np.float32).reshape(-1, 1, 2))
    if len(obj_pts) < min_views:
        raise CalibrationError(
            f"calibrate_intrinsics: the board was found in {len(obj_pts)} views; need "
            f"at least {min_views} at varied tilts"
        )
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(obj_pts, img_pts, size, None, None, flags=flags)
    per_view = []
    for o, i, r, t in zip(obj_pts, img_pts, rvecs, tvecs):
        proj, _ = cv2.projectPoints(o, r, t, K, dist)
        per_view.append(float(np.sqrt(np.mean(np.sum((proj - i) ** 2, axis=2)))))
    return IntrinsicsResult(K, dist.reshape(-1)[:5], float(rms), tuple(per_view), size)


def _solve_planar_pose(
    obj: np.ndarray, img: np.ndarray, nominal: PlateCalibration
) -> tuple[np.ndarray, np.ndarray]:
    K, d = nominal.camera_matrix, nominal.dist_coeffs
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, d, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise CalibrationError("the plate's pose could not be solved from the detected points")
    rvec, tvec = cv2.solvePnPRefineLM(
        obj, img, K, d, rvec, tvec, criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-12)
    )
    return rvec.reshape(3), tvec.reshape(3)


def _reprojection_errors(
    obj: np.ndarray, img: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, nominal: PlateCalibration
) -> np.ndarray:
    proj, _ = cv2.projectPoints(obj, rvec, tvec, nominal.camera_matrix, nominal.dist_coeffs)
    return np.linalg.norm(proj.reshape(-1, 2) - img, axis=1)


__all__ = [
    "CalibrationError",
    "Checkerboard",
    "PlateShift",
    "measure_plate_shift",
    "IntrinsicsResult",
    "calibrate_intrinsics",
    "calibrate_plate_from_checkerboard",
    "calibrate_plate_from_markers",
    "detect_markers",
    "find_checkerboard",
    "marker_dictionary",
]

"""The simulated overhead camera: renders the plate, its fiducials and the parts from their poses.

Image formation, in order: reflectance of the scene (table, plate, markers or a checkerboard, then
the parts' top faces, then occluders), each polygon projected through the camera's real pinhole
model, lens distortion and mounting pose and rasterised with exact area coverage (anti-aliased
edges); times the lighting's gain field and the exposure; Gaussian blur; read and photon noise;
quantisation to uint8 (mono8, or bgr8 by replicating the grey level). The plate's own small
vibration displacement at the frame's phase moves the plate and everything on it rigidly.

Deterministic: frame ``index`` with seed ``seed`` always draws the same noise. The static layer
(plate and markers) is rendered once at rest and moved with the plate's displacement by an affine
warp, so a 1280 x 1024 frame costs a few tens of milliseconds (``ppod bench tracker`` prints the
figure).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from ppod_ros.config.fields import check_array
from ppod_ros.errors import ConfigError
from ppod_ros.vision.calibration import Checkerboard, marker_dictionary
from ppod_ros.vision.camera import CameraConfig
from ppod_sim.camera.raster import coverage, densify, downsample, fill_polygons, window_of
from ppod_sim.camera.scene import (
    Lighting,
    LightingSchedule,
    Occluder,
    PartTruth,
    RenderedFrame,
    RenderPart,
    SceneStyle,
    SensorModel,
)

#: Edge length (m) below which projected edges are treated as straight (about 1/3 pixel).
_EDGE_STEP_M = 0.00015
_STATIC_EDGE_STEP_M = 0.001


class CameraRenderer:
    """Render camera frames of the plate and the parts.

    Parameters
    ----------
    config : CameraConfig
        The camera (the true one: a tracker may be given a perturbed copy).
    seed : int
        Noise seed; frame ``index`` draws from ``default_rng([seed, index])``.
    sensor : SensorModel
    lighting : Lighting or callable(stamp_s) -> Lighting
        Default lighting; :meth:`render` may override it per frame.
    style : SceneStyle
    supersample : int
        Sub-pixels per axis for the parts' edge coverage (static layer: half of it, at least 2).
    """

    def __init__(
        self,
        config: CameraConfig,
        *,
        seed: int = 0,
        sensor: SensorModel | None = None,
        lighting: Lighting | LightingSchedule | None = None,
        style: SceneStyle | None = None,
        supersample: int = 8,
    ):
        if not isinstance(config, CameraConfig):
            raise ConfigError(f"config: expected a CameraConfig, got {type(config).__name__}")
        if not 1 <= int(supersample) <= 16:
            raise ConfigError(f"supersample: expected 1..16 sub-pixels per axis, got {supersample}")
        self.config = config
        self.seed = int(seed)
        self.sensor = sensor or SensorModel()
        self.lighting = lighting or Lighting()
        self.style = style or SceneStyle()
        self.supersample = int(supersample)
        self._rvec, self._tvec = config.extrinsics()
        self._K = config.camera_matrix
        self._dist = config.dist_coeffs
        self._static: np.ndarray | None = None          # the static layer at rest (_static_layer)
        self._plate_grid: np.ndarray | None = None
        self._plate_uv0: np.ndarray | None = None
        self._gain: dict[Lighting, np.ndarray] = {}
        self._next_index = 0

    # -- projection ----------------------------------------------------------------------------
    def project(self, points_m: np.ndarray, displacement: np.ndarray | None = None) -> np.ndarray:
        """Pixels (N, 2) of plate-frame points (N, 3), after the plate's rigid displacement
        ``[dx, dy, dz, rx, ry, rz]`` (m, rad) if given."""
        pts = np.asarray(points_m, dtype=float).reshape(-1, 3)
        if displacement is not None and np.any(displacement):
            R, _ = cv2.Rodrigues(np.asarray(displacement[3:], dtype=float))
            pts = pts @ R.T + np.asarray(displacement[:3], dtype=float)
        uv, _ = cv2.projectPoints(pts, self._rvec, self._tvec, self._K, self._dist)
        return uv.reshape(-1, 2)

    def _project_polygon(
        self, poly_xy: np.ndarray, z_m: float, disp: np.ndarray | None, step: float
    ) -> np.ndarray:
        dense = densify(poly_xy, step)
        return self.project(np.concatenate([dense, np.full((len(dense), 1), z_m)], axis=1), disp)

    # -- rendering -----------------------------------------------------------------------------
    def render(
        self,
        parts: Sequence[RenderPart],
        stamp_s: float = 0.0,
        *,
        plate_displacement: Sequence[float] | None = None,
        lighting: Lighting | None = None,
        occluders: Sequence[Occluder] = (),
        index: int | None = None,
    ) -> RenderedFrame:
        """Render one frame of ``parts`` on the plate.

        Parameters
        ----------
        parts : sequence of RenderPart
        stamp_s : float
            Capture time (s); also the argument of a lighting schedule.
        plate_displacement : array_like, shape (6,), optional
            The plate's displacement [dx, dy, dz (m), rx, ry, rz (rad)] at the frame's phase
            (``PlateMotion.displacement(t)``; sub-millimetre).
        lighting : Lighting, optional
            Overrides the renderer's lighting for this frame.
        occluders : sequence of Occluder
        index : int, optional
            Frame index (selects the noise); default: one more than the previous frame.
        """
        disp = self._check_displacement(plate_displacement)
        refl = self._static_layer(disp).copy()
        truth = []
        for i, part in enumerate(parts):
            uv = self._paint(refl, part.plate_outline(), part.height_m, part.reflectance, disp)
            inside = bool(
                np.all((uv >= -0.5) & (uv <= np.array([self.config.width, self.config.height]) - 0.5))
            )
            truth.append(PartTruth(i, part.label, part.x_m, part.y_m, part.theta_rad, inside))
        for occ in occluders:
            self._paint(refl, occ.polygon, occ.height_m, occ.reflectance, disp)
        image, idx = self._expose(refl, stamp_s, lighting, index)
        return RenderedFrame(image, float(stamp_s), idx, tuple(truth), np.zeros(6) if disp is None else disp)

    def render_checkerboard(
        self,
        board: Checkerboard,
        rvec: Sequence[float],
        tvec: Sequence[float],
        *,
        stamp_s: float = 0.0,
        lighting: Lighting | None = None,
        index: int | None = None,
    ) -> RenderedFrame:
        """Render a checkerboard card held or laid over the plate.

        ``rvec``, ``tvec`` (3,) give the board frame in the plate frame: plate point =
        R(rvec) @ board point + tvec (m). A board lying flat at (x, y, theta) is
        rvec = (0, 0, theta), tvec = (x, y, 0).
        """
        R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=float))
        t = np.asarray(tvec, dtype=float).reshape(3)

        def to_plate(poly: np.ndarray) -> np.ndarray:
            dense = densify(poly, _STATIC_EDGE_STEP_M)
            return np.concatenate([dense, np.zeros((len(dense), 1))], axis=1) @ R.T + t

        refl = self._static_layer(None).copy()
        # The card occludes the plate; it is drawn at full supersampling in its own window.
        st = self.style
        card = self.project(to_plate(board.outline()))
        squares = [self.project(to_plate(sq)) for sq in board.black_squares()]
        win = window_of(card, self.config.width, self.config.height, 2)
        if win is not None:
            u0, v0, u1, v1 = win
            ss = max(2, self.supersample // 2)
            canvas = np.zeros(((v1 - v0) * ss, (u1 - u0) * ss), dtype=np.uint8)
            fill_polygons(canvas, [card], (u0, v0), ss, 255)
            cover = downsample(canvas, ss)
            canvas[:] = 0
            fill_polygons(canvas, squares, (u0, v0), ss, 255)
            dark = downsample(canvas, ss)
            board_refl = st.board_white + (st.board_black - st.board_white) * dark
            sub = refl[v0:v1, u0:u1]
            sub[:] = sub * (1 - cover) + board_refl * cover
        image, idx = self._expose(refl, stamp_s, lighting, index)
        return RenderedFrame(image, float(stamp_s), idx, (), np.zeros(6))

    def _paint(
        self, refl: np.ndarray, poly_xy: np.ndarray, z_m: float, reflectance: float, disp: np.ndarray | None
    ) -> np.ndarray:
        uv = self._project_polygon(poly_xy, z_m, disp, _EDGE_STEP_M)
        win = window_of(uv, self.config.width, self.config.height, 2)
        if win is not None:
            u0, v0, u1, v1 = win
            c = coverage([uv], (u0, v0), (u1 - u0, v1 - v0), self.supersample)
            sub = refl[v0:v1, u0:u1]
            sub += (np.float32(reflectance) - sub) * c
        return uv

    def _expose(
        self, refl: np.ndarray, stamp_s: float, lighting: Lighting | None, index: int | None
    ) -> tuple[np.ndarray, int]:
        cfg, sensor = self.config, self.sensor
        if lighting is None:
            lighting = self.lighting if isinstance(self.lighting, Lighting) else self.lighting(float(stamp_s))
        if not isinstance(lighting, Lighting):
            raise ConfigError(f"lighting: expected a Lighting, got {type(lighting).__name__}")
        img = refl * self._gain_map(lighting)
        img *= np.float32(sensor.exposure_dn)
        if sensor.blur_sigma_px > 0:
            img = cv2.GaussianBlur(img, (0, 0), sensor.blur_sigma_px, borderType=cv2.BORDER_REFLECT)
        idx = self._next_index if index is None else int(index)
        self._next_index = idx + 1
        rng = np.random.default_rng([self.seed, idx])
        noise = rng.standard_normal(img.shape, dtype=np.float32)
        var = np.maximum(img, 0) * np.float32(sensor.shot_noise_dn2_per_dn) + np.float32(
            sensor.read_noise_dn**2
        )
        img += noise * np.sqrt(var)
        img += np.float32(0.5)
        np.clip(img, 0.0, 255.0, out=img)
        gray = img.astype(np.uint8)
        if cfg.encoding == "bgr8":
            return cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR), idx
        return gray, idx

    def _gain_map(self, lighting: Lighting) -> np.ndarray:
        g = self._gain.get(lighting)
        if g is None:
            if len(self._gain) > 8:
                self._gain.clear()
            g = lighting.gain_map(self.config.width, self.config.height)
            self._gain[lighting] = g
        return g

    # -- the static layer: table, plate, markers ---------------------------------------------------
    def _static_layer(self, disp: np.ndarray | None) -> np.ndarray:
        """The table, the plate and its markers: rendered once at rest, then moved per frame with the
        plate's displacement as an image-plane homography warp (bilinear; the table around the plate
        is uniform, so moving it with the plate changes nothing). Re-rasterising the markers at every
        frame's phase cost most of the simulated camera's time (0.7-0.8 s per 1280 x 1024 frame
        against about 13 ms for the warp); the warped markers' corners agree with the re-rasterised
        ones to a few hundredths of a pixel (tests/vision/test_renderer.py)."""
        if self._static is None:
            self._static = self._render_static(None)
        if disp is None or not np.any(disp):
            return self._static
        return cv2.warpPerspective(self._static, self.plate_homography(disp), (self.config.width, self.config.height),
                                   flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)

    def plate_homography(self, disp: np.ndarray) -> np.ndarray:
        """The 3 x 3 homography from pixels of the plate at rest to pixels of the plate displaced by
        ``disp``: least squares over a grid of plate points through the camera's full model (a plane
        seen through a pinhole; the lens distortion's share of a sub-millimetre move is far below a
        hundredth of a pixel)."""
        if self._plate_grid is None:
            h = self.config.plate.size_m / 2
            g = np.linspace(-h, h, 9)
            gx, gy = np.meshgrid(g, g)
            self._plate_grid = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
            self._plate_uv0 = self.project(self._plate_grid)
        H, _ = cv2.findHomography(self._plate_uv0, self.project(self._plate_grid, disp), 0)
        return H

    def _render_static(self, disp: np.ndarray | None) -> np.ndarray:
        cfg, st = self.config, self.style
        plate = cfg.plate
        ss = max(2, self.supersample // 2)
        # Reflectances are drawn as 8-bit levels (steps of 1/250) on a supersampled canvas.
        level = lambda r: int(round(r * 250))  # noqa: E731
        canvas = np.full((cfg.height * ss, cfg.width * ss), level(st.table), dtype=np.uint8)

        def poly(p: np.ndarray) -> np.ndarray:
            return self._project_polygon(p, 0.0, disp, _STATIC_EDGE_STEP_M)

        h = plate.size_m / 2
        fill_polygons(
            canvas, [poly(np.array([[-h, -h], [h, -h], [h, h], [-h, h]]))], (0, 0), ss, level(st.plate)
        )
        dictionary = marker_dictionary(plate.marker_dictionary)
        n = dictionary.markerSize + 2
        cell = plate.marker_size_m / n
        whites, blacks, bits = [], [], []
        for mid, x, y in plate.markers:
            q = plate.marker_size_m / 2 + cell
            whites.append(poly(_square(x - q, y - q, 2 * q)))
            s = plate.marker_size_m / 2
            blacks.append(poly(_square(x - s, y - s, 2 * s)))
            pattern = cv2.aruco.generateImageMarker(dictionary, mid, n)
            for r, c in zip(*np.nonzero(pattern > 127)):
                # Row r of the marker image runs along plate -y from the marker's top edge.
                bits.append(poly(_square(x - s + c * cell, y + s - (r + 1) * cell, cell)))
        fill_polygons(canvas, whites, (0, 0), ss, level(st.marker_white))
        fill_polygons(canvas, blacks, (0, 0), ss, level(st.marker_black))
        fill_polygons(canvas, bits, (0, 0), ss, level(st.marker_white))
        return downsample(canvas, ss) * np.float32(255 / 250)

    @staticmethod
    def _check_displacement(d: Sequence[float] | None) -> np.ndarray | None:
        if d is None:
            return None
        arr = check_array(d, "plate_displacement", shape=(6,))
        if np.any(np.abs(arr[:3]) > 0.005) or np.any(np.abs(arr[3:]) > 0.05):
            raise ConfigError(
                f"plate_displacement: expected a small vibration displacement (|d| <= 5 mm, "
                f"|angle| <= 0.05 rad), got {arr.tolist()}"
            )
        return arr


def _square(x0: float, y0: float, side: float) -> np.ndarray:
    return np.array([[x0, y0], [x0 + side, y0], [x0 + side, y0 + side], [x0, y0 + side]])


def board_pose_flat(
    x_m: float, y_m: float, theta_rad: float, z_m: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """(rvec, tvec) of a checkerboard lying flat on the plate at (x, y, theta)."""
    return np.array([0.0, 0.0, theta_rad]), np.array([x_m, y_m, z_m])


def tilted_board_pose(
    x_m: float, y_m: float, z_m: float, tilt_x_rad: float, tilt_y_rad: float, yaw_rad: float
) -> tuple[np.ndarray, np.ndarray]:
    """(rvec, tvec) of a board held above the plate: yaw, then tilts about plate x and y."""
    Rz, _ = cv2.Rodrigues(np.array([0.0, 0.0, yaw_rad]))
    Rx, _ = cv2.Rodrigues(np.array([tilt_x_rad, 0.0, 0.0]))
    Ry, _ = cv2.Rodrigues(np.array([0.0, tilt_y_rad, 0.0]))
    rvec, _ = cv2.Rodrigues(Ry @ Rx @ Rz)
    return rvec.reshape(3), np.array([x_m, y_m, z_m])


__all__ = ["CameraRenderer", "board_pose_flat", "tilted_board_pose"]

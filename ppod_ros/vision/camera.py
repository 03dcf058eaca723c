"""Camera and plate description shared by the simulated camera and the part tracker.

:class:`CameraConfig` holds what a camera calibration file holds (resolution, encoding, frame rate,
pinhole intrinsics, lens distortion, mounting pose) plus the :class:`PlateLayout` the camera looks
at (plate size, the fiducial markers printed on it, the work area where parts are tracked). Both
are frozen, validated on construction and loaded strictly from YAML (unknown keys, wrong shapes and
non-finite numbers are errors naming the key)::

    camera:
      width: 1280
      height: 1024
      encoding: mono8            # mono8 or bgr8
      fps: 10
      intrinsics: {fx: 1700, fy: 1700, cx: 639.5, cy: 511.5}   # pixels
      distortion: [-0.08, 0.05, 0.0005, -0.0003, 0.0]         # OpenCV k1 k2 p1 p2 k3
      mount:
        position_m: [0.004, -0.006, 0.70]   # optical centre in the plate frame
        rotation_deg: [1.2, -1.5, 0.8]      # deviation from looking straight down (see below)
    plate:
      size_m: 0.35
      work_area_m: [-0.125, 0.125, -0.125, 0.125]
      markers: {dictionary: DICT_4X4_50, size_m: 0.024,
                layout: [[0, -0.151, -0.151], [1, 0.0, -0.151], ...]}   # [id, x, y]

Frames: the plate frame P (PHYSICS.md) has z up. The camera frame is OpenCV's (x right, y down,
z along the optical axis). A camera looking straight down with image x along plate x has
R_plate_from_camera = diag(1, -1, -1); ``rotation_deg`` = (rx, ry, rz) rotates the camera further
about its own x, then y, then z axis (intrinsic XYZ), so a real mount's small tilt is three small
numbers. Markers are axis-aligned on the plate, their image "up" along plate +y.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ppod_ros.config.fields import Fields, check_array, check_number, load_yaml_file, parse_yaml_text
from ppod_ros.errors import ConfigError

ENCODINGS = ("mono8", "bgr8")
#: ArUco dictionaries a layout may name (those of cv2.aruco; markers are 4x4 to 7x7 bits).
MARKER_DICTIONARIES = (
    "DICT_4X4_50",
    "DICT_4X4_100",
    "DICT_5X5_50",
    "DICT_5X5_100",
    "DICT_6X6_50",
    "DICT_6X6_100",
    "DICT_7X7_50",
    "DICT_7X7_100",
)

#: Default fiducial ring: four corners and four edge midpoints, inside a 0.35 m plate.
DEFAULT_MARKERS: tuple[tuple[int, float, float], ...] = (
    (0, -0.151, -0.151),
    (1, 0.0, -0.151),
    (2, 0.151, -0.151),
    (3, 0.151, 0.0),
    (4, 0.151, 0.151),
    (5, 0.0, 0.151),
    (6, -0.151, 0.151),
    (7, -0.151, 0.0),
)

_R_DOWN = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class PlateLayout:
    """The square plate seen by the camera, its fiducial markers and its work area.

    Parameters
    ----------
    size_m : float
        Side of the square plate (m), centred on the plate frame's origin.
    work_area_m : tuple of 4 floats
        (x_min, x_max, y_min, y_max) in the plate frame (m): parts are detected only here, away
        from the markers.
    marker_dictionary : str
        ArUco dictionary name (one of :data:`MARKER_DICTIONARIES`).
    marker_size_m : float
        Side of each marker's black square, border included (m). A white quiet zone of one
        marker cell surrounds it on the plate.
    markers : tuple of (id, x_m, y_m)
        Marker ids and centres in the plate frame; ids unique and valid for the dictionary.
    """

    size_m: float = 0.35
    work_area_m: tuple[float, float, float, float] = (-0.125, 0.125, -0.125, 0.125)
    marker_dictionary: str = "DICT_4X4_50"
    marker_size_m: float = 0.024
    markers: tuple[tuple[int, float, float], ...] = DEFAULT_MARKERS

    def __post_init__(self) -> None:
        size = check_number(self.size_m, "plate.size_m", min_value=0.0, exclusive_min=True, unit="m")
        wa = check_array(self.work_area_m, "plate.work_area_m", shape=(4,), unit="m")
        if not (wa[0] < wa[1] and wa[2] < wa[3]):
            raise ConfigError(
                f"plate.work_area_m: expected [x_min, x_max, y_min, y_max] with min < max, got {wa.tolist()}"
            )
        if np.any(np.abs(wa) > size / 2):
            raise ConfigError(
                f"plate.work_area_m: must lie on the plate (|value| <= {size / 2} m), got {wa.tolist()}"
            )
        if self.marker_dictionary not in MARKER_DICTIONARIES:
            raise ConfigError(
                f"plate.markers.dictionary: expected one of {', '.join(MARKER_DICTIONARIES)}; "
                f"got {self.marker_dictionary!r}"
            )
        msize = check_number(
            self.marker_size_m, "plate.markers.size_m", min_value=0.0, exclusive_min=True, unit="m"
        )
        rows = []
        limit = int(self.marker_dictionary.rsplit("_", 1)[1])
        for i, entry in enumerate(self.markers):
            arr = check_array(entry, f"plate.markers.layout[{i}]", shape=(3,))
            if arr[0] != round(arr[0]) or not 0 <= arr[0] < limit:
                raise ConfigError(
                    f"plate.markers.layout[{i}]: id must be an integer in 0..{limit - 1}, got {arr[0]}"
                )
            if np.any(np.abs(arr[1:]) + 0.75 * msize > size / 2):
                raise ConfigError(
                    f"plate.markers.layout[{i}]: marker at {arr[1:].tolist()} m does not fit on the plate"
                )
            rows.append((int(arr[0]), float(arr[1]), float(arr[2])))
        ids = [r[0] for r in rows]
        if len(set(ids)) != len(ids):
            raise ConfigError(f"plate.markers.layout: marker ids must be unique, got {ids}")
        object.__setattr__(self, "size_m", size)
        object.__setattr__(self, "work_area_m", tuple(float(v) for v in wa))
        object.__setattr__(self, "marker_size_m", msize)
        object.__setattr__(self, "markers", tuple(rows))

    def marker_corners(self) -> dict[int, np.ndarray]:
        """Plate-frame corners (4, 2) of each marker in ArUco order (TL, TR, BR, BL, image-upright)."""
        h = self.marker_size_m / 2
        offs = np.array([[-h, h], [h, h], [h, -h], [-h, -h]])
        return {mid: offs + np.array([x, y]) for mid, x, y in self.markers}

    def in_work_area(self, xy: np.ndarray) -> np.ndarray:
        """Boolean mask (N,) of plate points (N, 2) inside the work area."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        x0, x1, y0, y1 = self.work_area_m
        return (xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)

    @classmethod
    def from_fields(cls, f: Fields) -> PlateLayout:
        d = cls()
        size = f.number("size_m", d.size_m, min_value=0.0, exclusive_min=True, unit="m")
        wa = f.array("work_area_m", list(d.work_area_m), shape=(4,), unit="m")
        m = f.sub("markers", {})
        dictionary = m.string("dictionary", d.marker_dictionary, choices=MARKER_DICTIONARIES)
        msize = m.number("size_m", d.marker_size_m, min_value=0.0, exclusive_min=True, unit="m")
        layout = m.array("layout", [list(r) for r in d.markers], shape=(None, 3))
        m.finish()
        f.finish()
        return cls(size, tuple(wa), dictionary, msize, tuple(tuple(r) for r in layout))

    def to_dict(self) -> dict[str, Any]:
        return {
            "size_m": self.size_m,
            "work_area_m": list(self.work_area_m),
            "markers": {
                "dictionary": self.marker_dictionary,
                "size_m": self.marker_size_m,
                "layout": [list(r) for r in self.markers],
            },
        }


@dataclass(frozen=True)
class CameraConfig:
    """A camera: image format, pinhole intrinsics, distortion and mounting pose over the plate.

    Parameters
    ----------
    width, height : int
        Image size (pixels).
    encoding : str
        ``"mono8"`` or ``"bgr8"`` (uint8, 1 or 3 channels).
    fps : float
        Nominal frame rate (Hz); a triggered camera takes each frame at the first plate-cycle
        start after each frame tick.
    fx, fy, cx, cy : float
        Pinhole intrinsics (pixels; the centre of the top-left pixel is (0, 0)).
    distortion : tuple of 5 floats
        OpenCV (k1, k2, p1, p2, k3).
    position_m : tuple of 3 floats
        Optical centre in the plate frame (m); z > 0 (above the plate).
    rotation_deg : tuple of 3 floats
        Deviation (deg) from looking straight down, intrinsic rotations about the camera's x, y, z.
    plate : PlateLayout
        What the camera looks at.
    """

    width: int = 1280
    height: int = 1024
    encoding: str = "mono8"
    fps: float = 10.0
    fx: float = 1700.0
    fy: float = 1700.0
    cx: float = 639.5
    cy: float = 511.5
    distortion: tuple[float, float, float, float, float] = (-0.08, 0.05, 0.0005, -0.0003, 0.0)
    position_m: tuple[float, float, float] = (0.004, -0.006, 0.70)
    rotation_deg: tuple[float, float, float] = (1.2, -1.5, 0.8)
    plate: PlateLayout = field(default_factory=PlateLayout)

    def __post_init__(self) -> None:
        for name, lo in (("width", 16), ("height", 16)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo or v > 16384:
                raise ConfigError(
                    f"camera.{name}: expected an integer number of pixels in {lo}..16384, got {v!r}"
                )
            object.__setattr__(self, name, int(v))
        if self.encoding not in ENCODINGS:
            raise ConfigError(
                f"camera.encoding: expected one of {', '.join(ENCODINGS)}; got {self.encoding!r}"
            )
        object.__setattr__(
            self, "fps", check_number(self.fps, "camera.fps", min_value=0.0, exclusive_min=True, unit="Hz")
        )
        for name in ("fx", "fy"):
            object.__setattr__(
                self,
                name,
                check_number(
                    getattr(self, name),
                    f"camera.intrinsics.{name}",
                    min_value=0.0,
                    exclusive_min=True,
                    unit="px",
                ),
            )
        for name in ("cx", "cy"):
            object.__setattr__(
                self, name, check_number(getattr(self, name), f"camera.intrinsics.{name}", unit="px")
            )
        dist = check_array(self.distortion, "camera.distortion", shape=(5,))
        pos = check_array(self.position_m, "camera.mount.position_m", shape=(3,), unit="m")
        if pos[2] <= 0:
            raise ConfigError(
                f"camera.mount.position_m: the camera must be above the plate (z > 0 m), got z = {pos[2]}"
            )
        rot = check_array(
            self.rotation_deg,
            "camera.mount.rotation_deg",
            shape=(3,),
            min_value=-45.0,
            max_value=45.0,
            unit="deg",
        )
        if not isinstance(self.plate, PlateLayout):
            raise ConfigError(f"camera.plate: expected a PlateLayout, got {type(self.plate).__name__}")
        object.__setattr__(self, "distortion", tuple(float(v) for v in dist))
        object.__setattr__(self, "position_m", tuple(float(v) for v in pos))
        object.__setattr__(self, "rotation_deg", tuple(float(v) for v in rot))

    # -- derived quantities -------------------------------------------------------------------
    @property
    def channels(self) -> int:
        return 1 if self.encoding == "mono8" else 3

    @property
    def shape(self) -> tuple[int, ...]:
        """numpy shape of one frame: (height, width) or (height, width, 3)."""
        return (self.height, self.width) if self.channels == 1 else (self.height, self.width, 3)

    @property
    def camera_matrix(self) -> np.ndarray:
        """Intrinsic matrix K (3, 3)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        """Distortion coefficients (5,) in OpenCV order."""
        return np.array(self.distortion)

    @property
    def rotation_plate_from_camera(self) -> np.ndarray:
        """R (3, 3) taking camera-frame vectors to the plate frame."""
        rx, ry, rz = (math.radians(a) for a in self.rotation_deg)
        return _R_DOWN @ _rot(0, rx) @ _rot(1, ry) @ _rot(2, rz)

    def extrinsics(self) -> tuple[np.ndarray, np.ndarray]:
        """OpenCV (rvec (3,), tvec (3,)) mapping plate-frame points into the camera frame."""
        import cv2

        R = self.rotation_plate_from_camera.T
        t = -R @ np.array(self.position_m)
        rvec, _ = cv2.Rodrigues(R)
        return rvec.reshape(3), t

    def with_changes(self, **changes: Any) -> CameraConfig:
        """A copy with some fields replaced (validated again)."""
        return replace(self, **changes)

    # -- YAML ---------------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = "") -> CameraConfig:
        """Parse ``{camera: {...}, plate: {...}}`` (both optional; defaults fill the rest)."""
        top = Fields(data, where)
        c = top.sub("camera", {})
        p = top.sub("plate", {})
        top.finish()
        d = cls()
        width = c.integer("width", d.width, min_value=16)
        height = c.integer("height", d.height, min_value=16)
        encoding = c.string("encoding", d.encoding, choices=ENCODINGS)
        fps = c.number("fps", d.fps, min_value=0.0, exclusive_min=True, unit="Hz")
        intr = c.sub("intrinsics", {})
        fx = intr.number("fx", d.fx, min_value=0.0, exclusive_min=True, unit="px")
        fy = intr.number("fy", d.fy, min_value=0.0, exclusive_min=True, unit="px")
        cx = intr.number("cx", (width - 1) / 2, unit="px")
        cy = intr.number("cy", (height - 1) / 2, unit="px")
        intr.finish()
        dist = c.array("distortion", list(d.distortion), shape=(5,))
        mount = c.sub("mount", {})
        pos = mount.array("position_m", list(d.position_m), shape=(3,), unit="m")
        rot = mount.array("rotation_deg", list(d.rotation_deg), shape=(3,), unit="deg")
        mount.finish()
        c.finish()
        return cls(
            width,
            height,
            encoding,
            fps,
            fx,
            fy,
            cx,
            cy,
            tuple(dist),
            tuple(pos),
            tuple(rot),
            PlateLayout.from_fields(p),
        )

    @classmethod
    def from_yaml(cls, path: str | Path) -> CameraConfig:
        data = load_yaml_file(path, "camera")
        try:
            return cls.from_dict(data)
        except ConfigError as exc:
            raise ConfigError(f"{path}: {exc}") from exc

    @classmethod
    def from_yaml_text(cls, text: str, origin: str = "camera") -> CameraConfig:
        data = parse_yaml_text(text, origin)
        try:
            return cls.from_dict(data)
        except ConfigError as exc:
            raise ConfigError(f"{origin}: {exc}") from exc

    def to_dict(self) -> dict[str, Any]:
        return {
            "camera": {
                "width": self.width,
                "height": self.height,
                "encoding": self.encoding,
                "fps": self.fps,
                "intrinsics": {"fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy},
                "distortion": list(self.distortion),
                "mount": {"position_m": list(self.position_m), "rotation_deg": list(self.rotation_deg)},
            },
            "plate": self.plate.to_dict(),
        }

    def to_yaml(self) -> str:
        import yaml

        return yaml.safe_dump(self.to_dict(), sort_keys=False)


def _rot(axis: int, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i] = c
    R[j, j] = c
    R[i, j] = -s
    R[j, i] = s
    return R


__all__ = ["CameraConfig", "PlateLayout", "ENCODINGS", "MARKER_DICTIONARIES", "DEFAULT_MARKERS"]

"""Vision: plate-to-image calibration, part detection and multi-part tracking (no ROS).

Modules, in the order a frame meets them:

- :mod:`~ppod_ros.vision.camera`: :class:`CameraConfig` (image format, intrinsics, distortion,
  mount) and :class:`PlateLayout` (plate, fiducials, work area), shared with the simulated camera.
- :mod:`~ppod_ros.vision.sources`: frame sources (generator, VideoCapture, recordings).
- :mod:`~ppod_ros.vision.frames`: frame validation (:class:`BadFrameError` with a reason).
- :mod:`~ppod_ros.vision.calibration`: plate pose from the fiducials or a checkerboard; intrinsics.
- :mod:`~ppod_ros.vision.geometry`: :class:`PlateCalibration`, the plate-to-image mapping.
- :mod:`~ppod_ros.vision.detection`: blobs and their moments in the plate frame.
- :mod:`~ppod_ros.vision.shapes`: :class:`PartSpec` and the pose of a blob.
- :mod:`~ppod_ros.vision.kalman`: the constant-velocity pose filter.
- :mod:`~ppod_ros.vision.tracker`: :class:`PartTracker`; its results in
  :mod:`~ppod_ros.vision.track_result`, its settings and part lists in
  :mod:`~ppod_ros.vision.tracker_config`.
"""

from ppod_ros.vision.calibration import (
    CalibrationError,
    Checkerboard,
    IntrinsicsResult,
    calibrate_intrinsics,
    calibrate_plate_from_checkerboard,
    calibrate_plate_from_markers,
    detect_markers,
    find_checkerboard,
)
from ppod_ros.vision.camera import CameraConfig, PlateLayout
from ppod_ros.vision.detection import Blob, BlobDetector, DetectorSettings
from ppod_ros.vision.frames import BadFrameError, Frame, check_frame
from ppod_ros.vision.geometry import PixelMap, PlateCalibration
from ppod_ros.vision.kalman import FilterSettings, PoseFilter
from ppod_ros.vision.shapes import PartSpec, PoseFit, wrap_angle
from ppod_ros.vision.sources import (
    FrameSource,
    GeneratorSource,
    RecordedSource,
    VideoCaptureSource,
    open_source,
    save_npz_recording,
)
from ppod_ros.vision.track_result import TrackedPart, TrackResult, TrackStatus, UnexplainedBlob
from ppod_ros.vision.tracker import PartTracker
from ppod_ros.vision.tracker_config import TrackerSettings, load_part_specs, load_tracker_config

__all__ = [
    "BadFrameError",
    "Blob",
    "BlobDetector",
    "CalibrationError",
    "CameraConfig",
    "Checkerboard",
    "DetectorSettings",
    "FilterSettings",
    "Frame",
    "FrameSource",
    "GeneratorSource",
    "IntrinsicsResult",
    "PartSpec",
    "PartTracker",
    "PixelMap",
    "PlateCalibration",
    "PlateLayout",
    "PoseFilter",
    "PoseFit",
    "RecordedSource",
    "TrackResult",
    "TrackStatus",
    "TrackedPart",
    "TrackerSettings",
    "UnexplainedBlob",
    "VideoCaptureSource",
    "calibrate_intrinsics",
    "calibrate_plate_from_checkerboard",
    "calibrate_plate_from_markers",
    "check_frame",
    "detect_markers",
    "find_checkerboard",
    "load_part_specs",
    "load_tracker_config",
    "open_source",
    "save_npz_recording",
    "wrap_angle",
]

"""part_tracker: overhead-camera frames in, tracked part poses (PartPoseArray) out.

Lifecycle node (STYLE.md rule 9):
  configure  load the camera and tracker files, build the tracker, open a camera or file source
  activate   subscribe to the image topic (sensor-data QoS), or start reading the source at its fps
  deactivate stop reading; tracks are kept
  cleanup    close the source, drop the tracker

Frames come from the simulated camera's image topic (``source: topic``), a real camera through
OpenCV VideoCapture (``source: capture``, ``source_uri: "0"`` or a URL) or a recording
(``source: file``). Each PartPoseArray is stamped with its frame's capture time. Bad frames (empty,
wrong size, encoding or exposure) are logged and skipped. Diagnostics: fps, latency, lost tracks,
rejected frames by reason.
"""

from __future__ import annotations

import time
from importlib import resources
from pathlib import Path

import numpy as np
from geometry_msgs.msg import Pose2D
from ppod_msgs.msg import PartPose, PartPoseArray
from sensor_msgs.msg import CameraInfo, Image

from ppod_nodes.common import diagnostics as diag
from ppod_nodes.common import qos, topics
from ppod_nodes.common.convert import seconds_to_stamp, stamp_to_seconds
from ppod_nodes.common.lifecycle import PpodLifecycleNode
from ppod_nodes.common.params import Param
from ppod_nodes.common.runner import make_main
from ppod_ros.errors import ConfigError, DeviceError
from ppod_ros.vision import (
    BadFrameError,
    CalibrationError,
    CameraConfig,
    PartTracker,
    TrackResult,
    TrackStatus,
    load_tracker_config,
    open_source,
)
from ppod_ros.vision.ros_camera import (
    decode_image,
    intrinsics_from_camera_info,
    load_ost_yaml,
    to_encoding,
    with_intrinsics,
)


def default_tracker_config_path() -> Path:
    return Path(str(resources.files("ppod_ros") / "data" / "tracker.yaml"))


def image_to_array(msg: Image, encoding: str | None = None) -> np.ndarray:
    """A sensor_msgs/Image as uint8 (H, W) or (H, W, 3) BGR, in ``encoding`` if given; BadFrameError if malformed.

    Reads mono8, mono16, bgr8, rgb8 and the 8-bit Bayer patterns (ppod_ros.vision.ros_camera).
    """
    image = decode_image(msg.encoding, msg.width, msg.height, msg.step, msg.data, bool(msg.is_bigendian))
    return image if encoding is None else to_encoding(image, encoding)


def result_to_msg(result: TrackResult, frame_index: int, latency_s: float) -> PartPoseArray:
    out = PartPoseArray()
    out.header.stamp = seconds_to_stamp(result.stamp_s)
    out.header.frame_id = "plate"
    out.frame_index = frame_index
    out.latency_s = latency_s
    for p in result.parts:
        pose = PartPose(id=int(p.id), label=p.label, status=int(p.status))
        pose.pose = Pose2D(x=float(p.x_m), y=float(p.y_m), theta=float(p.theta_rad))
        cov = np.nan_to_num(np.asarray(p.covariance, dtype=float), posinf=1e12)
        pose.covariance = cov.reshape(9)
        pose.vx, pose.vy, pose.omega = float(p.vx_mps), float(p.vy_mps), float(p.omega_radps)
        pose.symmetry_rad = float(p.symmetry_rad)
        pose.stamp = seconds_to_stamp(p.last_measured_s if p.status == TrackStatus.LOST else result.stamp_s)
        out.parts.append(pose)
    return out


class PartTrackerNode(PpodLifecycleNode):
    PARAMS = (
        Param("camera_config", "", "camera YAML (CameraConfig); empty: the simulated device's camera"),
        Param("tracker_config", "", "tracker YAML: part types (label, footprint or part, height_m) and "
              "settings; empty: the packaged list of the simulated device's parts"),
        Param("source", "topic", "where frames come from", choices=("topic", "capture", "file")),
        Param("source_uri", "", "camera index or URL (capture), recording path (file)"),
        Param("source_fps", 10.0, "frame rate for capture/file sources (Hz)", min_value=0.1, max_value=200.0),
        Param("intrinsics", "", "camera_calibration's ost.yaml (or a camera_info YAML): replaces the camera "
              "file's intrinsics; empty: the camera file's"),
        Param("use_camera_info", False, "take the intrinsics from ppod/camera/camera_info (topic source): the "
              "tracker is rebuilt when they change"),
    )

    RUNTIME_PARAMS = ("source_fps",)

    def __init__(self, **kwargs):
        super().__init__("part_tracker", **kwargs)
        self._tracker: PartTracker | None = None
        self._source = None
        self._sub = None
        self._timer = None
        self._pub = None
        self._frames = 0
        self._rejected: dict[str, int] = {}
        self._window: list[tuple[float, float]] = []  # (wall time, processing s)
        self._diag_timer = None
        self._last_result: TrackResult | None = None
        self._info_sub = None
        self._camera = None

    # ------------------------------------------------------------------ lifecycle
    def on_configure_node(self, params):
        camera = CameraConfig.from_yaml(params["camera_config"]) if params["camera_config"] else CameraConfig()
        if params["intrinsics"]:
            camera = with_intrinsics(camera, load_ost_yaml(params["intrinsics"]))
        specs, settings = load_tracker_config(params["tracker_config"] or default_tracker_config_path())
        self._camera, self._specs, self._settings = camera, specs, settings
        self._tracker = PartTracker(camera, specs, settings)
        if params["source"] != "topic":
            uri = params["source_uri"]
            if not uri:
                raise ConfigError(f"parameter source_uri: required with source '{params['source']}'")
            self._source = open_source(int(uri) if uri.isdigit() else uri, camera.encoding, params["source_fps"])
        self._pub = self.create_lifecycle_publisher(PartPoseArray, topics.PART_POSES, qos.STREAM)
        self._diag_timer = self.create_timer(1.0, self._report)
        self.get_logger().info(f"tracking {', '.join(s.label for s in specs)} from {params['source']} "
                               f"({camera.width}x{camera.height} {camera.encoding})")

    def on_activate_node(self):
        if self._source is None:
            self._sub = self.create_subscription(Image, topics.IMAGE, self._on_image, qos.SENSOR_DATA)
            if self.params["use_camera_info"] and self._info_sub is None:
                self._info_sub = self.create_subscription(CameraInfo, topics.CAMERA_INFO, self._on_camera_info,
                                                          qos.LATCHED)
        else:
            self._timer = self.create_timer(1.0 / self.params["source_fps"], self._read_source)

    def apply_parameter(self, name, value):
        if name == "source_fps" and self._timer is not None:  # reading a camera or file: new pace now
            self.destroy_timer(self._timer)
            self._timer = self.create_timer(1.0 / value, self._read_source)

    def on_deactivate_node(self):
        if self._sub is not None:
            self.destroy_subscription(self._sub)
            self._sub = None
        if self._timer is not None:
            self.destroy_timer(self._timer)
            self._timer = None

    def on_cleanup_node(self):
        self.on_deactivate_node()
        if self._source is not None:
            self._source.close()
            self._source = None
        if self._diag_timer is not None:
            self.destroy_timer(self._diag_timer)
            self._diag_timer = None
        if self._pub is not None:
            self.destroy_lifecycle_publisher(self._pub)
            self._pub = None
        self._tracker = None

    def on_shutdown_node(self):
        self.on_cleanup_node()

    # ------------------------------------------------------------------ frames
    def _on_camera_info(self, msg: CameraInfo) -> None:
        if self._tracker is None:
            return
        try:
            camera = with_intrinsics(self._camera, intrinsics_from_camera_info(
                msg.width, msg.height, msg.k, msg.d, msg.distortion_model))
        except ConfigError as exc:
            self.get_logger().error(f"camera_info ignored: {exc}", throttle_duration_sec=5.0)
            return
        if camera != self._camera:
            self._camera = camera
            self._tracker = PartTracker(camera, self._specs, self._settings)
            self.get_logger().info(f"intrinsics from camera_info: fx {camera.fx:.1f}, fy {camera.fy:.1f}, "
                                   f"cx {camera.cx:.1f}, cy {camera.cy:.1f} px ({camera.width}x{camera.height})")

    def _on_image(self, msg: Image) -> None:
        if self._tracker is None:
            return  # between cleanup and the last callbacks
        try:
            image = image_to_array(msg, self._camera.encoding)
        except BadFrameError as exc:
            self._reject(exc)
            return
        self._process(image, stamp_to_seconds(msg.header.stamp))

    def _read_source(self) -> None:
        try:
            frame = self._source.read()
        except DeviceError as exc:
            self.diagnostics.set("camera", diag.ERROR, f"camera stopped: {exc}")
            return
        if frame is None:
            self.diagnostics.set("camera", diag.WARN, "end of recording")
            self.destroy_timer(self._timer)
            self._timer = None
            return
        self._process(frame.image, frame.stamp_s)

    def _process(self, image: np.ndarray, stamp_s: float) -> None:
        t0 = time.monotonic()
        try:
            result = self._tracker.update(image, stamp_s)
        except BadFrameError as exc:
            self._reject(exc)
            return
        except CalibrationError as exc:
            # No usable view of the markers yet: say so and try again on the next frame.
            self.diagnostics.set("calibration", diag.WARN, f"plate not calibrated: {exc}")
            return
        processing = time.monotonic() - t0
        self._last_result = result
        self._frames += 1
        now_ros = self.get_clock().now().nanoseconds * 1e-9
        latency = max(0.0, now_ros - stamp_s) if now_ros > 0 else processing
        if self._pub is None:
            return  # cleaned up while this frame was processed (shutdown)
        self._pub.publish(result_to_msg(result, self._frames, latency))
        self._window.append((time.monotonic(), processing))
        for event, ids in (("new", result.new_ids), ("lost", result.lost_ids), ("reacquired", result.reacquired_ids)):
            if ids:
                self.get_logger().info(f"frame {self._frames}: {event} track{'s' if len(ids) > 1 else ''} "
                                       f"{', '.join(map(str, ids))}")

    def _reject(self, exc: BadFrameError) -> None:
        self._rejected[exc.reason] = self._rejected.get(exc.reason, 0) + 1
        self.get_logger().warning(f"skipped a frame: {exc}", throttle_duration_sec=2.0)

    def _report(self) -> None:
        now = time.monotonic()
        self._window = [w for w in self._window if now - w[0] <= 5.0]
        fps = len(self._window) / 5.0
        proc_ms = 1000 * float(np.median([w[1] for w in self._window])) if self._window else float("nan")
        last = self._last_result
        lost = 0 if last is None else sum(p.status == TrackStatus.LOST for p in last.parts)
        level = diag.OK if fps > 0 or self.lifecycle_state != "active" else diag.WARN
        self.diagnostics.set("tracker", level, f"{fps:.1f} fps, {lost} lost", fps=fps, processing_ms=proc_ms,
                             frames=self._frames, lost_tracks=lost,
                             **{f"rejected_{k}": v for k, v in sorted(self._rejected.items())})


main = make_main(PartTrackerNode)

if __name__ == "__main__":
    raise SystemExit(main())

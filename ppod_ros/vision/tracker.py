"""Multi-part tracking: stable ids, filtered poses and velocities, honest status.

:class:`PartTracker` turns frames into a :class:`TrackResult` per frame::

    tracker = PartTracker(camera_config, [PartSpec("washer", Footprint.from_value({"disk": 0.006}))])
    result = tracker.update(image, stamp_s)          # BadFrameError if the frame is unusable
    for part in result.parts:
        part.id, part.label, part.status, part.pose, part.covariance, part.velocity

Each frame: blobs are detected and measured in the plate frame (:mod:`~ppod_ros.vision.detection`),
each blob is matched to a part type by area and shape and its pose fitted
(:mod:`~ppod_ros.vision.shapes`); blobs that fit no part type are explained, not guessed: a blob
that touches the work area's edge is ``edge``, one within about four pixels of another blob (their
edges mix) is measured only when its fit is clean (within half the area and shape tolerances; parts
at rest a few mm apart stay tracked) and is ``touching`` otherwise, one larger than any part is
``merged`` (parts touching, seen as
one blob), one smaller or misshapen is ``occluded``. Tracks are predicted to the frame time by a
constant-velocity filter (:mod:`~ppod_ros.vision.kalman`) and matched to fitted blobs of their own
label by the Hungarian method on distance, within a gate that grows with the track's uncertainty.

Status (same numbers as ppod_msgs/PartPose): TRACKED = measured in this frame; PREDICTED = not
measured (``reason`` says why: merged, touching, occluded, edge, out_of_view, missed), pose from
the filter (a part in contact with another is held still: parts cannot pass through each other);
LOST = not measured for longer than ``max_coast_s``: the pose is the last measured one. A lost
part that reappears within ``reacquire_radius_m`` of where it was lost, with no other lost part of
its type as close, gets its id back (``reacquired``); otherwise a new id. Dropped frames only
lengthen the prediction step.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import linear_sum_assignment

from ppod_ros.errors import ConfigError
from ppod_ros.vision.calibration import PlateShift, calibrate_plate_from_markers, measure_plate_shift
from ppod_ros.vision.camera import CameraConfig
from ppod_ros.vision.detection import Blob, BlobDetector
from ppod_ros.vision.frames import BadFrameError, check_frame, check_stamp, to_gray
from ppod_ros.vision.geometry import PlateCalibration
from ppod_ros.vision.kalman import PoseFilter
from ppod_ros.vision.shapes import PartSpec, PoseFit, wrap_angle
from ppod_ros.vision.track_result import TrackedPart, TrackResult, TrackStatus, UnexplainedBlob
from ppod_ros.vision.tracker_config import TrackerSettings, load_part_specs, load_tracker_config

_FAR = 1e9


@dataclass
class _Track:
    id: int
    spec: PartSpec
    filter: PoseFilter
    status: TrackStatus
    reason: str
    last_measured_s: float
    last_pose: tuple[float, float, float]
    last_cov: list[list[float]]
    last_vel: tuple[float, float, float]


@dataclass(frozen=True)
class _Measurement:
    spec: PartSpec
    fit: PoseFit
    blob: Blob


class PartTracker:
    """Track parts of known types on the plate from camera frames.

    Parameters
    ----------
    camera : CameraConfig
        The camera (intrinsics, distortion, nominal mount) and the plate it looks at.
    parts : sequence of PartSpec
        Part types to look for; labels must be unique.
    settings : TrackerSettings, optional
    calibration : PlateCalibration, optional
        The plate-to-image mapping; if omitted, the first frame is calibrated from the plate's
        fiducial markers (:meth:`calibrate`).
    """

    def __init__(
        self,
        camera: CameraConfig,
        parts: Sequence[PartSpec],
        settings: TrackerSettings | None = None,
        calibration: PlateCalibration | None = None,
    ):
        if not isinstance(camera, CameraConfig):
            raise ConfigError(f"camera: expected a CameraConfig, got {type(camera).__name__}")
        specs = tuple(parts)
        if not specs or not all(isinstance(p, PartSpec) for p in specs):
            raise ConfigError("parts: expected at least one PartSpec")
        labels = [p.label for p in specs]
        if len(set(labels)) != len(labels):
            raise ConfigError(f"parts: labels must be unique, got {labels}")
        self.camera = camera
        self.specs = specs
        self.settings = settings or TrackerSettings()
        self._calibration: PlateCalibration | None = None
        #: The plate's last measured shift from its calibrated place (None: not measured yet).
        self.plate_shift: PlateShift | None = None
        self.plate_shift_misses = 0
        self._detector: BlobDetector | None = None
        self._tracks: list[_Track] = []
        self._next_id = 1
        self._last_stamp: float | None = None
        self._frames = 0
        self.rejected: dict[str, int] = {}
        if calibration is not None:
            self.set_calibration(calibration)

    # -- calibration ---------------------------------------------------------------------------
    @property
    def calibration(self) -> PlateCalibration | None:
        return self._calibration

    def set_calibration(self, calibration: PlateCalibration) -> None:
        """Use this plate-to-image mapping from now on (tracks are kept)."""
        if (calibration.width, calibration.height) != (self.camera.width, self.camera.height):
            raise ConfigError(
                f"calibration: made for {calibration.width}x{calibration.height} px, the camera is "
                f"{self.camera.width}x{self.camera.height} px"
            )
        det_settings = self.settings.detector
        largest = 2 * max(p.radius_m for p in self.specs)
        if largest > det_settings.max_part_size_m:
            det_settings = replace(det_settings, max_part_size_m=largest)
        self._calibration = calibration
        self._detector = BlobDetector(calibration, self.camera.plate, det_settings)
        orders = sorted({n for p in self.specs for n in p.orders if n <= det_settings.max_order})
        self._detector.orders = tuple(orders)

    def calibrate(self, image: np.ndarray) -> PlateCalibration:
        """Calibrate from the plate's markers in ``image`` and use the result (CalibrationError if
        too few markers are visible)."""
        gray = to_gray(check_frame(image, self.camera.width, self.camera.height, self.camera.encoding))
        cal = calibrate_plate_from_markers(gray, self.camera)
        self.set_calibration(cal)
        return cal

    # -- tracking ------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget every track (ids continue to increase)."""
        self._tracks.clear()
        self._last_stamp = None

    def update(self, image: np.ndarray, stamp_s: float) -> TrackResult:
        """Process one frame taken at ``stamp_s`` (s) and return every track's state.

        Raises BadFrameError (with ``reason``) for an empty, wrongly sized or encoded, dark or
        out-of-order frame; the tracker's state is then unchanged.
        """
        t0 = time.perf_counter()
        try:
            img = check_frame(image, self.camera.width, self.camera.height, self.camera.encoding)
            stamp = check_stamp(stamp_s, self._last_stamp)
            gray = to_gray(img)
            if self._detector is None:
                self.calibrate(gray if self.camera.encoding == "mono8" else img)
            assert self._detector is not None
            blobs = self._detector.detect(gray)
        except BadFrameError as exc:
            self.rejected[exc.reason] = self.rejected.get(exc.reason, 0) + 1
            raise
        dt = 0.0 if self._last_stamp is None else stamp - self._last_stamp
        self._last_stamp = stamp
        self._frames += 1
        for tr in self._tracks:
            if tr.status != TrackStatus.LOST:
                tr.filter.predict(dt)
        measurements, unexplained = self._classify(blobs)
        if self.settings.follow_plate:
            measurements = self._follow_plate(img, measurements)
        matched = self._associate(measurements)
        new_ids, reacquired = self._birth_and_reacquire(measurements, matched, stamp)
        lost, forgotten = self._coast(matched, unexplained, stamp)
        parts = tuple(
            self._report(tr, tr.id in reacquired) for tr in sorted(self._tracks, key=lambda t: t.id)
        )
        return TrackResult(
            stamp,
            self._frames - 1,
            parts,
            tuple(
                UnexplainedBlob(kind, float(b.centroid_m[0]), float(b.centroid_m[1]), b.area_m2)
                for kind, b in unexplained
            ),
            tuple(new_ids),
            tuple(lost),
            tuple(sorted(reacquired)),
            tuple(forgotten),
            time.perf_counter() - t0,
        )

    def _follow_plate(self, img: np.ndarray, measurements: list[_Measurement]) -> list[_Measurement]:
        """Poses in the moving plate's frame: undo the plate's shift measured from its markers."""
        assert self._calibration is not None
        shift = measure_plate_shift(img, self._calibration, self.camera.plate)
        if shift is None:
            self.plate_shift_misses += 1
            shift = self.plate_shift  # keep the last one (the motion rarely changes between frames)
        else:
            self.plate_shift = shift
        if shift is None or not measurements:
            return measurements
        xy, th = shift.to_plate(np.array([(m.fit.x_m, m.fit.y_m) for m in measurements]),
                                np.array([m.fit.theta_rad for m in measurements]))
        return [_Measurement(m.spec, replace(m.fit, x_m=float(p[0]), y_m=float(p[1]), theta_rad=float(t)),
                             m.blob) for m, p, t in zip(measurements, xy, th)]

    def _classify(self, blobs: list[Blob]) -> tuple[list[_Measurement], list[tuple[str, Blob]]]:
        s = self.settings
        cal = self._calibration
        assert cal is not None
        measurements, unexplained = [], []
        # Blobs are measured on the plate surface, where a raised top face looks larger.
        biggest = max(p.area_m2 / cal.height_scale(p.height_m) ** 2 for p in self.specs)
        for blob in blobs:
            # A blob cut by the work area's edge or mixed with a neighbour's edge is no
            # measurement of one part, whatever its shape.
            if blob.at_edge:
                unexplained.append(("edge", blob))
                continue
            best, best_score = None, math.inf
            for spec in self.specs:
                if abs(spec.area_ratio(blob, cal) - 1) > s.area_tolerance:
                    continue
                fit = spec.fit(blob, cal, s.shape_tolerance)
                if (
                    abs(fit.area_ratio - 1) <= s.area_tolerance
                    and fit.shape_distance <= s.shape_tolerance
                    and fit.moment_residual <= s.fit_tolerance
                ):
                    score = (
                        abs(fit.area_ratio - 1) / s.area_tolerance + fit.shape_distance / s.shape_tolerance
                    )
                    if score < best_score:
                        best, best_score = _Measurement(spec, fit, blob), score
            if best is not None and blob.crowded and (best.fit.shape_distance > 0.5 * s.shape_tolerance
                                                      or abs(best.fit.area_ratio - 1) > 0.5 * s.area_tolerance):
                best = None  # a neighbour took edge pixels: only a clean fit is still a measurement
            if best is not None:
                measurements.append(best)
            elif blob.crowded:
                unexplained.append(("touching", blob))
            elif blob.area_m2 > (1 + s.area_tolerance) * biggest:
                unexplained.append(("merged", blob))
            else:
                unexplained.append(("occluded", blob))
        return measurements, unexplained

    def _associate(self, measurements: list[_Measurement]) -> dict[int, int]:
        """Match active tracks to measurements; returns {track index: measurement index}."""
        s = self.settings
        active = [i for i, tr in enumerate(self._tracks) if tr.status != TrackStatus.LOST]
        if not active or not measurements:
            return {}
        pred = np.array([self._tracks[i].filter.position for i in active])
        sigma = np.array([self._tracks[i].filter.position_sigma_m() for i in active])
        gate = np.maximum(s.gate_m, s.gate_sigmas * sigma)
        meas = np.array([(m.fit.x_m, m.fit.y_m) for m in measurements])
        same = np.array([[m.spec is self._tracks[i].spec for m in measurements] for i in active])
        dist = np.hypot(pred[:, None, 0] - meas[None, :, 0], pred[:, None, 1] - meas[None, :, 1])
        cost = np.where(same & (dist <= gate[:, None]), dist, _FAR)
        rows, cols = linear_sum_assignment(cost)
        matched = {}
        for r, c in zip(rows, cols):
            if cost[r, c] < _FAR:
                matched[active[r]] = int(c)
        for i, c in matched.items():
            self._apply(self._tracks[i], measurements[c], self._last_stamp)
        return matched

    def _apply(self, tr: _Track, m: _Measurement, stamp: float | None) -> None:
        tr.filter.update(m.fit.x_m, m.fit.y_m, m.fit.theta_rad)
        tr.status, tr.reason = TrackStatus.TRACKED, ""
        tr.last_measured_s = float(stamp if stamp is not None else 0.0)
        x, y = tr.filter.position
        tr.last_pose = (x, y, tr.filter.theta)
        tr.last_cov = tr.filter.covariance()
        tr.last_vel = tr.filter.velocity

    def _birth_and_reacquire(
        self, measurements: list[_Measurement], matched: dict[int, int], stamp: float
    ) -> tuple[list[int], set[int]]:
        s = self.settings
        used = set(matched.values())
        free = [c for c in range(len(measurements)) if c not in used]
        waiting = [i for i, tr in enumerate(self._tracks) if i not in matched]
        reacquired: set[int] = set()
        # Re-acquisition is one-to-one and only when unambiguous: a detection with two candidate
        # tracks (or a track with two candidate detections) is a new part, never a guess.
        cand: dict[int, list[int]] = {c: [] for c in free}
        for c in free:
            m = measurements[c]
            for i in waiting:
                tr = self._tracks[i]
                if tr.spec is not m.spec:
                    continue
                x, y = tr.last_pose[:2] if tr.status == TrackStatus.LOST else tr.filter.position
                if math.hypot(m.fit.x_m - x, m.fit.y_m - y) <= s.reacquire_radius_m:
                    cand[c].append(i)
        per_track: dict[int, int] = {}
        for tracks in cand.values():
            for i in tracks:
                per_track[i] = per_track.get(i, 0) + 1
        for c, tracks in cand.items():
            if len(tracks) == 1 and per_track[tracks[0]] == 1:
                tr = self._tracks[tracks[0]]
                m = measurements[c]
                was_lost = tr.status == TrackStatus.LOST
                tr.filter = PoseFilter(m.fit.x_m, m.fit.y_m, m.fit.theta_rad, m.spec.symmetry_rad, s.filter)
                self._apply(tr, m, stamp)
                used.add(c)
                if was_lost:
                    reacquired.add(tr.id)
        new_ids = []
        for c in range(len(measurements)):
            if c in used:
                continue
            m = measurements[c]
            filt = PoseFilter(m.fit.x_m, m.fit.y_m, m.fit.theta_rad, m.spec.symmetry_rad, s.filter)
            tr = _Track(
                self._next_id,
                m.spec,
                filt,
                TrackStatus.TRACKED,
                "",
                stamp,
                (0.0, 0.0, 0.0),
                [],
                (0.0, 0.0, 0.0),
            )
            self._apply(tr, m, stamp)
            self._tracks.append(tr)
            new_ids.append(tr.id)
            self._next_id += 1
        return new_ids, reacquired

    def _coast(
        self, matched: dict[int, int], unexplained: list[tuple[str, Blob]], stamp: float
    ) -> tuple[list[int], list[int]]:
        s = self.settings
        lost, forgotten, keep = [], [], []
        x0, x1, y0, y1 = self.camera.plate.work_area_m
        for tr in self._tracks:
            if tr.status == TrackStatus.TRACKED and tr.last_measured_s == stamp:
                keep.append(tr)
                continue
            if tr.status == TrackStatus.LOST:
                if stamp - tr.last_measured_s > s.forget_after_s:
                    forgotten.append(tr.id)
                else:
                    keep.append(tr)
                continue
            px, py = tr.filter.position
            r = tr.spec.radius_m
            reason = "missed"
            for kind, blob in unexplained:
                if math.hypot(blob.centroid_m[0] - px, blob.centroid_m[1] - py) <= blob.extent_m + r:
                    reason = kind
                    break
            if reason == "missed" and not (x0 + r <= px <= x1 - r and y0 + r <= py <= y1 - r):
                reason = "out_of_view"
            tr.reason = reason
            if reason in ("merged", "touching"):
                tr.filter.hold()
            if stamp - tr.last_measured_s > s.max_coast_s:
                tr.status = TrackStatus.LOST
                lost.append(tr.id)
            else:
                tr.status = TrackStatus.PREDICTED
            keep.append(tr)
        self._tracks = keep
        return lost, forgotten

    def _report(self, tr: _Track, reacquired: bool) -> TrackedPart:
        sym = tr.spec.symmetry_rad
        if tr.status == TrackStatus.LOST:
            x, y, th = tr.last_pose
            cov, vel = tr.last_cov, tr.last_vel
        else:
            (x, y), th = tr.filter.position, tr.filter.theta
            cov, vel = tr.filter.covariance(), tr.filter.velocity
        return TrackedPart(
            tr.id,
            tr.spec.label,
            tr.status,
            tr.reason,
            float(x),
            float(y),
            wrap_angle(th, sym),
            np.array(cov, dtype=float),
            float(vel[0]),
            float(vel[1]),
            float(vel[2]),
            sym,
            tr.last_measured_s,
            reacquired,
        )

    # -- introspection -------------------------------------------------------------------------
    @property
    def frames_processed(self) -> int:
        return self._frames

    @property
    def detector(self) -> BlobDetector | None:
        return self._detector


__all__ = [
    "PartTracker",
    "TrackResult",
    "TrackStatus",
    "TrackedPart",
    "TrackerSettings",
    "UnexplainedBlob",
    "load_part_specs",
    "load_tracker_config",
]

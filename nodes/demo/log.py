"""What the demo watches while it runs: ground truth, tracked poses, motions, feedback.

ROS-facing on one side (subscriptions on a RosSession node), plain numpy data on the other, so the
figures (:mod:`ppod_nodes.demo.figures`) and the summary need no ROS. Times are on the device
clock (message stamps), in seconds.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np

from ppod_ros.motion import PlateMotion


@dataclass
class DemoLog:
    labels: list[str] = field(default_factory=list)            # scene parts, in scene order
    truth_t: list[float] = field(default_factory=list)
    truth_poses: list[np.ndarray] = field(default_factory=list)  # (N, 3) per sample
    tracked_t: list[float] = field(default_factory=list)
    tracked: list[dict[int, tuple[float, float, float]]] = field(default_factory=list)
    motions: list[tuple[float, PlateMotion | None]] = field(default_factory=list)  # (t, active motion)
    feedback: list[tuple[float, str, str, float]] = field(default_factory=list)  # (t, phase, text, err m)
    accel_errors: list[tuple[float, float, int]] = field(default_factory=list)  # (t, relative, iteration)
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    # ------------------------------------------------------------------ ROS callbacks
    def attach(self, node) -> None:
        """Subscribe ``node`` (a RosSession helper node) to what the demo shows."""
        from ppod_msgs.msg import PartPoseArray, PlateAcceleration
        from ppod_msgs.msg import PlateMotion as PlateMotionMsg

        from ppod_nodes.common import qos, topics

        node.create_subscription(PartPoseArray, topics.SIM_TRUE_POSES, self._on_truth, qos.STREAM)
        node.create_subscription(PartPoseArray, topics.PART_POSES, self._on_tracked, qos.STREAM)
        node.create_subscription(PlateMotionMsg, topics.ACTIVE_MOTION, self._on_motion, qos.LATCHED)
        node.create_subscription(PlateAcceleration, topics.ACCELERATION, self._on_accel, qos.STREAM)

    def _on_truth(self, msg) -> None:
        from ppod_nodes.common.convert import stamp_to_seconds

        poses = np.array([(p.pose.x, p.pose.y, p.pose.theta) for p in msg.parts], dtype=float)
        with self.lock:
            if not self.labels:
                self.labels = [p.label for p in msg.parts]
            self.truth_t.append(stamp_to_seconds(msg.header.stamp))
            self.truth_poses.append(poses)

    def _on_tracked(self, msg) -> None:
        from ppod_msgs.msg import PartPose

        from ppod_nodes.common.convert import stamp_to_seconds

        seen = {int(p.id): (p.pose.x, p.pose.y, p.pose.theta) for p in msg.parts
                if p.status == PartPose.STATUS_TRACKED}
        with self.lock:
            self.tracked_t.append(stamp_to_seconds(msg.header.stamp))
            self.tracked.append(seen)

    def _on_motion(self, msg) -> None:
        from ppod_nodes.common.convert import motion_from_msg, stamp_to_seconds

        try:
            motion = motion_from_msg(msg) if msg.harmonics else None  # None: the plate at rest
        except ValueError:
            return
        with self.lock:
            self.motions.append((stamp_to_seconds(msg.header.stamp), motion))

    def _on_accel(self, msg) -> None:
        from ppod_nodes.common.convert import stamp_to_seconds

        with self.lock:
            self.accel_errors.append((stamp_to_seconds(msg.header.stamp), float(msg.error_relative),
                                      int(msg.iteration)))

    def add_feedback(self, t_s: float, phase: str, text: str, error_m: float) -> None:
        with self.lock:
            self.feedback.append((t_s, phase, text, error_m))

    # ------------------------------------------------------------------ queries
    def latest_truth(self) -> tuple[float, np.ndarray] | None:
        with self.lock:
            return (self.truth_t[-1], self.truth_poses[-1]) if self.truth_t else None

    def latest_tracked(self) -> tuple[float, dict[int, tuple[float, float, float]]] | None:
        with self.lock:
            return (self.tracked_t[-1], self.tracked[-1]) if self.tracked_t else None

    def trajectories(self) -> tuple[np.ndarray, np.ndarray]:
        """Ground-truth times (T,) and poses (T, N, 3)."""
        with self.lock:
            n = len(self.labels)
            keep = [i for i, p in enumerate(self.truth_poses) if p.shape == (n, 3)]
            return np.array([self.truth_t[i] for i in keep]), np.array([self.truth_poses[i] for i in keep])

    def motion_at(self, t_s: float) -> PlateMotion | None:
        with self.lock:
            before = [m for t, m in self.motions if t <= t_s]
            return before[-1] if before else None

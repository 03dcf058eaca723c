"""The scene's inputs from ROS topics, shared by the viz node and ``ppod view``.

:class:`SceneState` subscribes ``node`` to the tracked parts, MovePart targets and the active
motion, computes the active motion's field in a thread (the solver takes a moment) and builds a
:class:`~ppod_ros.view.scene.Scene` on demand.
"""

from __future__ import annotations

import threading

from ppod_msgs.msg import PartPoseArray
from ppod_msgs.msg import PlateMotion as PlateMotionMsg

from ppod_nodes.common import qos, topics
from ppod_nodes.common.convert import motion_from_msg
from ppod_nodes.view.ros_drawables import scene_from_poses
from ppod_ros.errors import PpodError
from ppod_ros.view.scene import DEFAULT_ARROW_SCALE_S, DEFAULT_FIELD_GRID, PartDrawing, Scene, field_arrows


class SceneState:
    def __init__(self, node, plate_radius_m: float, field_grid: int = DEFAULT_FIELD_GRID, field_mu: float = 0.3,
                 arrow_scale_s: float = DEFAULT_ARROW_SCALE_S):
        self.node = node
        self.radius_m = plate_radius_m
        self.field_grid, self.field_mu, self.arrow_scale_s = field_grid, field_mu, arrow_scale_s
        self._poses = None
        self._targets: tuple[PartDrawing, ...] = ()
        self._arrows = ()
        self._motion_name = ""
        self._lock = threading.Lock()
        node.create_subscription(PartPoseArray, topics.PART_POSES, self._on_poses, qos.STREAM)
        node.create_subscription(PartPoseArray, topics.MOVE_PART_TARGET, self._on_targets, qos.LATCHED)
        node.create_subscription(PlateMotionMsg, topics.ACTIVE_MOTION, self._on_motion, qos.LATCHED)

    def _on_poses(self, msg) -> None:
        self._poses = msg

    def _on_targets(self, msg) -> None:
        self._targets = scene_from_poses(msg, self.radius_m).parts

    def _on_motion(self, msg) -> None:
        threading.Thread(target=self._compute_field, args=(msg,), daemon=True, name="scene-field").start()

    def _compute_field(self, msg) -> None:
        try:
            motion = motion_from_msg(msg)
            arrows = () if self.field_grid < 2 or motion.is_zero() else field_arrows(
                motion, self.radius_m, self.field_mu, self.field_grid)
        except (PpodError, ValueError) as exc:
            self.node.get_logger().warning(f"field of {msg.name!r} not drawn: {exc}")
            arrows = ()
        with self._lock:
            self._arrows, self._motion_name = arrows, msg.name

    def scene(self) -> Scene:
        with self._lock:
            arrows, name = self._arrows, self._motion_name
        return scene_from_poses(self._poses, self.radius_m, self._targets, arrows, self.arrow_scale_s, name)

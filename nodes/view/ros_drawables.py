"""A :class:`~ppod_ros.view.scene.Scene` from ROS messages, and as ROS drawables (MarkerArray, TF).

Markers live in the ``plate`` frame; the TF tree is ``plate -> camera`` (the camera's mounting pose).
Namespaces: ``plate`` (the working disc), ``parts`` (disc + heading arrow + label per track),
``goals`` (MovePart targets), ``field`` (velocity arrows, length = velocity x arrow_scale_s).
"""

from __future__ import annotations

import math

from geometry_msgs.msg import Point, TransformStamped
from ppod_msgs.msg import TFMessage
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from ppod_ros.view.scene import PartDrawing, Scene

PLATE_FRAME = "plate"
CAMERA_FRAME = "camera"
PART_DIAMETER_M = 0.02  # drawn size of a part whose outline is unknown
COLORS = {"plate": (0.6, 0.6, 0.65, 0.35), "parts": (0.1, 0.5, 0.9, 0.9), "lost": (0.6, 0.6, 0.6, 0.6),
          "goals": (0.1, 0.75, 0.2, 0.6), "field": (0.9, 0.4, 0.1, 0.9)}


def _color(name: str) -> ColorRGBA:
    r, g, b, a = COLORS[name]
    return ColorRGBA(r=r, g=g, b=b, a=a)


def scene_from_poses(poses_msg, plate_radius_m: float, goals: tuple[PartDrawing, ...] = (),
                     arrows=(), arrow_scale_s: float | None = None, motion_name: str = "") -> Scene:
    """The scene of a ppod_msgs/PartPoseArray (None: no parts yet)."""
    parts = () if poses_msg is None else tuple(
        PartDrawing(int(p.id), p.label, float(p.pose.x), float(p.pose.y), float(p.pose.theta),
                    tracked=p.status != p.STATUS_LOST) for p in poses_msg.parts)
    kw = {} if arrow_scale_s is None else {"arrow_scale_s": arrow_scale_s}
    return Scene(plate_radius_m, parts, tuple(goals), tuple(arrows), motion_name=motion_name, **kw)


def _marker(ns: str, mid: int, kind: int, stamp, color: str) -> Marker:
    m = Marker(ns=ns, id=mid, type=kind, action=Marker.ADD)
    m.header.frame_id = PLATE_FRAME
    m.header.stamp = stamp
    m.pose.orientation.w = 1.0
    m.color = _color(color)
    return m


def _yaw(m: Marker, theta: float) -> None:
    m.pose.orientation.z, m.pose.orientation.w = math.sin(theta / 2), math.cos(theta / 2)


def scene_markers(scene: Scene, stamp) -> MarkerArray:
    """Every drawable of ``scene`` as one MarkerArray (a DELETEALL first, so stale ids vanish)."""
    out = [Marker(action=Marker.DELETEALL)]
    out[0].header.frame_id = PLATE_FRAME
    disc = _marker("plate", 0, Marker.CYLINDER, stamp, "plate")
    disc.scale.x = disc.scale.y = 2 * scene.plate_radius_m
    disc.scale.z = 0.002
    disc.pose.position.z = -0.001
    out.append(disc)
    for group, items in (("parts", scene.parts), ("goals", scene.goals)):
        for p in items:
            color = group if (group == "goals" or p.tracked) else "lost"
            body = _marker(group, 3 * p.id, Marker.CYLINDER, stamp, color)
            body.pose.position.x, body.pose.position.y = p.x, p.y
            body.scale.x = body.scale.y = PART_DIAMETER_M
            body.scale.z = 0.004
            heading = _marker(group, 3 * p.id + 1, Marker.ARROW, stamp, color)
            heading.pose.position.x, heading.pose.position.y, heading.pose.position.z = p.x, p.y, 0.004
            _yaw(heading, p.theta)
            heading.scale.x, heading.scale.y, heading.scale.z = PART_DIAMETER_M, 0.002, 0.002
            label = _marker(group, 3 * p.id + 2, Marker.TEXT_VIEW_FACING, stamp, color)
            label.pose.position.x, label.pose.position.y, label.pose.position.z = p.x, p.y, 0.015
            label.scale.z = 0.008
            label.text = f"{'goal ' if group == 'goals' else ''}{p.id} {p.label}".strip()
            out += [body, heading, label]
    for i, a in enumerate(scene.arrows):
        arrow = _marker("field", i, Marker.ARROW, stamp, "field")
        arrow.points = [Point(x=a.x, y=a.y, z=0.001),
                        Point(x=a.x + a.vx * scene.arrow_scale_s, y=a.y + a.vy * scene.arrow_scale_s, z=0.001)]
        arrow.scale.x, arrow.scale.y, arrow.scale.z = 0.0015, 0.004, 0.004
        out.append(arrow)
    return MarkerArray(markers=out)


def camera_tf(translation, rotation, stamp) -> TFMessage:
    """plate -> camera as a TFMessage (recorded as tf2_msgs/msg/TFMessage)."""
    t = TransformStamped()
    t.header.frame_id, t.header.stamp, t.child_frame_id = PLATE_FRAME, stamp, CAMERA_FRAME
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = translation
    q = t.transform.rotation
    q.x, q.y, q.z, q.w = rotation
    return TFMessage(transforms=[t])

"""A :class:`~ppod_ros.view.scene.Scene` as Foxglove's own schemas (SceneUpdate, FrameTransform)."""

from __future__ import annotations

import math

from foxglove import messages as fm

from ppod_ros.view.scene import Scene

PLATE_FRAME = "plate"
CAMERA_FRAME = "camera"
PART_DIAMETER_M = 0.02


def _pose(x=0.0, y=0.0, z=0.0, yaw=0.0) -> fm.Pose:
    return fm.Pose(position=fm.Vector3(x=x, y=y, z=z),
                   orientation=fm.Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)))


def _color(r, g, b, a) -> fm.Color:
    return fm.Color(r=r, g=g, b=b, a=a)


def scene_update(scene: Scene) -> fm.SceneUpdate:
    """Entities ``plate``, ``part/<id>``, ``goal/<id>`` and ``field``, all in the plate frame."""
    entities = [fm.SceneEntity(frame_id=PLATE_FRAME, id="plate", cylinders=[fm.CylinderPrimitive(
        pose=_pose(z=-0.001), size=fm.Vector3(x=2 * scene.plate_radius_m, y=2 * scene.plate_radius_m, z=0.002),
        bottom_scale=1.0, top_scale=1.0, color=_color(0.6, 0.6, 0.65, 0.35))])]
    groups = (("part", scene.parts, (0.1, 0.5, 0.9, 0.9)), ("goal", scene.goals, (0.1, 0.75, 0.2, 0.6)))
    for kind, items, color in groups:
        for p in items:
            c = _color(*color) if p.tracked else _color(0.6, 0.6, 0.6, 0.6)
            entities.append(fm.SceneEntity(
                frame_id=PLATE_FRAME, id=f"{kind}/{p.id}",
                cylinders=[fm.CylinderPrimitive(pose=_pose(p.x, p.y, 0.002), size=fm.Vector3(
                    x=PART_DIAMETER_M, y=PART_DIAMETER_M, z=0.004), bottom_scale=1.0, top_scale=1.0, color=c)],
                arrows=[fm.ArrowPrimitive(pose=_pose(p.x, p.y, 0.004, p.theta), shaft_length=0.014,
                                          shaft_diameter=0.002, head_length=0.006, head_diameter=0.005, color=c)],
                texts=[fm.TextPrimitive(pose=_pose(p.x, p.y, 0.015), billboard=True, font_size=12.0,
                                        scale_invariant=True, color=c, text=f"{kind} {p.id} {p.label}".strip())]))
    arrows = []
    for a in scene.arrows:
        speed = math.hypot(a.vx, a.vy)
        length = speed * scene.arrow_scale_s
        if length <= 0:
            continue
        arrows.append(fm.ArrowPrimitive(pose=_pose(a.x, a.y, 0.001, math.atan2(a.vy, a.vx)),
                                        shaft_length=0.75 * length, shaft_diameter=0.0015,
                                        head_length=0.25 * length, head_diameter=0.004,
                                        color=_color(0.9, 0.4, 0.1, 0.9)))
    entities.append(fm.SceneEntity(frame_id=PLATE_FRAME, id="field", arrows=arrows,
                                   metadata=[fm.KeyValuePair(key="motion", value=scene.motion_name),
                                             fm.KeyValuePair(key="arrow_scale_s", value=f"{scene.arrow_scale_s:g}")]))
    return fm.SceneUpdate(entities=entities)


def camera_frame_transform(translation, rotation) -> fm.FrameTransform:
    x, y, z = translation
    qx, qy, qz, qw = rotation
    return fm.FrameTransform(parent_frame_id=PLATE_FRAME, child_frame_id=CAMERA_FRAME,
                             translation=fm.Vector3(x=x, y=y, z=z),
                             rotation=fm.Quaternion(x=qx, y=qy, z=qz, w=qw))

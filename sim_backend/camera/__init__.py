"""The simulated overhead camera (no ROS): renders the plate, fiducials and parts with ground truth.

See :mod:`ppod_sim.camera.renderer` for the image formation model and docs/vision.md for its use.
"""

from ppod_sim.camera.renderer import CameraRenderer, board_pose_flat, tilted_board_pose
from ppod_sim.camera.scene import (
    Lighting,
    Occluder,
    PartTruth,
    RenderedFrame,
    RenderPart,
    SceneStyle,
    SensorModel,
)
from ppod_sim.camera.trigger import TriggeredCamera, frame_times_s, trigger_time_s

__all__ = [
    "CameraRenderer",
    "Lighting",
    "Occluder",
    "PartTruth",
    "RenderPart",
    "RenderedFrame",
    "SceneStyle",
    "SensorModel",
    "TriggeredCamera",
    "board_pose_flat",
    "frame_times_s",
    "tilted_board_pose",
    "trigger_time_s",
]

"""What the live view and the drawable topics show, ROS-free: :mod:`ppod_ros.view.scene`."""

from ppod_ros.view.scene import Arrow, PartDrawing, Scene, camera_transform, field_arrows, quaternion_from_matrix

__all__ = ["Arrow", "PartDrawing", "Scene", "camera_transform", "field_arrows", "quaternion_from_matrix"]

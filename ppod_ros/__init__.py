"""ppod_ros: the ROS-free core of the PPOD control stack.

Physics (plate motion, point and rigid parts, asymptotic solver, full dynamics), kinematics,
actuation, the CAN protocol, estimation, control, vision and planning. Nothing in this package
imports rclpy or ROS message types: it is importable and testable without ROS.
"""

from ppod_ros.errors import ConfigError, DeviceError, LimitError, PpodError, ProtocolError, SolverError
from ppod_ros.motion import PlateMotion

__version__ = "0.1.0"

__all__ = [
    "ConfigError",
    "DeviceError",
    "LimitError",
    "PlateMotion",
    "PpodError",
    "ProtocolError",
    "SolverError",
    "__version__",
]

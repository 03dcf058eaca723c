"""Standard ROS 2 launch file for labs with a full ROS 2 Jazzy installation (ros2 launch).

    ros2 launch config/launch/ppod.launch.py sim:=true
    ros2 launch config/launch/ppod.launch.py config:=/path/to/ppod_up.yaml

A thin wrapper: :func:`ppod_nodes.launch.ros_launch.launch_entries` reads the same launch
configuration as ``ppod up`` (nodes/data/ppod_up.yaml by default), fills in every placeholder the
same way and writes each node's parameter file; here each entry becomes a managed ``LifecycleNode``
(or a plain ``Node`` for the simulated device) running the node's console script, e.g.
``ppod-waveform-generator``. Lifecycle nodes get ``autostart: true`` and bring themselves to active.
On machines with ROS from PyPI wheels (no ``launch`` package) use ``ppod up`` instead.
"""

import os

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction, SetEnvironmentVariable
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node

from ppod_nodes.launch.ros_launch import ROS_PACKAGE, launch_entries
from ppod_nodes.launch.spec import load_launch_spec


def _package_or_none():
    """ros2 run's package when installed in an ament workspace; else the scripts are on PATH."""
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_prefix
    except ImportError:
        return None
    try:
        get_package_prefix(ROS_PACKAGE)
    except (PackageNotFoundError, OSError):  # OSError: no AMENT_PREFIX_PATH (no sourced workspace)
        return None
    return ROS_PACKAGE


def _nodes(context):
    config = LaunchConfiguration("config").perform(context) or None
    sim = LaunchConfiguration("sim").perform(context).lower() in ("1", "true", "yes")
    spec = load_launch_spec(config)
    package = _package_or_none()
    actions = [SetEnvironmentVariable("ROS_AUTOMATIC_DISCOVERY_RANGE",
                                      os.environ.get("PPOD_DISCOVERY_RANGE", spec.discovery_range))]
    for entry in launch_entries(sim=sim, spec=spec):
        kind = LifecycleNode if entry.lifecycle else Node
        actions.append(kind(package=package, executable=entry.executable, name=entry.name, namespace="",
                            parameters=[entry.params_file], output="screen", prefix=entry.prefix or None,
                            additional_env=entry.env or None))
    return actions


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument("sim", default_value="false", description="start the simulated device"),
        DeclareLaunchArgument("config", default_value="", description="launch configuration YAML"),
        OpaqueFunction(function=_nodes),
    ])

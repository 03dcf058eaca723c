"""Standard ROS 2 launch file for labs with a full ROS 2 Jazzy installation (ros2 launch).

    ros2 launch config/launch/ppod.launch.py sim:=true
    ros2 launch config/launch/ppod.launch.py config:=/path/to/ppod_up.yaml

It reads the same launch configuration as ``ppod up`` (nodes/data/ppod_up.yaml by default), so the
two never disagree, and starts each node as ``python -m MODULE`` with its parameters; lifecycle nodes
get ``autostart:=true`` and bring themselves to active. On machines with ROS from PyPI wheels (no
``launch`` package) use ``ppod up`` instead.
"""

import os
import sys
import tempfile

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess, OpaqueFunction, SetEnvironmentVariable
from launch.substitutions import LaunchConfiguration

from ppod_nodes.common.params import params_file_text
from ppod_nodes.launch.spec import load_launch_spec


def _nodes(context):
    config = LaunchConfiguration("config").perform(context) or None
    sim = LaunchConfiguration("sim").perform(context).lower() in ("1", "true", "yes")
    spec = load_launch_spec(config)
    tmp = tempfile.mkdtemp(prefix="ppod-launch-")
    actions = [SetEnvironmentVariable("ROS_AUTOMATIC_DISCOVERY_RANGE",
                                      os.environ.get("PPOD_DISCOVERY_RANGE", spec.discovery_range))]
    for node in spec.selected(sim):
        params = node.parameters(sim)
        if node.lifecycle:
            params = {**params, "autostart": True}
        path = os.path.join(tmp, f"{node.name}.yaml")
        with open(path, "w") as f:
            f.write(params_file_text(node.name, params))
        cmd = [sys.executable, "-m", node.module, *node.args, "--ros-args", "-r", f"__node:={node.name}",
               "--params-file", path]
        if node.nice:
            cmd = ["nice", "-n", str(node.nice), *cmd]  # as ppod up: the simulator yields to the host nodes
        actions.append(ExecuteProcess(cmd=cmd, name=node.name, output="screen", sigterm_timeout="10",
                                      sigkill_timeout="5"))
    return actions


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument("sim", default_value="false", description="start the simulated device"),
        DeclareLaunchArgument("config", default_value="", description="launch configuration YAML"),
        OpaqueFunction(function=_nodes),
    ])

"""The ROS 2 launch file's node list: every placeholder filled, managed nodes, one script per node."""

import re
import sys
import types
from pathlib import Path

import pytest
import yaml

from ppod_nodes.launch.ros_launch import launch_entries, leftover_placeholders
from ppod_ros.errors import ConfigError

PLACEHOLDER = re.compile(r"\{[A-Za-z_]\w*\}")


@pytest.mark.parametrize("sim", [True, False])
def test_launch_entries_leave_no_placeholder_unfilled(sim, tmp_path):
    entries = launch_entries(sim=sim, out_dir=tmp_path, substitutions={"sim_port": 54321, "data": "/d"})
    assert entries
    for e in entries:
        written = yaml.safe_load(Path(e.params_file).read_text())
        params = written[e.name]["ros__parameters"]
        assert leftover_placeholders(params) == []
        assert not PLACEHOLDER.search(Path(e.params_file).read_text())
        if e.lifecycle:
            assert params["autostart"] is True
    if sim:
        by_name = {e.name: e for e in entries}
        assert by_name["sim_device"].parameters["port"] == 54321
        assert by_name["waveform_generator"].parameters["can_channel"] == "ws://127.0.0.1:54321/"
        # The generator asks for real-time scheduling (its heartbeats); the simulated device yields to
        # the host's nodes (nodes/data/ppod_up.yaml).
        assert by_name["sim_device"].prefix == "nice -n 5"
        assert by_name["sim_device"].env == {}
        assert by_name["waveform_generator"].env == {"PPOD_REALTIME_PRIORITY": "10", "OPENBLAS_NUM_THREADS": "1"}


def test_an_unknown_placeholder_is_a_one_line_config_error(tmp_path):
    config = tmp_path / "up.yaml"
    config.write_text("nodes:\n  - name: field_planner\n    module: ppod_nodes.field_planner\n"
                      "    params: {device_config: '{nowhere}/device.yaml'}\n")
    with pytest.raises(ConfigError, match=r"field_planner.*\{nowhere\}"):
        launch_entries(config, out_dir=tmp_path / "p")


def test_the_launch_file_starts_managed_nodes_with_the_console_scripts(tmp_path, monkeypatch):
    """Loads config/launch/ppod.launch.py against stand-ins of launch/launch_ros (no wheels here)."""
    made = []

    class Action:
        def __init__(self, *args, **kwargs):
            self.args, self.kwargs = args, kwargs
            made.append(self)

    class LifecycleNode(Action):
        pass

    class Node(Action):
        pass

    class LaunchConfiguration:
        def __init__(self, name):
            self.name = name

        def perform(self, context):
            return context[self.name]

    stubs = {
        "launch": types.SimpleNamespace(LaunchDescription=lambda actions: actions),
        "launch.actions": types.SimpleNamespace(DeclareLaunchArgument=Action, OpaqueFunction=Action,
                                                SetEnvironmentVariable=Action),
        "launch.substitutions": types.SimpleNamespace(LaunchConfiguration=LaunchConfiguration),
        "launch_ros": types.SimpleNamespace(),
        "launch_ros.actions": types.SimpleNamespace(LifecycleNode=LifecycleNode, Node=Node),
    }
    for name, module in stubs.items():
        monkeypatch.setitem(sys.modules, name, module)
    import importlib.util

    path = Path(__file__).parents[2] / "config" / "launch" / "ppod.launch.py"
    spec = importlib.util.spec_from_file_location("ppod_launch_under_test", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    opaque = [a for a in description if "function" in a.kwargs][0]
    actions = opaque.kwargs["function"]({"sim": "true", "config": ""})
    nodes = [a for a in actions if isinstance(a, (LifecycleNode, Node))]
    assert [type(n).__name__ for n in nodes] == ["Node"] + ["LifecycleNode"] * 4 + ["Node"]
    envs = {n.kwargs["name"]: n.kwargs["additional_env"] for n in nodes}
    assert envs["waveform_generator"] == {"PPOD_REALTIME_PRIORITY": "10", "OPENBLAS_NUM_THREADS": "1"}
    assert all(env is None for name, env in envs.items() if name != "waveform_generator")
    for n in nodes:
        assert n.kwargs["executable"].startswith("ppod-")
        params_file = n.kwargs["parameters"][0]
        assert not PLACEHOLDER.search(Path(params_file).read_text())

"""What ``ros2 launch config/launch/ppod.launch.py`` starts, built without the ``launch`` package.

There are no ``launch``/``launch_ros`` wheels, so the launch file stays a thin wrapper: this module
reads the same launch configuration as ``ppod up`` (nodes/data/ppod_up.yaml), fills in every
placeholder the same way (``{sim_port}``, ``{data}``), writes one parameter file per node and returns
the entries the launch file turns into ``LifecycleNode``/``Node`` actions. It is importable and
testable anywhere::

    entries = launch_entries(sim=True, out_dir=tmp)
    entries[1].executable      # 'ppod-waveform-generator' (console script; ros2 run ppod_control ...)
    entries[1].params_file     # tmp/waveform_generator.yaml, autostart: true for lifecycle nodes
"""

from __future__ import annotations

import re
import socket
import sys
import tempfile
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from ppod_nodes.common.params import params_file_text
from ppod_nodes.launch.spec import LaunchSpec, load_launch_spec
from ppod_ros.errors import ConfigError

#: The ROS package the console scripts are installed under (package.xml, setup.cfg).
ROS_PACKAGE = "ppod_control"

#: Node module -> its console script (pyproject.toml [project.scripts]); one script per node.
EXECUTABLES: dict[str, str] = {
    "ppod_sim.ros_node": "ppod-sim-device",
    "ppod_nodes.waveform_generator": "ppod-waveform-generator",
    "ppod_nodes.accel_feedback": "ppod-accel-feedback",
    "ppod_nodes.part_tracker": "ppod-part-tracker",
    "ppod_nodes.field_planner": "ppod-field-planner",
    "ppod_nodes.viz": "ppod-viz",
}

_PLACEHOLDER = re.compile(r"\{[A-Za-z_][A-Za-z0-9_]*\}")


@dataclass(frozen=True)
class LaunchEntry:
    """One node as the launch file starts it."""

    name: str
    module: str
    executable: str
    lifecycle: bool
    parameters: dict[str, Any]
    params_file: str
    #: ``python -m MODULE ...``: the same process without an installed console script.
    cmd: tuple[str, ...]
    nice: int = 0
    #: Environment the launch action adds (``PPOD_REALTIME_PRIORITY``, as ``ppod up`` sets it).
    env: dict[str, str] = field(default_factory=dict)

    @property
    def prefix(self) -> str:
        """Command prefix for the launch action (``nice -n N``, as ``ppod up`` does)."""
        return f"nice -n {self.nice}" if self.nice else ""


def free_port() -> int:
    """A TCP port on 127.0.0.1 that is free now (for the simulator's CAN bridge)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def launch_substitutions(sim_port: int | None = None) -> dict[str, Any]:
    """The placeholders of a launch configuration and their values (shared with ``ppod up``)."""
    return {"sim_port": free_port() if sim_port is None else int(sim_port),
            "data": str(resources.files("ppod_ros") / "data")}


def leftover_placeholders(value: Any, path: str = "") -> list[str]:
    """Every ``{name}`` still inside ``value`` (nested dicts and lists), as ``path: text``."""
    if isinstance(value, dict):
        return [hit for k, v in value.items() for hit in leftover_placeholders(v, f"{path}.{k}" if path else k)]
    if isinstance(value, list):
        return [hit for i, v in enumerate(value) for hit in leftover_placeholders(v, f"{path}[{i}]")]
    if isinstance(value, str) and _PLACEHOLDER.search(value):
        return [f"{path}: {value}"]
    return []


def launch_entries(config: str | Path | None = None, sim: bool = False, out_dir: str | Path | None = None,
                   substitutions: dict[str, Any] | None = None,
                   spec: LaunchSpec | None = None) -> list[LaunchEntry]:
    """The nodes to start, in order, with their parameter files written to ``out_dir``.

    Lifecycle nodes get ``autostart: true`` (they configure and activate themselves, as no
    launcher drives their transitions). Raises ConfigError naming any placeholder left unfilled.
    """
    spec = spec or load_launch_spec(config)
    subs = launch_substitutions() if substitutions is None else substitutions
    out = Path(out_dir) if out_dir is not None else Path(tempfile.mkdtemp(prefix="ppod-launch-"))
    out.mkdir(parents=True, exist_ok=True)
    entries = []
    for node in spec.selected(sim):
        params = node.parameters(sim, subs)
        if node.lifecycle:
            params = {**params, "autostart": True}
        left = leftover_placeholders(params)
        if left:
            raise ConfigError(f"{spec.origin}: node {node.name}: unfilled placeholder(s) "
                              f"{'; '.join(left)} (known: {', '.join('{' + k + '}' for k in subs)})")
        path = out / f"{node.name}.yaml"
        path.write_text(params_file_text(node.name, params))
        cmd = (sys.executable, "-m", node.module, *node.args, "--ros-args", "-r", f"__node:={node.name}",
               "--params-file", str(path))
        executable = EXECUTABLES.get(node.module)
        if executable is None:
            raise ConfigError(f"{spec.origin}: node {node.name}: module {node.module} has no console script "
                              f"(known: {', '.join(sorted(EXECUTABLES))})")
        entries.append(LaunchEntry(node.name, node.module, executable, node.lifecycle, params, str(path), cmd,
                                   node.nice, dict(node.env)))
    return entries

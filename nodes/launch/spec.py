"""What ``ppod up`` starts: the launch configuration (YAML), validated strictly.

Example (the packaged default is ``nodes/data/ppod_up.yaml``)::

    discovery_range: LOCALHOST      # SUBNET for a lab network (DDS leaves loopback)
    domain_id: null                 # null: inherit ROS_DOMAIN_ID
    shutdown_timeout_s: 10
    nodes:
      - name: waveform_generator
        module: ppod_nodes.waveform_generator   # started as `python -m MODULE --ros-args ...`
        lifecycle: true                          # the launcher configures and activates it
        params: {heartbeat_period_s: 0.05}       # node parameters (nested keys allowed)
        sim_params: {can_channel: "ws://127.0.0.1:{sim_port}/"}  # merged over params with --sim;
                                                 # {sim_port}: a free port the launcher picks,
                                                 # {data}: the packaged data folder (ppod_ros/data)
        hardware_params: {can_interface: socketcan}  # merged over params without --sim
        when: always                              # always | sim | hardware
        required: true                            # its death stops everything (default true)
        ready: "CAN bridge on"                    # non-lifecycle nodes: a log line (regex) that says
                                                  # it is up; later nodes wait for it

Nodes start in list order and stop in reverse order.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from ppod_nodes.ros_env import REALTIME_ENV
from ppod_ros.config.fields import Fields, load_yaml_file
from ppod_ros.errors import ConfigError


@dataclass(frozen=True)
class NodeSpec:
    name: str
    module: str
    lifecycle: bool = True
    params: dict[str, Any] = field(default_factory=dict)
    sim_params: dict[str, Any] = field(default_factory=dict)
    hardware_params: dict[str, Any] = field(default_factory=dict)
    when: str = "always"
    required: bool = True
    args: tuple[str, ...] = ()
    ready: str = ""
    #: Niceness added to the child process (0..19): a simulated device yields the CPU to the host's
    #: nodes, since a starved simulator only slows its own clock while a starved host misses heartbeats.
    nice: int = 0
    #: SCHED_FIFO priority asked for the child (1-99; 0: normal scheduling), through
    #: ``PPOD_REALTIME_PRIORITY`` (nodes/common/runner.py): the waveform generator's, whose heartbeat
    #: thread must get the GIL within the device's watchdog on a loaded machine. Not granted (no
    #: CAP_SYS_NICE or rtprio limit): the node runs at normal priority and logs it. Such a node's
    #: BLAS runs on the calling thread (``OPENBLAS_NUM_THREADS=1``): its worker threads start at
    #: import, before the process takes its priority, and a goal check waiting for one at normal
    #: priority on a busy machine held the process up to 376 ms (the watchdog tripped).
    realtime_priority: int = 0

    @property
    def env(self) -> dict[str, str]:
        """Environment the child gets on top of the launcher's."""
        if not self.realtime_priority:
            return {}
        return {REALTIME_ENV: str(self.realtime_priority), "OPENBLAS_NUM_THREADS": "1"}

    def enabled(self, sim: bool) -> bool:
        return self.when == "always" or (self.when == "sim") == sim

    def parameters(self, sim: bool, substitutions: dict[str, Any] | None = None) -> dict[str, Any]:
        """The node's parameters for this mode, with ``{name}`` placeholders filled in.

        A value that is exactly ``"{name}"`` takes the substitution's own type (``port: "{sim_port}"``
        becomes an integer); placeholders inside longer strings are formatted in.
        """
        merged = deep_merge(self.params, self.sim_params if sim else self.hardware_params)
        return _substitute(merged, substitutions or {})


@dataclass(frozen=True)
class LaunchSpec:
    nodes: tuple[NodeSpec, ...]
    discovery_range: str = "LOCALHOST"
    domain_id: int | None = None
    shutdown_timeout_s: float = 10.0
    lifecycle_timeout_s: float = 30.0
    origin: str = ""

    def selected(self, sim: bool, only: list[str] | None = None) -> list[NodeSpec]:
        nodes = [n for n in self.nodes if n.enabled(sim)]
        if only:
            unknown = sorted(set(only) - {n.name for n in self.nodes})
            if unknown:
                raise ConfigError(f"--only: no node named {', '.join(unknown)} in {self.origin}")
            nodes = [n for n in nodes if n.name in only]
        return nodes


def _substitute(value: Any, subs: dict[str, Any]) -> Any:
    if isinstance(value, dict):
        return {k: _substitute(v, subs) for k, v in value.items()}
    if isinstance(value, list):
        return [_substitute(v, subs) for v in value]
    if isinstance(value, str) and "{" in value:
        for name, sub in subs.items():
            if value == "{" + name + "}":
                return sub
            value = value.replace("{" + name + "}", str(sub))
    return value


def deep_merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        out[k] = deep_merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _mapping(f: Fields, key: str) -> dict[str, Any]:
    value = f.raw(key, {})
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise ConfigError(f"{f.key_path(key)}: expected a mapping of parameter names to values")
    return dict(value)


def launch_spec_from_dict(data: dict[str, Any], origin: str = "launch config") -> LaunchSpec:
    f = Fields(data, "")
    discovery = f.string("discovery_range", "LOCALHOST", choices=("LOCALHOST", "SUBNET", "OFF", "SYSTEM_DEFAULT"))
    domain = f.raw("domain_id", None)
    if domain is not None:
        domain = f.integer("domain_id", min_value=0, max_value=232)
    shutdown_s = f.number("shutdown_timeout_s", 10.0, min_value=0.5, unit="s")
    lifecycle_s = f.number("lifecycle_timeout_s", 30.0, min_value=1.0, unit="s")
    nodes = []
    for item in f.items("nodes"):
        name = item.string("name")
        if not name.isidentifier():
            raise ConfigError(f"{item.key_path('name')}: must be a valid ROS node name, got {name!r}")
        args = item.raw("args", [])
        if not isinstance(args, list) or not all(isinstance(a, str) for a in args):
            raise ConfigError(f"{item.key_path('args')}: expected a list of strings")
        spec = NodeSpec(
            name=name,
            module=item.string("module"),
            lifecycle=item.boolean("lifecycle", True),
            params=_mapping(item, "params"),
            sim_params=_mapping(item, "sim_params"),
            hardware_params=_mapping(item, "hardware_params"),
            when=item.string("when", "always", choices=("always", "sim", "hardware")),
            required=item.boolean("required", True),
            args=tuple(args),
            ready=item.string("ready", ""),
            nice=item.integer("nice", 0, min_value=0, max_value=19),
            realtime_priority=item.integer("realtime_priority", 0, min_value=0, max_value=99),
        )
        if spec.ready:
            try:
                re.compile(spec.ready)
            except re.error as exc:
                raise ConfigError(f"{item.key_path('ready')}: not a valid regular expression: {exc}") from exc
        item.finish()
        nodes.append(spec)
    names = [n.name for n in nodes]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise ConfigError(f"nodes: names must be unique, repeated: {', '.join(dupes)}")
    f.finish()
    return LaunchSpec(tuple(nodes), discovery, domain, shutdown_s, lifecycle_s, origin)


def load_launch_spec(path: str | Path | None = None) -> LaunchSpec:
    """Load a launch configuration; None loads the packaged default."""
    if path is None:
        ref = resources.files("ppod_nodes") / "data" / "ppod_up.yaml"
        with resources.as_file(ref) as p:
            data = load_yaml_file(p, "launch config")
            origin = str(p)
    else:
        data = load_yaml_file(path, "launch config")
        origin = str(path)
    try:
        return launch_spec_from_dict(dict(data), origin)
    except ConfigError as exc:
        raise ConfigError(f"{origin}: {exc}") from exc

"""Helpers for system tests: run ``ppod up --sim`` stacks with a test configuration, in process."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import yaml

from ppod_nodes.launch.spec import launch_spec_from_dict
from ppod_nodes.launch.stack import Stack

# As nodes/data/ppod_up.yaml: the simulated device niced (it takes no CPU from the host's nodes; on a
# machine that cannot run both its clock slows), the generator under SCHED_FIFO 10 where granted (its
# heartbeats on a loaded machine; a CI run tripped the device's watchdog with 157 ms between two of them).
SIM = {"name": "sim_device", "module": "ppod_sim.ros_node", "lifecycle": False, "when": "sim", "nice": 5,
       "ready": "CAN bridge on", "params": {"port": "{sim_port}", "camera": False, "mismatch": "default"}}
GENERATOR = {"name": "waveform_generator", "module": "ppod_nodes.waveform_generator", "realtime_priority": 10,
             "sim_params": {"can_interface": "remote", "can_channel": "ws://127.0.0.1:{sim_port}/",
                            "use_sim_time": True}}
FEEDBACK = {"name": "accel_feedback", "module": "ppod_nodes.accel_feedback",
            "sim_params": {"can_interface": "remote", "can_channel": "ws://127.0.0.1:{sim_port}/",
                           "use_sim_time": True}}


def node(base: dict, **params) -> dict:
    out = {**base, "params": {**base.get("params", {}), **params}}
    return out


@contextlib.contextmanager
def running_stack(tmp_path: Path, nodes: list[dict], **spec_extra):
    """Start the given nodes against the simulated device; yields the Stack; stops it on exit."""
    data = {"shutdown_timeout_s": 10, "lifecycle_timeout_s": 90, "nodes": nodes, **spec_extra}
    (tmp_path / "stack.yaml").write_text(yaml.safe_dump(data))
    spec = launch_spec_from_dict(data, str(tmp_path / "stack.yaml"))
    log = open(tmp_path / "stack.log", "w")  # noqa: SIM115 - closed below
    stack = Stack(spec, sim=True, out=log, handle_signals=False)
    try:
        stack.start()
        yield stack
    finally:
        stack.stop()
        log.close()


def log_text(tmp_path: Path) -> str:
    return (tmp_path / "stack.log").read_text()


def hardware_config() -> str | None:
    """The device description given with ``pytest --hardware CONFIG``, or None (simulated device)."""
    return os.environ.get("PPOD_TEST_HARDWARE_CONFIG") or None


@contextlib.contextmanager
def device_stack(tmp_path: Path, nodes: list[dict], **spec_extra):
    """:func:`running_stack` against the simulated device, or the real one with ``--hardware CONFIG``.

    ``nodes`` are the host nodes (GENERATOR, FEEDBACK, ...); the simulator is added here when no
    hardware is given. On hardware, each node gets ``device_config: CONFIG`` and no sim parameters.
    """
    config = hardware_config()
    if config is None:
        with running_stack(tmp_path, [SIM, *nodes], **spec_extra) as stack:
            yield stack
        return
    hw_nodes = [{**n, "params": {**n.get("params", {}), "device_config": config}} for n in nodes]
    data = {"shutdown_timeout_s": 10, "lifecycle_timeout_s": 90, "nodes": hw_nodes, **spec_extra}
    (tmp_path / "stack.yaml").write_text(yaml.safe_dump(data))
    spec = launch_spec_from_dict(data, str(tmp_path / "stack.yaml"))
    with open(tmp_path / "stack.log", "w") as log:
        stack = Stack(spec, sim=False, out=log, handle_signals=False)
        try:
            stack.start()
            yield stack
        finally:
            stack.stop()

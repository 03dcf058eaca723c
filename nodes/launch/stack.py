"""Bring the whole stack up and down: processes, lifecycle transitions, ordered shutdown.

Used by ``ppod up``, ``ppod demo`` and the system tests::

    with Stack(load_launch_spec(), sim=True) as stack:
        stack.start()               # spawn, configure and activate, in list order
        stack.wait(duration_s=10)   # until Ctrl-C, SIGTERM, the duration, or a required node dies
    # leaving the block stops every node in reverse order and reaps every process
"""

from __future__ import annotations

import os
import re
import signal
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import IO

from ppod_nodes.launch import runfile
from ppod_nodes.launch.ros_launch import free_port, launch_substitutions  # noqa: F401 - free_port re-exported
from ppod_nodes.launch.spec import LaunchSpec, NodeSpec, deep_merge
from ppod_nodes.launch.supervisor import Supervisor
from ppod_nodes.ros_env import configure_ros_environment
from ppod_ros.errors import DeviceError


class Stack:
    """The running stack. See the module docstring."""

    def __init__(self, spec: LaunchSpec, sim: bool, only: list[str] | None = None, out: IO[str] | None = None,
                 log_dir: Path | None = None, extra_params: dict[str, dict] | None = None,
                 handle_signals: bool = True):
        self.spec = spec
        self.sim = sim
        self.nodes: list[NodeSpec] = spec.selected(sim, only)
        if extra_params:
            self.nodes = [_with_params(n, extra_params.get(n.name, {})) for n in self.nodes]
        self.env = dict(os.environ)
        configure_ros_environment(self.env, spec.discovery_range)
        if spec.domain_id is not None:
            self.env["ROS_DOMAIN_ID"] = str(spec.domain_id)
        self.env.setdefault("PYTHONUNBUFFERED", "1")
        self.env.setdefault("RCUTILS_CONSOLE_OUTPUT_FORMAT", "[{severity}] {message}")
        self.env.setdefault("RCUTILS_LOGGING_BUFFERED_STREAM", "0")
        # The supervisor's own lifecycle client must see the same DDS settings as the children.
        for key in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_DOMAIN_ID"):
            if key in self.env:
                os.environ[key] = self.env[key]
        os.environ.pop("ROS_LOCALHOST_ONLY", None)
        self.substitutions = launch_substitutions()
        self.supervisor = Supervisor(self.env, sim, out=out, log_dir=log_dir, substitutions=self.substitutions)
        self.stop_event = threading.Event()
        self.failed: list[str] = []
        self._lifecycle = None
        self._previous_handlers: dict[int, object] = {}
        self._handle_signals = handle_signals

    # ------------------------------------------------------------------ context manager
    def __enter__(self) -> Stack:
        if self._handle_signals and threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._previous_handlers[sig] = signal.signal(sig, self._on_signal)
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
        for sig, handler in self._previous_handlers.items():
            signal.signal(sig, handler)

    def _on_signal(self, signum, _frame) -> None:
        if self.stop_event.is_set():
            self.supervisor.say("second signal: stopping now")
        self.supervisor.say(f"{signal.Signals(signum).name} received: stopping the stack")
        self.stop_event.set()

    @property
    def domain(self) -> str:
        """The ROS domain the stack's nodes run in (its run file is that domain's)."""
        return self.env.get("ROS_DOMAIN_ID", "0")

    # ------------------------------------------------------------------ start
    def start(self, activate: bool = True) -> None:
        """Spawn every node, then configure and activate the lifecycle nodes in order.

        Raises DeviceError (after reporting) if a node dies or a transition fails.
        """
        if not self.nodes:
            raise DeviceError("no nodes selected to start")
        domain = self.domain
        other = runfile.read(domain)
        if other is not None and other.get("pid") != os.getpid():
            # Two stacks in one domain share node, service and topic names: the lifecycle requests
            # reach the other stack's nodes (measured: "configure failed" as its response timed out).
            raise DeviceError(f"another ppod stack is running in ROS domain {domain} (launcher pid "
                              f"{other.get('pid')}, {runfile.path(domain)}): stop it first, or "
                              f"start this one with another ROS_DOMAIN_ID")
        mode = "simulated device" if self.sim else "hardware"
        self.supervisor.say(f"starting {len(self.nodes)} nodes against the {mode} "
                            f"(DDS discovery {self.env['ROS_AUTOMATIC_DISCOVERY_RANGE']}, "
                            f"domain {domain}); config {self.spec.origin}")
        for node in self.nodes:
            self.supervisor.start(node)
        runfile.write({"sim": self.sim, "domain": domain, "nodes": [n.name for n in self.nodes],
                       "sim_bridge": f"ws://127.0.0.1:{self.substitutions['sim_port']}/" if self.sim else None})
        managed = [n for n in self.nodes if n.lifecycle]
        if activate and managed:
            from ppod_nodes.launch.lifecycle_client import LifecycleClient

            self._lifecycle = LifecycleClient()
        for node in self.nodes:  # in order: a node may need the ones before it (the simulator's bus)
            if node.ready:
                self._wait_ready(node)
            if node.lifecycle and self._lifecycle is not None:
                self._bring_up(node)
        self.supervisor.say("all nodes up: " + ", ".join(
            f"{n.name} ({'active' if n.lifecycle else 'running'})" for n in self.nodes))

    def _bring_up(self, node: NodeSpec) -> None:
        deadline = time.monotonic() + self.spec.lifecycle_timeout_s
        while not self._lifecycle.wait_for(node.name, 0.5):
            self._check_alive()
            if self.stop_event.is_set():
                raise DeviceError("interrupted while starting")
            if time.monotonic() > deadline:
                raise DeviceError(f"{node.name}: lifecycle services did not appear within "
                                  f"{self.spec.lifecycle_timeout_s:g} s")
        for transition in ("configure", "activate"):
            left = max(1.0, deadline - time.monotonic())
            if not self._lifecycle.change_state(node.name, transition, timeout_s=left):
                self._check_alive()
                raise DeviceError(f"{node.name}: {transition} failed (see its log above)")
        self._check_alive()

    def _wait_ready(self, node: NodeSpec) -> None:
        rx = re.compile(node.ready)
        child = next(c for c in self.supervisor.children if c.spec.name == node.name)
        deadline = time.monotonic() + self.spec.lifecycle_timeout_s
        while not any(rx.search(line) for line in list(child.lines)):
            self._check_alive()
            if self.stop_event.wait(0.05):
                raise DeviceError("interrupted while starting")
            if time.monotonic() > deadline:
                raise DeviceError(f"{node.name}: not ready ('{node.ready}' not logged) within "
                                  f"{self.spec.lifecycle_timeout_s:g} s")

    def _check_alive(self) -> None:
        dead = self.supervisor.dead_children()
        required = [c.spec.name for c in dead if c.spec.required]
        self.failed += [c.spec.name for c in dead]
        if required:
            raise DeviceError(f"required node{'s' if len(required) > 1 else ''} exited: {', '.join(required)}")

    # ------------------------------------------------------------------ run
    def wait(self, duration_s: float | None = None) -> int:
        """Block until Ctrl-C/SIGTERM, ``duration_s`` or a required node's death; 0 if nobody died."""
        deadline = None if duration_s is None else time.monotonic() + duration_s
        while not self.stop_event.wait(0.1):
            try:
                self._check_alive()
            except DeviceError as exc:
                self.supervisor.say(f"{exc}: stopping the stack")
                return 1
            if deadline is not None and time.monotonic() >= deadline:
                self.supervisor.say(f"ran for {duration_s:g} s: stopping the stack")
                break
        return 1 if self.failed else 0

    def alive(self) -> bool:
        return not self.stop_event.is_set() and not any(
            c.spec.required and c.process.poll() is not None for c in self.supervisor.children)

    # ------------------------------------------------------------------ stop
    def stop(self) -> bool:
        """Stop all nodes in reverse order; True if all exited cleanly. Idempotent."""
        if getattr(self, "_stopped", False):
            return True
        self._stopped = True
        self.stop_event.set()
        if self._lifecycle is not None:
            self._lifecycle.close()
            self._lifecycle = None
        clean = self.supervisor.stop_all(self.spec.shutdown_timeout_s)
        runfile.remove(self.domain)
        left = self.supervisor.running()
        self.supervisor.say("all children exited" if not left else
                            "still running: " + ", ".join(c.spec.name for c in left))
        self.supervisor.close()
        return clean and not left


def _with_params(node: NodeSpec, extra: dict) -> NodeSpec:
    return replace(node, params=deep_merge(node.params, extra)) if extra else node

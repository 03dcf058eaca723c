"""A private rclpy session for tools and tests: context, one helper node, an executor thread.

Used by the CLI (``ppod goal``, ``ppod echo``, the launcher's lifecycle client) and by the in-process
node tests. Blocking calls wait on futures from the caller's thread while the executor spins in
its own (fast and safe per ROS_NOTES.md). :meth:`RosSession.close` tears down in the order that
never aborts, the spin thread stopped first (``runner.spin_until_halted``): halt, join,
executor.shutdown, destroy nodes, context.try_shutdown.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from ppod_nodes.common.runner import spin_until_halted, stop_spinning
from ppod_nodes.ros_env import configure_ros_environment
from ppod_ros.errors import DeviceError


class RosSession:
    """See the module docstring. Usable as a context manager."""

    def __init__(self, name: str = "ppod_tool", args: list[str] | None = None):
        configure_ros_environment()
        self.context = Context()
        rclpy.init(args=args, context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes: list[Any] = []
        self.failures: list[Exception] = []   # a callback that raised (its traceback is printed)
        self._halt = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True, name=f"{name}-spin")
        self._thread.start()
        self.node = self.add(rclpy.create_node(name, context=self.context))
        self._closed = False

    def _spin(self) -> None:
        spin_until_halted(self.executor, self.failures, self._halt)

    def __enter__(self) -> RosSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def add(self, node):
        """Spin ``node`` in this session (it must use ``self.context``)."""
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    @staticmethod
    def wait_until(predicate: Callable[[], bool], timeout_s: float, step_s: float = 0.01) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if predicate():
                return True
            time.sleep(step_s)
        return bool(predicate())

    def wait_future(self, future, timeout_s: float, what: str):
        done = threading.Event()
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(timeout_s):
            raise DeviceError(f"{what}: no answer within {timeout_s:g} s")
        return future.result()

    def call(self, srv_type, name: str, request, timeout_s: float = 10.0, client=None):
        """Call a service and return its response; DeviceError if unavailable or silent."""
        own = client is None
        if own:
            client = self.node.create_client(srv_type, name)
        try:
            if not client.wait_for_service(timeout_sec=timeout_s):
                raise DeviceError(f"service {name} is not available (is the node running? try `ppod up`)")
            future = client.call_async(request)
            try:
                return self.wait_future(future, timeout_s, f"service {name}")
            except DeviceError:
                client.remove_pending_request(future)
                raise
        finally:
            if own:
                self.node.destroy_client(client)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        stop_spinning(self.executor, self._halt, self._thread)
        self.executor.shutdown()
        for node in reversed(self.nodes):
            node.destroy_node()
        self.context.try_shutdown()

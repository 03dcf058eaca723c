"""In-process ROS for node tests: a private context, one executor thread, bounded waits.

Teardown follows ROS_NOTES.md (executor.shutdown, join, destroy nodes, try_shutdown), which is the
order that never aborts the interpreter at exit.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import rclpy
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from ppod_nodes.ros_env import configure_ros_environment


class RosHarness:
    def __init__(self, args: list[str] | None = None):
        configure_ros_environment()
        self.context = Context()
        rclpy.init(args=args, context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes: list[Any] = []
        self._thread = threading.Thread(target=self._spin, daemon=True, name="test-spin")
        self._thread.start()
        self.helper = self.add(rclpy.create_node("test_helper", context=self.context))

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except ExternalShutdownException:
            pass

    def add(self, node):
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def make(self, factory: Callable[..., Any], parameter_overrides: list | None = None, **kwargs):
        """Create a node with this harness's context (factory(context=..., ...)) and spin it."""
        if parameter_overrides is not None:
            kwargs["parameter_overrides"] = parameter_overrides
        return self.add(factory(context=self.context, **kwargs))

    def collect(self, msg_type, topic: str, qos) -> list:
        """Subscribe the helper node to ``topic``; returns the list the messages land in."""
        got: list = []
        self.helper.create_subscription(msg_type, topic, got.append, qos)
        return got

    @staticmethod
    def wait_until(predicate: Callable[[], bool], timeout_s: float, step_s: float = 0.01) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if predicate():
                return True
            time.sleep(step_s)
        return predicate()

    def call(self, srv_type, name: str, request, timeout_s: float = 10.0):
        client = self.helper.create_client(srv_type, name)
        try:
            if not client.wait_for_service(timeout_sec=timeout_s):
                raise TimeoutError(f"service {name} not available within {timeout_s} s")
            future = client.call_async(request)
            if not self.wait_until(future.done, timeout_s):
                raise TimeoutError(f"service {name} did not answer within {timeout_s} s")
            return future.result()
        finally:
            self.helper.destroy_client(client)

    def close(self) -> None:
        self.executor.shutdown()
        self._thread.join(timeout=5)
        for node in reversed(self.nodes):
            node.destroy_node()
        self.context.try_shutdown()

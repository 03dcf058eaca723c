"""In-process ROS for node tests: the tools' RosSession plus helpers to make and observe nodes."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ppod_nodes.common.session import RosSession
from ppod_ros.errors import DeviceError


class RosHarness(RosSession):
    def __init__(self, args: list[str] | None = None):
        super().__init__("test_helper", args)
        self.helper = self.node

    def check_callbacks(self) -> None:
        """AssertionError if a callback raised: the executor thread then stopped spinning (in the
        stack the node's process would have ended, ``runner.spin_until_halted``), so a test waiting
        on the nodes fails now, naming the exception, instead of at the end of its wait."""
        if self.failures:
            exc = self.failures[0]
            raise AssertionError(f"a node's callback raised {type(exc).__name__}: {exc} (the executor stopped "
                                 f"spinning; in the stack the node would have exited)")

    def wait_until(self, predicate: Callable[[], bool], timeout_s: float, step_s: float = 0.01) -> bool:
        """:meth:`RosSession.wait_until`, failing at once when a callback raised (:meth:`check_callbacks`)."""

        def checked() -> bool:
            self.check_callbacks()
            return predicate()

        return RosSession.wait_until(checked, timeout_s, step_s)

    def wait_future(self, future, timeout_s: float, what: str):
        """:meth:`RosSession.wait_future`, failing at once when a callback raised."""
        if not self.wait_until(future.done, timeout_s, step_s=0.005):
            raise DeviceError(f"{what}: no answer within {timeout_s:g} s")
        return future.result()

    def make(self, factory: Callable[..., Any], parameter_overrides: list | None = None, **kwargs):
        """Create a node with this harness's context (factory(context=..., ...)) and spin it."""
        if parameter_overrides is not None:
            kwargs["parameter_overrides"] = parameter_overrides
        return self.add(factory(context=self.context, **kwargs))

    def wait_for_action_server(self, client, timeout_s: float = 30.0) -> None:
        """Wait until ``client`` (an rclpy action client) sees its server, ``timeout_s`` of wall time.

        rclpy's ``wait_for_server(timeout_sec=10)`` counts 0.25 s sleeps, not time; and one CI run
        (commit 0f3e060) saw an in-process server still undiscovered after it. On failure the
        assertion says what the helper's graph shows, so a recurrence says whether the server's
        endpoints were missing or only some of them.
        """
        if self.wait_until(client.server_is_ready, timeout_s, step_s=0.05):
            return
        name = client._action_name
        servers = {k: self.helper.count_services(f"{name}/_action/{k}")
                   for k in ("send_goal", "cancel_goal", "get_result")}
        publishers = {k: self.helper.count_publishers(f"{name}/_action/{k}") for k in ("status", "feedback")}
        raise AssertionError(f"action server {name} not discovered within {timeout_s:g} s: the graph shows "
                             f"service servers {servers}, topic publishers {publishers}, "
                             f"nodes {sorted(self.helper.get_node_names())}")

    def collect(self, msg_type, topic: str, qos) -> list:
        """Subscribe the helper node to ``topic``; returns the list the messages land in."""
        got: list = []
        self.helper.create_subscription(msg_type, topic, got.append, qos)
        return got

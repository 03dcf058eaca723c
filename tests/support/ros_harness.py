"""In-process ROS for node tests: the tools' RosSession plus helpers to make and observe nodes."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ppod_nodes.common.session import RosSession


class RosHarness(RosSession):
    def __init__(self, args: list[str] | None = None):
        super().__init__("test_helper", args)
        self.helper = self.node

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

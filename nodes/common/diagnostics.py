"""/diagnostics publishing (diagnostic_msgs/DiagnosticArray), the ROS convention for health.

A node keeps named entries up to date with :meth:`Diagnostics.set` (level, message, key values);
the helper publishes them all periodically (default 1 Hz) and immediately when a level worsens, so
a fault is visible at once. Levels are diagnostic_msgs' OK, WARN, ERROR, STALE.
"""

from __future__ import annotations

import threading
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from ppod_nodes.common import topics

OK = DiagnosticStatus.OK
WARN = DiagnosticStatus.WARN
ERROR = DiagnosticStatus.ERROR
STALE = DiagnosticStatus.STALE


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


class Diagnostics:
    """Named diagnostic entries of one node, published on /diagnostics."""

    def __init__(self, node, hardware_id: str = "ppod", period_s: float = 1.0):
        self._node = node
        self._hardware_id = hardware_id
        self._lock = threading.Lock()
        self._entries: dict[str, DiagnosticStatus] = {}
        self._pub = node.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        self._timer = node.create_timer(period_s, self.publish)

    def set(self, name: str, level: int, message: str, **values: Any) -> None:
        """Update entry ``name`` (shown as "<node>: <name>"); publishes at once if the level worsened."""
        status = DiagnosticStatus(
            level=bytes([level]) if isinstance(level, int) else level,
            name=f"{self._node.get_name()}: {name}",
            message=message,
            hardware_id=self._hardware_id,
            values=[KeyValue(key=k, value=_fmt(v)) for k, v in values.items()],
        )
        with self._lock:
            old = self._entries.get(name)
            self._entries[name] = status
        if old is None or status.level > old.level:
            self.publish()

    def level(self, name: str) -> int | None:
        with self._lock:
            entry = self._entries.get(name)
        return None if entry is None else entry.level[0] if isinstance(entry.level, bytes) else entry.level

    def publish(self) -> None:
        with self._lock:
            status = list(self._entries.values())
        if not status:
            return
        msg = DiagnosticArray(status=status)
        msg.header.stamp = self._node.get_clock().now().to_msg()
        try:
            self._pub.publish(msg)
        except RuntimeError as exc:  # RCLError / InvalidHandle while the context shuts down
            self._node.get_logger().debug(f"diagnostics not published: {exc}")

    def destroy(self) -> None:
        self._node.destroy_timer(self._timer)
        self._node.destroy_publisher(self._pub)

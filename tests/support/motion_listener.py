"""Test node: a plain (non-lifecycle) node that counts PlateMotion messages and logs each tenth.

Tests wait for a count ("11 so far"), never for a message name: discovery may miss the first few.
"""

from __future__ import annotations

from ppod_msgs.msg import PlateMotion as PlateMotionMsg
from rclpy.node import Node

from ppod_nodes.common import qos
from ppod_nodes.common.runner import make_main


class MotionListener(Node):
    def __init__(self, **kwargs):
        super().__init__("motion_listener", **kwargs)
        self.declare_parameter("topic", "talk")
        self.count = 0
        self.create_subscription(PlateMotionMsg, self.get_parameter("topic").value, self._on_msg, qos.STREAM)

    def _on_msg(self, msg):
        self.count += 1
        if self.count % 10 == 1:
            self.get_logger().info(f"received {msg.name} (amplitude {msg.harmonics[0].amplitude[0]:g}); "
                                   f"{self.count} so far")

    def finalize(self):
        self.get_logger().info(f"received {self.count} motions in total")


main = make_main(MotionListener)

if __name__ == "__main__":
    raise SystemExit(main())

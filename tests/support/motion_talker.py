"""Test node: a lifecycle node that publishes a PlateMotion at a fixed rate while active.

It exercises the shared plumbing (parameters, lifecycle base, diagnostics, run_node) exactly as a
product node does; the launcher tests start it as a separate process.
"""

from __future__ import annotations

from ppod_msgs.msg import PlateMotion as PlateMotionMsg

from ppod_nodes.common import qos
from ppod_nodes.common.convert import motion_to_msg
from ppod_nodes.common.lifecycle import PpodLifecycleNode
from ppod_nodes.common.params import Param
from ppod_nodes.common.runner import make_main
from ppod_ros.motion import PlateMotion


class MotionTalker(PpodLifecycleNode):
    PARAMS = (
        Param("rate_hz", 10.0, "publication rate", min_value=0.1, max_value=1000.0),
        Param("topic", "talk", "topic to publish PlateMotion on"),
        Param("fail_configure", False, "fail the configure transition (tests)"),
    )

    def __init__(self, **kwargs):
        super().__init__("motion_talker", **kwargs)
        self._pub = None
        self._timer = None
        self._count = 0

    def on_configure_node(self, params):
        from ppod_ros.errors import ConfigError

        if params["fail_configure"]:
            raise ConfigError("fail_configure is set")
        self._pub = self.create_lifecycle_publisher(PlateMotionMsg, params["topic"], qos.STREAM)

    def on_activate_node(self):
        self._timer = self.create_timer(1.0 / self.params["rate_hz"], self._tick)

    def _tick(self):
        self._count += 1
        motion = PlateMotion.single(30.0, [self._count, 0, 0, 0, 0, 0], name=f"talk-{self._count}")
        self._pub.publish(motion_to_msg(motion, self.get_clock().now().to_msg()))

    def on_deactivate_node(self):
        if self._timer is not None:
            self.destroy_timer(self._timer)
            self._timer = None
        self.get_logger().info(f"published {self._count} motions")

    def on_shutdown_node(self):
        self.get_logger().info("shutdown: safe")


main = make_main(MotionTalker)

if __name__ == "__main__":
    raise SystemExit(main())

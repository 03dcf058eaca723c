"""viz: the stack's state as drawable and plottable topics (Foxglove's and RViz's 3D and plot panels).

Subscribes to the tracked parts, the active motion, MovePart targets and the measured acceleration;
publishes, at ``rate_hz``:

* ``/ppod/viz/markers`` (visualization_msgs/MarkerArray, frame ``plate``): the working disc, each
  part (disc, heading arrow, id and label), each MovePart target, and the active motion's field for
  a point part (arrows: velocity x ``arrow_scale_s``);
* ``/tf``: ``plate -> camera`` from the camera's mounting pose (ppod_msgs/TFMessage, the wire format
  of tf2_msgs/msg/TFMessage; recordings name it so);
* ``/ppod/viz/accel_goal`` and ``/ppod/viz/accel_measured`` (geometry_msgs/AccelStamped): the
  fundamental's amplitude per axis, goal and measured, for a plot panel.

The scene itself is built in the core (``ppod_ros.view``); this node only translates.
"""

from __future__ import annotations

from geometry_msgs.msg import AccelStamped
from ppod_msgs.msg import PlateAcceleration, TFMessage
from rclpy.node import Node
from visualization_msgs.msg import MarkerArray

from ppod_nodes.common import qos, topics
from ppod_nodes.common.events import QuietPublishers
from ppod_nodes.common.params import Param, declare, read
from ppod_nodes.common.runner import make_main
from ppod_nodes.view.ros_drawables import camera_tf, scene_markers
from ppod_nodes.view.state import SceneState
from ppod_ros.device.config import load_device_config
from ppod_ros.view.scene import DEFAULT_ARROW_SCALE_S, camera_transform
from ppod_ros.vision import CameraConfig


class VizNode(QuietPublishers, Node):
    PARAMS = (
        Param("device_config", "", "device description YAML (plate radius); empty: the packaged default"),
        Param("camera_config", "", "camera YAML (the plate -> camera transform); empty: the simulated camera"),
        Param("rate_hz", 5.0, "publication rate of markers and TF (Hz)", min_value=0.2, max_value=30.0),
        Param("field_grid", 9, "field arrows per plate diameter (0: no field)", min_value=0, max_value=25),
        Param("field_mu", 0.3, "friction of the point part whose field is drawn", min_value=0.01, max_value=2.0),
        Param("arrow_scale_s", DEFAULT_ARROW_SCALE_S, "arrow length per velocity (s)", min_value=0.01),
    )

    def __init__(self, node_name: str = "viz", **kwargs):
        super().__init__(node_name, **kwargs)
        declare(self, self.PARAMS)
        p = read(self, self.PARAMS)
        self.params = p
        self.radius_m = load_device_config(p["device_config"] or None).plate.radius_m
        camera = CameraConfig.from_yaml(p["camera_config"]) if p["camera_config"] else CameraConfig()
        self.camera = camera_transform(camera)
        self.state = SceneState(self, self.radius_m, p["field_grid"], p["field_mu"], p["arrow_scale_s"])
        self.markers_pub = self.create_publisher(MarkerArray, topics.VIZ_MARKERS, qos.STREAM)
        self.tf_pub = self.create_publisher(TFMessage, topics.TF, qos.STREAM)
        self.goal_pub = self.create_publisher(AccelStamped, topics.ACCEL_GOAL_PLOT, qos.STREAM)
        self.measured_pub = self.create_publisher(AccelStamped, topics.ACCEL_MEASURED_PLOT, qos.STREAM)
        self.create_subscription(PlateAcceleration, topics.ACCELERATION, self._on_accel, qos.STREAM)
        self.create_timer(1.0 / p["rate_hz"], self._publish)

    def _on_accel(self, msg) -> None:
        stamp = msg.header.stamp
        for harmonics, pub in ((msg.goal, self.goal_pub), (msg.measured, self.measured_pub)):
            first = next((h for h in harmonics if h.k == 1), None)
            if first is None:
                continue
            out = AccelStamped()
            out.header.stamp, out.header.frame_id = stamp, "plate"
            a = list(first.amplitude)
            out.accel.linear.x, out.accel.linear.y, out.accel.linear.z = a[0:3]
            out.accel.angular.x, out.accel.angular.y, out.accel.angular.z = a[3:6]
            pub.publish(out)

    def _publish(self) -> None:
        stamp = self.get_clock().now().to_msg()
        self.markers_pub.publish(scene_markers(self.state.scene(), stamp))
        self.tf_pub.publish(camera_tf(*self.camera, stamp))


main = make_main(VizNode)

if __name__ == "__main__":
    raise SystemExit(main())

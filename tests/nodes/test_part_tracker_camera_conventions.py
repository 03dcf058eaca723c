"""part_tracker takes its intrinsics from camera_info or ost.yaml and reads Bayer images."""

import numpy as np
import pytest

pytestmark = pytest.mark.ros


def test_the_tracker_takes_intrinsics_from_camera_info(ros):
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import CameraInfo

    from ppod_nodes.common import qos, topics
    from ppod_nodes.part_tracker import PartTrackerNode

    node = ros.make(PartTrackerNode, parameter_overrides=[Parameter("use_camera_info", value=True)])
    node.trigger_configure()
    node.trigger_activate()
    assert node.lifecycle_state == "active"
    base = node._camera
    info = CameraInfo(width=base.width, height=base.height, distortion_model="plumb_bob")
    info.k = [1650.0, 0.0, 641.0, 0.0, 1660.0, 510.0, 0.0, 0.0, 1.0]
    info.d = [-0.07, 0.04, 0.0, 0.0, 0.0]
    ros.helper.create_publisher(CameraInfo, topics.CAMERA_INFO, qos.LATCHED).publish(info)
    assert ros.wait_until(lambda: node._camera.fx == 1650.0, 10)
    assert (node._camera.fy, node._camera.cx, node._camera.cy) == (1660.0, 641.0, 510.0)
    assert node._tracker.camera.fx == 1650.0
    node.trigger_deactivate()


def test_the_tracker_takes_intrinsics_from_an_ost_yaml(ros, tmp_path):
    from rclpy.parameter import Parameter

    from ppod_nodes.part_tracker import PartTrackerNode
    from tests.vision.test_ros_camera import OST

    (tmp_path / "ost.yaml").write_text(OST)
    node = ros.make(PartTrackerNode, parameter_overrides=[Parameter("intrinsics", value=str(tmp_path / "ost.yaml"))])
    node.trigger_configure()
    assert node.lifecycle_state == "inactive"
    assert (node._camera.fx, node._camera.width) == (851.2, 640)


def test_a_bayer_image_message_becomes_the_cameras_mono_frame():
    from sensor_msgs.msg import Image

    from ppod_nodes.part_tracker import image_to_array

    raw = np.full((8, 8), 100, np.uint8)
    msg = Image(height=8, width=8, encoding="bayer_rggb8", step=8, is_bigendian=0)
    msg.data = raw.tobytes()
    frame = image_to_array(msg, "mono8")
    assert frame.shape == (8, 8) and abs(int(frame[4, 4]) - 100) <= 1

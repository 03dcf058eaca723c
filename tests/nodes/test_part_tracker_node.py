"""part_tracker in-process: rendered frames on the image topic in, PartPoseArray out."""

import math

import numpy as np
import pytest

from tests.ros.helpers import ROOT

pytestmark = pytest.mark.ros


def _image_msg(image: np.ndarray, stamp_s: float, encoding: str = "mono8"):
    from sensor_msgs.msg import Image

    from ppod_nodes.common.convert import seconds_to_stamp

    msg = Image(height=image.shape[0], width=image.shape[1], encoding=encoding, is_bigendian=0)
    msg.step = image.shape[1] * (1 if image.ndim == 2 else 3)
    msg.data = image.tobytes()
    msg.header.stamp = seconds_to_stamp(stamp_s)
    return msg


def test_tracker_node_reports_rendered_poses_and_skips_bad_frames(ros):
    from ppod_msgs.msg import PartPoseArray
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import Image

    from ppod_nodes.common import qos, topics
    from ppod_nodes.part_tracker import PartTrackerNode
    from ppod_ros.vision import CameraConfig, load_tracker_config
    from ppod_sim.camera import CameraRenderer, RenderPart

    specs, _ = load_tracker_config(ROOT / "ppod_ros" / "data" / "tracker.yaml")
    by_label = {s.label: s for s in specs}
    renderer = CameraRenderer(CameraConfig(), seed=3)
    truth = {"pin": (0.03, -0.02, 0.4), "washer": (-0.05, 0.04, 0.0), "tab": (0.0, 0.06, -1.0)}

    got = ros.collect(PartPoseArray, topics.PART_POSES, qos.STREAM)
    pub = ros.helper.create_publisher(Image, topics.IMAGE, qos.SENSOR_DATA)
    node = ros.make(PartTrackerNode, parameter_overrides=[
        Parameter("tracker_config", value=str(ROOT / "ppod_ros" / "data" / "tracker.yaml"))])
    node.trigger_configure()
    node.trigger_activate()
    assert node.lifecycle_state == "active"
    assert ros.wait_until(lambda: ros.helper.count_subscribers(topics.IMAGE) > 0, 5)

    for i in range(4):
        t = 0.1 * (i + 1)
        parts = [RenderPart.of(lbl, by_label[lbl].footprint, pose, by_label[lbl].height_m)
                 for lbl, pose in truth.items()]
        frame = renderer.render(parts, t, index=i)
        pub.publish(_image_msg(frame.image, t))
        assert ros.wait_until(lambda n=i: len(got) > n, 10), f"no poses for frame {i}"
    # A frame of the wrong encoding is skipped, not fatal; the next good frame is tracked.
    pub.publish(_image_msg(np.zeros((8, 8), np.uint8), 0.45, encoding="yuv422"))
    frame = renderer.render(parts, 0.5, index=9)
    pub.publish(_image_msg(frame.image, 0.5))
    assert ros.wait_until(lambda: len(got) >= 5, 10)

    last = got[-1]
    assert abs(last.header.stamp.sec + last.header.stamp.nanosec * 1e-9 - 0.5) < 1e-6
    assert last.header.frame_id == "plate"
    seen = {p.label: p for p in last.parts}
    assert set(seen) == set(truth)
    for label, (x, y, th) in truth.items():
        p = seen[label]
        assert p.status == 0
        assert math.hypot(p.pose.x - x, p.pose.y - y) < 2e-4
        sym = by_label[label].footprint.symmetry_rad
        if sym > 0:
            d = (p.pose.theta - th + sym / 2) % sym - sym / 2
            assert abs(d) < math.radians(0.5)
    assert len({p.id for p in last.parts}) == 3
    assert node._rejected == {"encoding": 1}


def test_tracker_node_with_a_bad_part_list_fails_configure_naming_the_problem(ros, tmp_path):
    from rclpy.parameter import Parameter

    from ppod_nodes.part_tracker import PartTrackerNode

    bad = tmp_path / "tracker.yaml"
    bad.write_text("parts:\n  - {label: washer, footprint: {disk: -1}}\n")
    node = ros.make(PartTrackerNode, parameter_overrides=[Parameter("tracker_config", value=str(bad))])
    node.trigger_configure()
    assert node.lifecycle_state == "unconfigured"

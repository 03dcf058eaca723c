"""The viz node's drawable topics land in a recording that independent readers decode completely.

The recording is read back by mcap-ros2-support and by rosbags (as the rosbag2 folder that the file's
own ``rosbag2`` metadata record describes); both find MarkerArray, TF and the plottable topics.
"""

import shutil
import time

import pytest
import yaml

pytestmark = pytest.mark.ros

DRAWABLE = {"/ppod/viz/markers": "visualization_msgs/msg/MarkerArray", "/tf": "tf2_msgs/msg/TFMessage",
            "/ppod/viz/accel_goal": "geometry_msgs/msg/AccelStamped",
            "/ppod/viz/accel_measured": "geometry_msgs/msg/AccelStamped"}


def _record(ros, path):
    from ppod_msgs.msg import PartPose, PartPoseArray, PlateAcceleration, PlateHarmonic
    from rclpy.parameter import Parameter

    from ppod_nodes.cli.record import default_include
    from ppod_nodes.common import qos, topics
    from ppod_nodes.record.mcap_io import McapRecorder
    from ppod_nodes.viz import VizNode

    viz = ros.make(VizNode, parameter_overrides=[Parameter("rate_hz", value=20.0)])
    poses = ros.helper.create_publisher(PartPoseArray, topics.PART_POSES, qos.STREAM)
    accel = ros.helper.create_publisher(PlateAcceleration, topics.ACCELERATION, qos.STREAM)
    recorder = McapRecorder(ros.helper, path, default_include(images=False), discovery_period_s=0.2)
    try:
        msg = PartPoseArray(parts=[PartPose(id=3, label="washer")])
        a = PlateAcceleration(goal_name="x", measured=[PlateHarmonic(k=1, amplitude=[9.5, 0, 0, 0, 95, 0])],
                              goal=[PlateHarmonic(k=1, amplitude=[10.0, 0, 0, 0, 100, 0])])
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not all(recorder.counts.get(t, 0) >= 3 for t in DRAWABLE):
            poses.publish(msg)
            accel.publish(a)
            viz.get_logger().info("recorded on /rosout")
            time.sleep(0.05)
    finally:
        recorder.close()
    return recorder.counts


def test_a_recording_has_drawable_schemas_that_independent_readers_decode(ros, tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    path = tmp_path / "session.mcap"
    counts = _record(ros, path)
    for topic in (*DRAWABLE, "/rosout"):
        assert counts.get(topic, 0) >= 1, (topic, counts)

    # 1. mcap + mcap-ros2-support: every message decodes, the schemas are the drawable ROS types.
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        schemas = {ch.topic: summary.schemas[ch.schema_id].name for ch in summary.channels.values()}
        assert all("offered_qos_profiles" in ch.metadata for ch in summary.channels.values())
        decoded = list(reader.iter_decoded_messages())
    assert len(decoded) == sum(counts.values())
    for topic, type_name in DRAWABLE.items():
        assert schemas[topic] == type_name
    markers = [m for _, ch, _, m in decoded if ch.topic == "/ppod/viz/markers"][-1]
    assert any(mk.ns == "parts" and mk.text.startswith("3 washer") for mk in markers.markers)
    tf = [m for _, ch, _, m in decoded if ch.topic == "/tf"][-1]
    assert tf.transforms[0].header.frame_id == "plate" and tf.transforms[0].child_frame_id == "camera"

    # 2. rosbags, on the rosbag2 folder the file's own metadata record describes.
    from rosbags.highlevel import AnyReader

    from ppod_nodes.record.mcap_io import read_metadata

    meta = yaml.safe_load(read_metadata(path)["rosbag2"]["serialized_metadata"])
    bag = tmp_path / "bag"
    bag.mkdir()
    shutil.copy(path, bag / path.name)
    (bag / "metadata.yaml").write_text(yaml.safe_dump(meta))
    with AnyReader([bag]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        n = 0
        for connection, _, raw in reader.messages():
            reader.deserialize(raw, connection.msgtype)
            n += 1
    assert n == sum(counts.values())
    for topic, type_name in DRAWABLE.items():
        assert types[topic] == type_name


def test_record_includes_planner_progress_tf_and_rosout_but_not_images_or_hidden_feedback():
    from ppod_nodes.cli.record import default_include

    include = default_include(images=False)
    # The action feedback's content is recorded as the plain planner progress topic; the hidden
    # _action/feedback topic only on request (ppod record --action-feedback).
    assert include("/ppod/planner/progress", "ppod_msgs/msg/PlannerProgress")
    assert not include("/ppod/move_part/_action/feedback", "ppod_msgs/action/MovePart_FeedbackMessage")
    assert default_include(images=False, action_feedback=True)(
        "/ppod/move_part/_action/feedback", "ppod_msgs/action/MovePart_FeedbackMessage")
    assert include("/ppod/move_part/_action/status", "action_msgs/msg/GoalStatusArray")
    assert not include("/ppod/move_part/_action/send_goal", "x")
    assert include("/rosout", "rcl_interfaces/msg/Log") and include("/tf", "ppod_msgs/msg/TFMessage")
    assert not include("/ppod/camera/image_raw", "sensor_msgs/msg/Image")
    assert default_include(images=True)("/ppod/camera/image_raw", "sensor_msgs/msg/Image")


def test_action_feedback_has_a_full_definition_and_a_type():
    from ppod_nodes.common.msgdict import type_from_name
    from ppod_nodes.record.msgdef import full_definition

    cls = type_from_name("ppod_msgs/action/MovePart_FeedbackMessage")
    assert set(cls.get_fields_and_field_types()) == {"goal_id", "feedback"}
    text = full_definition("ppod_msgs/action/MovePart_FeedbackMessage")
    assert text.startswith("unique_identifier_msgs/UUID goal_id\nMovePart_Feedback feedback\n")
    assert "MSG: ppod_msgs/action/MovePart_Feedback\ngeometry_msgs/Pose2D current_pose" in text

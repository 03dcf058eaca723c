"""MovePart's action feedback is recorded on request (as rosbag2 names it) and rosbags decodes it from
the file; by default only its plain copy, /ppod/planner/progress, is recorded."""

import shutil
import time

import pytest
import yaml

pytestmark = pytest.mark.ros


def test_action_feedback_is_recorded_and_decoded_by_rosbags(ros, tmp_path):
    from ppod_msgs.action import MovePart
    from rclpy.action import ActionServer

    from ppod_nodes.cli.record import default_include
    from ppod_nodes.common import topics
    from ppod_nodes.common.actions import ActionClient
    from ppod_nodes.record.mcap_io import McapRecorder, read_mcap, read_metadata

    def execute(handle):
        for i in range(5):
            fb = MovePart.Feedback(phase="positioning", text=f"step {i}", position_error_m=0.01 * (5 - i))
            handle.publish_feedback(fb)
            time.sleep(0.1)
        handle.succeed()
        return MovePart.Result(success=True)

    ActionServer(ros.helper, MovePart, "/" + topics.MOVE_PART, execute_callback=execute)
    path = tmp_path / "feedback.mcap"
    recorder = McapRecorder(ros.helper, path, default_include(images=False, action_feedback=True),
                            discovery_period_s=0.2)
    client = ActionClient(ros.helper, MovePart, "/" + topics.MOVE_PART)
    try:
        ros.wait_for_action_server(client)
        feedback_topic = "/" + topics.MOVE_PART + "/_action/feedback"
        assert ros.wait_until(lambda: feedback_topic in recorder.counts, 10)
        future = client.send_goal_async(MovePart.Goal(part_id=1))
        assert ros.wait_until(lambda: future.done(), 10)
        assert ros.wait_until(lambda: recorder.counts.get(feedback_topic, 0) >= 5, 10)
    finally:
        recorder.close()
    got = [m.decode() for m in read_mcap(path, [feedback_topic])]
    assert [m.feedback.text for m in got] == [f"step {i}" for i in range(5)]

    from rosbags.highlevel import AnyReader

    bag = tmp_path / "bag"
    bag.mkdir()
    shutil.copy(path, bag / path.name)
    (bag / "metadata.yaml").write_text(yaml.safe_dump(yaml.safe_load(
        read_metadata(path)["rosbag2"]["serialized_metadata"])))
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic == feedback_topic]
        assert conns[0].msgtype == "ppod_msgs/action/MovePart_FeedbackMessage"
        texts = [reader.deserialize(raw, c.msgtype).feedback.text for c, _, raw in reader.messages(connections=conns)]
    assert texts == [f"step {i}" for i in range(5)]


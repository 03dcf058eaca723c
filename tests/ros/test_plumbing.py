"""The shared node plumbing in-process: parameters, lifecycle transitions, diagnostics, conversion."""

import numpy as np
import pytest

pytestmark = pytest.mark.ros


def test_lifecycle_node_declares_parameters_and_fails_configure_with_a_diagnostic(ros):
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.parameter import Parameter

    from tests.support.motion_talker import MotionTalker

    diags = ros.collect(DiagnosticArray, "/diagnostics", 10)
    node = ros.make(MotionTalker, parameter_overrides=[Parameter("fail_configure", value=True)])
    assert node.get_parameter("rate_hz").value == 10.0
    assert "publication rate" in node.describe_parameter("rate_hz").description
    node.trigger_configure()
    assert node.lifecycle_state == "unconfigured"
    assert ros.wait_until(lambda: any("configure failed: fail_configure is set" in s.message
                                      for d in diags for s in d.status), 5)


def test_lifecycle_publisher_only_publishes_while_active(ros):
    from ppod_msgs.msg import PlateMotion as PlateMotionMsg
    from rclpy.parameter import Parameter

    from ppod_nodes.common import qos
    from tests.support.motion_talker import MotionTalker

    got = ros.collect(PlateMotionMsg, "talk", qos.STREAM)
    node = ros.make(MotionTalker, parameter_overrides=[Parameter("rate_hz", value=50.0)])
    node.trigger_configure()
    node.trigger_activate()
    assert node.lifecycle_state == "active"
    assert ros.wait_until(lambda: len(got) >= 3, 5)
    node.finalize()
    assert node.lifecycle_state == "finalized"
    n = len(got)
    ros.wait_until(lambda: False, 0.3)
    assert len(got) <= n + 1


def test_out_of_range_parameter_is_rejected_with_its_name(ros):
    from rclpy.exceptions import InvalidParameterValueException
    from rclpy.parameter import Parameter

    from tests.support.motion_talker import MotionTalker

    with pytest.raises(InvalidParameterValueException, match="rate_hz"):
        ros.make(MotionTalker, parameter_overrides=[Parameter("rate_hz", value=5000.0)])


def test_motion_message_round_trip_and_validation():
    from ppod_nodes.common.convert import motion_from_msg, motion_to_msg
    from ppod_ros.errors import ConfigError
    from ppod_ros.motion import PlateMotion

    m = PlateMotion(20.0, [1, 3], [[1, 2, 3, 4, 5, 6], [0, 0, 0.5, 0, 0, 0]], np.full((2, 6), 0.25), name="x",
                    ramp_time_s=0.4)
    back = motion_from_msg(motion_to_msg(m))
    assert back == m and back.name == "x" and back.ramp_time_s == 0.4
    msg = motion_to_msg(m)
    msg.frequency_hz = float("nan")
    with pytest.raises(ConfigError, match="frequency_hz"):
        motion_from_msg(msg)
    msg = motion_to_msg(m)
    msg.harmonics[1].k = 1
    with pytest.raises(ConfigError, match="at most once"):
        motion_from_msg(msg)


def test_stamps_round_to_the_nanosecond_without_losing_a_second():
    from ppod_nodes.common.convert import seconds_to_stamp, stamp_to_seconds

    for t in (0.0, 2.9999999999, 3.0, 12.3456789012, 1e6 + 0.5):
        stamp = seconds_to_stamp(t)
        assert 0 <= stamp.nanosec < 1_000_000_000
        assert abs(stamp_to_seconds(stamp) - t) <= 1e-9 * max(1.0, t) + 1e-9

"""System tests that run against the simulated device, or the real one with ``pytest --hardware CONFIG``.

    pytest tests/system -m hardware                                  # the simulator (CI)
    pytest tests/system -m hardware --hardware config/my_device.yaml # the lab's device
"""

import pytest

from tests.system.stack import GENERATOR, device_stack

pytestmark = [pytest.mark.system, pytest.mark.ros, pytest.mark.slow, pytest.mark.hardware]

#: A small goal: 2 m/s^2 at 30 Hz along x, well inside the default device's limits.
SMALL_GOAL = "name: SmallX\nfrequency_hz: 30\nramp_time_s: 0.3\nharmonics:\n" \
             "  - {k: 1, amplitude: [2, 0, 0, 0, 0, 0], phase: [0, 0, 0, 0, 0, 0]}\n"


def test_the_device_plays_a_goal_reports_its_status_and_stops(tmp_path):
    from ppod_msgs.msg import DeviceStatus, PlateMotionStatus
    from ppod_msgs.srv import SetPlateMotion
    from std_srvs.srv import Trigger

    from ppod_nodes.common import qos, topics
    from ppod_nodes.common.convert import motion_to_msg
    from ppod_nodes.common.session import RosSession
    from ppod_ros.can.protocol import PROTOCOL_VERSION
    from ppod_ros.motion import PlateMotion

    with device_stack(tmp_path, [GENERATOR]), RosSession("device_target_test") as ros:
        status, device = [], []
        ros.node.create_subscription(PlateMotionStatus, topics.MOTION_STATUS, status.append, qos.LATCHED)
        ros.node.create_subscription(DeviceStatus, topics.DEVICE_STATUS, device.append, qos.STREAM)
        # Both readers matched before the goal (a reader matched while a goal plays can hold up the
        # generator's heartbeat: tests/system/test_sim_stack.py, _matched).
        assert ros.wait_until(lambda: len(device) >= 2 and status, 15)
        assert device[-1].protocol_version >> 8 == PROTOCOL_VERSION[0]
        assert (device[-1].bus_load > 0) and not device[-1].faults
        goal = PlateMotion.from_yaml_text(SMALL_GOAL)
        resp = ros.call(SetPlateMotion, "/" + topics.SET_MOTION,
                        SetPlateMotion.Request(motion=motion_to_msg(goal)), timeout_s=15)
        assert resp.accepted, resp.reason
        assert ros.wait_until(lambda: any(s.state == PlateMotionStatus.STATE_ACTIVE for s in status), 15)
        assert ros.call(Trigger, "/" + topics.STOP, Trigger.Request(), timeout_s=15).success
        assert ros.wait_until(lambda: status[-1].state == PlateMotionStatus.STATE_IDLE, 15)

"""waveform_generator publishes the bus load it measures in DeviceStatus.bus_load."""

import pytest

from tests.support.sim_thread import SimThread

pytestmark = pytest.mark.ros


def test_device_status_reports_the_measured_bus_load(ros):
    from ppod_msgs.msg import DeviceStatus
    from rclpy.parameter import Parameter

    from ppod_nodes.common import qos, topics
    from ppod_nodes.waveform_generator import WaveformGeneratorNode

    with SimThread() as sim:
        got = ros.collect(DeviceStatus, topics.DEVICE_STATUS, qos.STREAM)
        node = ros.make(WaveformGeneratorNode, parameter_overrides=[
            Parameter("can_interface", value="virtual"), Parameter("can_channel", value=sim.channel)])
        node.trigger_configure()
        node.trigger_activate()
        assert node.lifecycle_state == "active"
        # Idle, the device still streams STATUS and accelerometer summaries: the load is above zero.
        assert ros.wait_until(lambda: any(m.bus_load > 0 for m in got), 10)
        assert all(0.0 <= m.bus_load < 1.0 for m in got)
        node.trigger_deactivate()

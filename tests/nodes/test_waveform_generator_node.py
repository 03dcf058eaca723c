"""waveform_generator in-process against the simulated device on a virtual bus."""

import math

import can
import pytest

from tests.support.sim_thread import SimThread

pytestmark = pytest.mark.ros

LINESINKX = "name: LineSinkX\nfrequency_hz: 30\nramp_time_s: 0.2\nharmonics:\n" \
            "  - {k: 1, amplitude: [10, 0, 0, 0, 100, 0], phase: [0, 0, 0, 0, 4.71238898, 0]}\n"


@pytest.fixture
def sim():
    with SimThread() as s:
        yield s


def _node(ros, sim):
    from rclpy.parameter import Parameter

    from ppod_nodes.waveform_generator import WaveformGeneratorNode

    node = ros.make(WaveformGeneratorNode, parameter_overrides=[
        Parameter("can_interface", value="virtual"), Parameter("can_channel", value=sim.channel)])
    node.trigger_configure()
    assert node.lifecycle_state == "inactive"
    node.trigger_activate()
    assert node.lifecycle_state == "active"
    return node


def _request(text, dry_run=False):
    from ppod_msgs.srv import SetPlateMotion

    from ppod_nodes.common.convert import motion_to_msg
    from ppod_ros.motion import PlateMotion

    return SetPlateMotion.Request(motion=motion_to_msg(PlateMotion.from_yaml_text(text)), dry_run=dry_run)


def test_goal_is_accepted_played_and_ramped_down_on_deactivate(ros, sim, capfd):
    from ppod_msgs.msg import PlateMotion as PlateMotionMsg
    from ppod_msgs.msg import PlateMotionStatus
    from ppod_msgs.srv import SetPlateMotion

    from ppod_nodes.common import qos, topics
    from ppod_ros.can import DeviceState

    status = ros.collect(PlateMotionStatus, topics.MOTION_STATUS, qos.LATCHED)
    active = ros.collect(PlateMotionMsg, topics.ACTIVE_MOTION, qos.LATCHED)
    node = _node(ros, sim)
    resp = ros.call(SetPlateMotion, "/" + topics.SET_MOTION, _request(LINESINKX))
    assert resp.accepted, resp.reason
    assert len(resp.predicted_current_peak_a) == 6 and max(resp.predicted_current_peak_a) > 0
    assert resp.contact_margin_mps2 == pytest.approx(9.81 - 100 * 0.08, abs=0.05)
    assert ros.wait_until(lambda: any(s.state == PlateMotionStatus.STATE_ACTIVE for s in status), 5)
    assert ros.wait_until(lambda: active and active[-1].name == "LineSinkX", 2)
    truth = sim.device.last_truth()
    assert abs(truth.accel[0, 0]) == pytest.approx(10, rel=0.3)  # the plate really moves (mismatch on)
    node.trigger_deactivate()
    assert node.lifecycle_state == "inactive"
    assert ros.wait_until(lambda: sim.device.state == DeviceState.DISABLED, 3)
    # The session's heartbeat record, for a watchdog trip to be read against (docs/ros.md).
    import re

    assert re.search(r"heartbeats: longest interval \d+ ms \(period 50 ms\); \d+ more than two periods apart",
                     capfd.readouterr().err)


def test_bad_goals_are_rejected_with_the_reason_and_nothing_goes_on_the_bus(ros, sim):
    from ppod_msgs.msg import PlateMotionStatus
    from ppod_msgs.srv import SetPlateMotion

    from ppod_nodes.common import qos, topics
    from ppod_nodes.common.convert import motion_to_msg
    from ppod_ros.can.protocol import Fn
    from ppod_ros.motion import PlateMotion

    status = ros.collect(PlateMotionStatus, topics.MOTION_STATUS, qos.LATCHED)
    _node(ros, sim)
    spy = can.Bus(interface="virtual", channel=sim.channel)
    try:
        over = ros.call(SetPlateMotion, "/" + topics.SET_MOTION, _request(LINESINKX.replace("[10, 0, 0, 0, 100, 0]",
                                                                                            "[10, 0, 0, 0, 400, 0]")))
        # alpha_y = 400 rad/s^2 lifts parts off inside the working disc: the contact-margin limit.
        assert not over.accepted and over.limit == "limits.contact_margin_mps2"
        assert over.requested_value < over.limit_value and over.limit in over.reason
        nan = _request(LINESINKX)
        nan.motion.harmonics[0].amplitude[0] = math.nan
        resp = ros.call(SetPlateMotion, "/" + topics.SET_MOTION, nan)
        assert not resp.accepted and "amplitude" in resp.reason
        neg = _request(LINESINKX)
        neg.motion.frequency_hz = -30.0
        resp = ros.call(SetPlateMotion, "/" + topics.SET_MOTION, neg)
        assert not resp.accepted and "frequency_hz" in resp.reason
        many = motion_to_msg(PlateMotion(30, [1, 2, 3, 4, 5, 6, 7, 8, 9, 10], [[0.1, 0, 0, 0, 0, 0]] * 10,
                                         [[0.0] * 6] * 10))
        many.harmonics.append(many.harmonics[0].__class__(k=11))
        resp = ros.call(SetPlateMotion, "/" + topics.SET_MOTION, SetPlateMotion.Request(motion=many))
        assert not resp.accepted and "1..10" in resp.reason
        # Every frame the spy saw during the four rejections: none of them a table frame.
        seen = []
        while (m := spy.recv(0.0 if seen else 2.0)) is not None:  # at least the next status/heartbeat
            seen.append(m.arbitration_id >> 4)
        assert seen, "the spy should at least see the device's status and the host's heartbeats"
        assert not set(seen) & {Fn.TABLE_HEADER, Fn.TABLE_ENTRY, Fn.TABLE_COMMIT}
    finally:
        spy.shutdown()
    assert ros.wait_until(lambda: any(s.state == PlateMotionStatus.STATE_REJECTED and s.limit for s in status), 2)


def test_emergency_stop_service_works_before_configure_and_when_active(ros, sim):
    from rclpy.parameter import Parameter
    from std_srvs.srv import Trigger

    from ppod_nodes.common import topics
    from ppod_nodes.waveform_generator import WaveformGeneratorNode
    from ppod_ros.can import DeviceState

    node = ros.make(WaveformGeneratorNode, parameter_overrides=[
        Parameter("can_interface", value="virtual"), Parameter("can_channel", value=sim.channel)])
    resp = ros.call(Trigger, "/" + topics.ESTOP, Trigger.Request())
    assert resp.success, resp.message
    assert ros.wait_until(lambda: sim.device.state == DeviceState.ESTOP, 2)
    ros.call(Trigger, "/ppod/reset_emergency_stop", Trigger.Request())  # not configured: refused politely
    node.trigger_configure()
    node.trigger_activate()
    assert ros.call(Trigger, "/ppod/reset_emergency_stop", Trigger.Request()).success
    assert ros.wait_until(lambda: sim.device.state == DeviceState.DISABLED, 2)
    from ppod_msgs.srv import SetPlateMotion

    assert ros.call(SetPlateMotion, "/" + topics.SET_MOTION, _request(LINESINKX)).accepted
    assert ros.wait_until(lambda: sim.device.state in (DeviceState.ENABLED, DeviceState.RAMPING), 2)
    assert ros.call(Trigger, "/" + topics.ESTOP, Trigger.Request()).success
    assert ros.wait_until(lambda: sim.device.state == DeviceState.ESTOP, 2)


def test_a_bus_off_episode_rejects_goals_and_the_node_answers_again_after_it(ros, sim):
    from ppod_msgs.srv import SetPlateMotion
    from std_srvs.srv import Trigger

    from ppod_nodes.common import topics
    from ppod_ros.can import FaultInjectingBus

    node = _node(ros, sim)
    faulty = FaultInjectingBus(node.link.bus)
    node.link.bus = faulty  # the node's own bus goes bus-off: every send raises
    try:
        faulty.go_bus_off()
        resp = ros.call(SetPlateMotion, "/" + topics.SET_MOTION, _request(LINESINKX))
        assert not resp.accepted and "CAN send failed" in resp.reason
        stop = ros.call(Trigger, "/" + topics.STOP, Trigger.Request())
        assert not stop.success and "not sent" in stop.message
        faulty.recover()
        resp = ros.call(SetPlateMotion, "/" + topics.SET_MOTION, _request(LINESINKX))
        assert resp.accepted, resp.reason
    finally:
        node.link.bus = faulty.inner


def test_a_raw_capture_on_request_is_written_as_a_recording(ros, sim, tmp_path):
    from ppod_msgs.srv import SetPlateMotion
    from rclpy.parameter import Parameter
    from std_srvs.srv import Trigger

    from ppod_nodes.common import topics
    from ppod_nodes.waveform_generator import WaveformGeneratorNode
    from ppod_ros.estimation import AccelEstimator, read_recording

    node = ros.make(WaveformGeneratorNode, parameter_overrides=[
        Parameter("can_interface", value="virtual"), Parameter("can_channel", value=sim.channel),
        Parameter("raw_cycles", value=1), Parameter("raw_dir", value=str(tmp_path))])
    assert not ros.call(Trigger, "/" + topics.CAPTURE_RAW, Trigger.Request()).success  # not active yet
    node.trigger_configure()
    node.trigger_activate()
    assert ros.call(SetPlateMotion, "/" + topics.SET_MOTION, _request(LINESINKX)).accepted
    # Once the plate plays the goal (past its ramp and the suspension's transient).
    assert ros.wait_until(lambda: sim.device.time_s > 0.8 and sim.device.last_truth() is not None
                          and abs(sim.device.last_truth().accel[0, 0]) > 5, 10)
    resp = ros.call(Trigger, "/" + topics.CAPTURE_RAW, Trigger.Request())
    assert resp.success and "30 Hz" in resp.message, resp.message
    assert ros.wait_until(lambda: list(tmp_path.glob("raw_*.npz")), 30)
    rec = read_recording(next(tmp_path.glob("raw_*.npz")))
    layout = node.config.accelerometers.layout
    assert rec.channels == layout.names and rec.meta["motion"] == "LineSinkX"
    est = AccelEstimator(layout, harmonics=6).from_recording(rec, 0)
    assert est.phasors.shape[1] == 6 and abs(est.phasors[0, 0]) > 1.0  # the plate's p''x, read from raw samples


def test_a_correction_learned_for_another_goal_of_the_same_name_is_never_applied(ros, sim):
    """The field planner names every motion "mpc": a correction in flight for the goal before must not
    land on the next one (the goal key in HarmonicCorrection names the motion itself)."""
    import numpy as np
    from ppod_msgs.msg import HarmonicCorrection
    from ppod_msgs.srv import SetPlateMotion

    from ppod_nodes.common import qos, topics
    from ppod_ros.motion import PlateMotion

    node = _node(ros, sim)
    first = PlateMotion.from_yaml_text(LINESINKX)
    second = PlateMotion.from_yaml_text(LINESINKX.replace("[10, 0, 0, 0, 100, 0]", "[8, 0, 0, 0, 80, 0]"))
    for motion in (first, second):
        resp = ros.call(SetPlateMotion, "/" + topics.SET_MOTION, _request(motion.to_yaml()))
        assert resp.accepted, resp.reason
    pub = node.create_publisher(HarmonicCorrection, topics.CORRECTION, qos.COMMANDS)

    def correction(key: bytes, amps: float) -> HarmonicCorrection:
        msg = HarmonicCorrection(goal_name="LineSinkX", iteration=1, absolute=True, k=[1])
        msg.real_a, msg.imag_a = [amps] * 6, [0.0] * 6
        msg.goal_key = list(key)
        return msg

    pub.publish(correction(first.key, 0.1))      # learned for the goal before: same name, refused
    ros.wait_until(lambda: False, 0.5)
    assert not np.any(node.gen.applied_correction_a)
    pub.publish(correction(second.key, 0.1))     # for the goal playing: applied
    assert ros.wait_until(lambda: node.gen.applied_correction_a is not None
                          and np.any(node.gen.applied_correction_a), 3)


def test_a_generator_destroyed_without_its_shutdown_stops_its_heartbeats(ros, sim):
    """Each node test's generator left its heartbeat thread running to the end of the session (9 of
    them starved at the interpreter's exit): a node destroyed while active must not keep the device's
    watchdog fed. Destroyed without the executor, it stops its heartbeats and the device ramps the
    plate down on its watchdog."""
    import threading

    from ppod_msgs.srv import SetPlateMotion

    from ppod_nodes.common import topics
    from ppod_ros.can import DeviceState

    def heartbeat_threads():
        return [t for t in threading.enumerate() if t.name == "ppod-can-heartbeat" and t.is_alive()]

    before = len(heartbeat_threads())
    node = _node(ros, sim)
    resp = ros.call(SetPlateMotion, "/" + topics.SET_MOTION, _request(LINESINKX), timeout_s=10)
    assert resp.accepted, resp.reason
    assert ros.wait_until(lambda: sim.device.state in (DeviceState.RAMPING, DeviceState.ENABLED), 10)
    assert len(heartbeat_threads()) == before + 1
    ros.executor.remove_node(node)
    ros.nodes.remove(node)
    node.destroy_node()
    assert len(heartbeat_threads()) == before
    assert ros.wait_until(lambda: sim.device.state == DeviceState.WATCHDOG, 10)


def test_over_the_bridge_the_generator_heartbeats_from_a_keeper_process(ros, sim, capfd):
    """On a bus a second process can open (the simulator's bridge here, SocketCAN in a lab) the
    generator's heartbeats come from a keeper process whose lease the node renews: a DDS publish that
    held the node's GIL for ~330 ms had tripped the device's watchdog (docs/device.md, "Heartbeat
    keeper"). The plate plays a goal on the keeper's heartbeats and the node reports the keeper's count."""
    from ppod_msgs.srv import SetPlateMotion
    from rclpy.parameter import Parameter

    from ppod_nodes.common import topics
    from ppod_nodes.waveform_generator import WaveformGeneratorNode
    from ppod_ros.can import DeviceState

    node = ros.make(WaveformGeneratorNode, parameter_overrides=[
        Parameter("can_interface", value="remote"), Parameter("can_channel", value=sim.sim.url)])
    node.trigger_configure()
    node.trigger_activate()
    assert node.lifecycle_state == "active"
    keeper = node.link._keeper
    assert keeper is not None
    assert ros.wait_until(keeper.ready, 20)
    resp = ros.call(SetPlateMotion, "/" + topics.SET_MOTION, _request(LINESINKX), timeout_s=10)
    assert resp.accepted, resp.reason
    assert ros.wait_until(lambda: sim.device.state == DeviceState.ENABLED and sim.device.time_s > 2.0, 20)
    renewals = node.link.counters.keeper_renewals
    assert ros.wait_until(lambda: node.link.counters.keeper_renewals > renewals + 5, 5)
    assert sim.device.state == DeviceState.ENABLED          # never WATCHDOG: the keeper beats
    node.trigger_deactivate()
    assert ros.wait_until(lambda: sim.device.state == DeviceState.DISABLED, 5)
    assert keeper.process.poll() is not None                 # ended with the heartbeats
    assert "keeper: sent " in capfd.readouterr().err


def test_a_keeper_asked_for_on_a_bus_one_process_owns_falls_back_to_the_thread_and_says_so(ros, sim, capfd):
    from rclpy.parameter import Parameter

    from ppod_nodes.waveform_generator import WaveformGeneratorNode

    node = ros.make(WaveformGeneratorNode, parameter_overrides=[
        Parameter("can_interface", value="virtual"), Parameter("can_channel", value=sim.channel),
        Parameter("heartbeat_keeper", value="process")])
    node.trigger_configure()
    node.trigger_activate()
    assert node.lifecycle_state == "active"
    assert node.link._keeper is None and node.link._hb_thread.is_alive()
    node.trigger_deactivate()
    assert "cannot be opened by a second process; heartbeats from the node's thread" in capfd.readouterr().err

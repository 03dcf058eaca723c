"""accel_feedback + waveform_generator in-process against the simulated device (default mismatch)."""

import pytest

from tests.support.sim_thread import SimThread

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_feedback_drives_the_plate_to_the_goal_within_one_percent(ros, tmp_path):
    from ppod_msgs.msg import AccelSummary, HarmonicCorrection, PlateAcceleration
    from ppod_msgs.srv import SetPlateMotion
    from rclpy.parameter import Parameter

    from ppod_bench.feedback import simulated_calibration
    from ppod_nodes.accel_feedback import AccelFeedbackNode
    from ppod_nodes.common import qos, topics
    from ppod_nodes.common.convert import motion_to_msg
    from ppod_nodes.waveform_generator import WaveformGeneratorNode
    from ppod_ros.device import default_device_config
    from ppod_ros.estimation.calibration import save_calibration
    from ppod_ros.motion import PlateMotion, acceleration_error

    goal = PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0], name="LineSinkX",
                              ramp_time_s=0.2)
    # The simulated sensors have their default (lab-like) errors: the node uses the array
    # calibration stored for the device, as `ppod calibrate accel --simulated` makes it.
    save_calibration(simulated_calibration(), tmp_path, default_device_config().name)
    with SimThread(seed=4) as sim:
        summaries = ros.collect(AccelSummary, topics.ACCEL_SUMMARIES, qos.STREAM)
        bus = [Parameter("can_interface", value="virtual"), Parameter("can_channel", value=sim.channel)]
        accel = ros.collect(PlateAcceleration, topics.ACCELERATION, qos.STREAM)
        corr = ros.collect(HarmonicCorrection, topics.CORRECTION, qos.COMMANDS)
        gen = ros.make(WaveformGeneratorNode, parameter_overrides=bus)
        fb = ros.make(AccelFeedbackNode, parameter_overrides=[*bus, Parameter("cache_dir", value=str(tmp_path))])
        for node in (gen, fb):
            node.trigger_configure()
            node.trigger_activate()
            assert node.lifecycle_state == "active"
        assert ros.call(SetPlateMotion, "/" + topics.SET_MOTION,
                        SetPlateMotion.Request(motion=motion_to_msg(goal))).accepted
        assert ros.wait_until(lambda: any(a.converged for a in accel), 20), \
            [round(a.error_relative, 4) for a in accel if a.iteration]
        first = next(a for a in accel if a.converged)
        assert first.iteration <= 5 and first.error_relative <= 0.01
        assert first.out_of_goal_relative <= 0.005
        assert corr and all(c.goal_name == "LineSinkX" and c.absolute and bytes(c.goal_key) == goal.key for c in corr)
        # Every learning step carries the plate measured on the device table it was taken on, for the
        # generator to judge the plate-side limits on (docs/device.md).
        steps = [c for c in corr if c.iteration >= 1]
        assert steps and all(c.measured_table_seq >= 1 and len(c.measured_real) >= 6 and
                             len(c.measured_real) == len(c.measured_imag) for c in steps)
        # The plate itself (simulator truth, not the estimate) is within 1% of the goal.
        truth = sim.device.last_truth().accel
        K = truth.shape[0]
        _, rel = acceleration_error(goal.phasor_table(K), truth)
        assert rel <= 0.015
        # Every device summary is published (and so recorded by default) for calibration.
        assert summaries and len(summaries[-1].channels) == 12
        assert len(summaries[-1].real_mps2) == len(summaries[-1].k) * 12
        assert list(tmp_path.rglob("*.npz")), "the converged correction is stored for this goal"
        gen.trigger_deactivate()


def test_a_channel_that_dies_leaves_the_set_once_reported_on_diagnostics_with_its_reason(ros, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from ppod_msgs.srv import SetPlateMotion
    from rclpy.parameter import Parameter

    from ppod_nodes.accel_feedback import AccelFeedbackNode
    from ppod_nodes.common import diagnostics as diag
    from ppod_nodes.common import qos, topics
    from ppod_nodes.common.convert import motion_to_msg
    from ppod_nodes.waveform_generator import WaveformGeneratorNode
    from ppod_ros.motion import PlateMotion

    goal = PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0], name="LineSinkX",
                              ramp_time_s=0.2)
    with SimThread(seed=5) as sim:
        sim.device.sensors.axis[3] = 0.0  # u110.z senses nothing: it reads noise (a broken sensor)
        bus = [Parameter("can_interface", value="virtual"), Parameter("can_channel", value=sim.channel)]
        diags = ros.collect(DiagnosticArray, topics.DIAGNOSTICS, qos.STREAM)
        gen = ros.make(WaveformGeneratorNode, parameter_overrides=bus)
        fb = ros.make(AccelFeedbackNode, parameter_overrides=[*bus, Parameter("cache_dir", value=str(tmp_path))])
        for node in (gen, fb):
            node.trigger_configure()
            node.trigger_activate()
        assert ros.call(SetPlateMotion, "/" + topics.SET_MOTION,
                        SetPlateMotion.Request(motion=motion_to_msg(goal))).accepted

        def channel_set():
            return [s for a in diags for s in a.status if s.name.endswith("channel_set")]

        assert ros.wait_until(lambda: channel_set(), 20)
        status = channel_set()[-1]
        name = fb.loop.estimator.layout.names[3]
        assert status.level == diag.WARN and name in status.message
        assert [v.key for v in status.values] == [name] and "consecutive estimates" in status.values[0].value
        assert fb.loop.channels.active == tuple(n for n in fb.loop.estimator.layout.names if n != name)
        fb.trigger_deactivate()
        gen.trigger_deactivate()

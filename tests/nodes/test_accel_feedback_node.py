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
        assert corr and all(c.goal_name == "LineSinkX" and c.absolute for c in corr)
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

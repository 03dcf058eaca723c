"""Honest parameters: a runtime parameter is applied at once (and logged); every other one is read-only."""

import pytest

pytestmark = pytest.mark.ros


def test_runtime_parameters_apply_and_the_others_are_read_only(ros):
    from rclpy.parameter import Parameter

    from ppod_nodes.field_planner import FieldPlannerNode

    node = ros.make(FieldPlannerNode)
    node.trigger_configure()
    assert node.lifecycle_state == "inactive"
    described = node.describe_parameters(["timeout_s", "device_config", "autostart"])
    assert [d.read_only for d in described] == [False, True, True]
    [ok] = node.set_parameters([Parameter("timeout_s", value=42.0)])
    assert ok.successful and node.params["timeout_s"] == 42.0
    [refused] = node.set_parameters([Parameter("device_config", value="/elsewhere.yaml")])
    assert not refused.successful and "read-only" in refused.reason
    [out_of_range] = node.set_parameters([Parameter("timeout_s", value=0.5)])
    assert not out_of_range.successful
    assert node.params["timeout_s"] == 42.0


def test_a_runtime_rate_change_reaches_the_running_timer(ros, tmp_path):
    import numpy as np
    from rclpy.parameter import Parameter

    from ppod_nodes.part_tracker import PartTrackerNode
    from ppod_ros.vision import CameraConfig
    from ppod_ros.vision.sources import save_npz_recording

    video = tmp_path / "frames.npz"
    cam = CameraConfig()
    save_npz_recording(video, [(np.zeros((cam.height, cam.width), np.uint8), t) for t in (0.0, 0.1, 0.2)])
    node = ros.make(PartTrackerNode, parameter_overrides=[Parameter("source", value="file"),
                                                          Parameter("source_uri", value=str(video))])
    node.trigger_configure()
    node.trigger_activate()
    assert node.lifecycle_state == "active"
    before = node._timer
    [ok] = node.set_parameters([Parameter("source_fps", value=25.0)])
    assert ok.successful
    assert node._timer is not before and node._timer.timer_period_ns == 40_000_000
    node.trigger_deactivate()

"""field_planner in process: PlanField designs, and MovePart closes the loop over tracked poses.

The plate and the camera are stood in for by the full dynamics (ppod_ros.physics.PartDynamics)
driven by whatever PlateMotion goal the node publishes, sampled at 10 Hz of device time into
PartPoseArray messages (what the tracker publishes). No mismatch, no camera noise: this checks the
node's wiring and the loop, the planner's own tests and benchmark cover accuracy in depth.
"""

import math

import numpy as np
import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def _active(ros, node):
    node.trigger_configure()
    node.trigger_activate()
    assert node.lifecycle_state == "active"
    return node


def _two_washers(t: float):
    """A PartPoseArray at device time ``t``: washers 7 and 9 tracked where the lease and latency
    tests keep them (those tests step the planner, not the parts)."""
    from ppod_msgs.msg import PartPose, PartPoseArray

    from ppod_nodes.common.convert import seconds_to_stamp

    msg = PartPoseArray()
    msg.header.stamp = seconds_to_stamp(t)
    for pid, (x, y) in ((7, (-0.04, 0.035)), (9, (0.045, 0.02))):
        p = PartPose(id=pid, label="washer", status=PartPose.STATUS_TRACKED)
        p.pose.x, p.pose.y = x, y
        p.stamp = msg.header.stamp
        msg.parts.append(p)
    return msg


def test_plan_field_designs_a_sink_and_rejects_bad_requests_naming_the_problem(ros):
    from ppod_msgs.srv import PlanField

    from ppod_nodes.common import topics
    from ppod_nodes.common.convert import motion_from_msg
    from ppod_nodes.field_planner import FieldPlannerNode
    from ppod_ros.actuation.planning import GoalPlanner
    from ppod_ros.device import default_device_config

    _active(ros, ros.make(FieldPlannerNode))
    resp = ros.call(PlanField, "/" + topics.PLAN_FIELD,
                    PlanField.Request(field_type="sink", params=[0.02, -0.02, 0.3]), timeout_s=30)
    assert resp.success, resp.reason
    assert resp.r_squared >= 0.98 and 0 < resp.valid_fraction <= 1 and resp.seconds > 0
    GoalPlanner(default_device_config()).plan(motion_from_msg(resp.motion))  # within the device's limits
    bad = ros.call(PlanField, "/" + topics.PLAN_FIELD, PlanField.Request(field_type="vortex", params=[0.0]),
                   timeout_s=30)
    assert not bad.success and "field_type" in bad.reason
    short = ros.call(PlanField, "/" + topics.PLAN_FIELD, PlanField.Request(field_type="sink", params=[0.0, 0.0]),
                     timeout_s=30)
    assert not short.success and "params" in short.reason


def test_move_part_brings_a_point_part_to_the_goal_over_tracked_poses(ros):
    from ppod_msgs.action import MovePart
    from ppod_msgs.msg import PartPose, PartPoseArray
    from ppod_msgs.msg import PlateMotion as PlateMotionMsg

    from ppod_nodes.common import qos, topics
    from ppod_nodes.common.actions import ActionClient
    from ppod_nodes.common.convert import motion_from_msg, seconds_to_stamp
    from ppod_nodes.field_planner import FieldPlannerNode
    from ppod_ros.motion import PlateMotion
    from ppod_ros.parts import Footprint, PointPart
    from ppod_ros.physics import PartDynamics

    _active(ros, ros.make(FieldPlannerNode))
    goals = ros.collect(PlateMotionMsg, topics.GOAL, qos.COMMANDS)
    poses_pub = ros.node.create_publisher(PartPoseArray, topics.PART_POSES, qos.STREAM)
    washer = PointPart(mu=0.3, footprint=Footprint.from_value({"disk": 0.006}))
    dyn = PartDynamics([washer], np.array([[-0.04, 0.035, 0.0]]))
    t = [0.0]

    def publish() -> None:
        s = dyn.state
        msg = PartPoseArray()
        msg.header.stamp = seconds_to_stamp(t[0])
        p = PartPose(id=7, label="washer", status=PartPose.STATUS_TRACKED)
        p.pose.x, p.pose.y = float(s.configurations[0, 0]), float(s.configurations[0, 1])
        p.stamp = msg.header.stamp
        msg.parts.append(p)
        poses_pub.publish(msg)

    for _ in range(5):  # the planner must have seen the part before it accepts a goal for it
        publish()
        ros.wait_until(lambda: False, 0.05)
    client = ActionClient(ros.node, MovePart, "/" + topics.MOVE_PART)
    ros.wait_for_action_server(client)
    unknown = MovePart.Goal(part_id=99)
    assert not ros.wait_future(client.send_goal_async(unknown), 10, "goal").accepted  # not tracked
    goal = MovePart.Goal(part_id=7, position_tolerance_m=1e-3, timeout_s=40.0)
    goal.target.x, goal.target.y = 0.01, -0.015
    feedback = []
    handle = ros.wait_future(client.send_goal_async(goal, feedback_callback=feedback.append), 10, "goal")
    assert handle.accepted
    result = handle.get_result_async()
    while not result.done() and t[0] < 60.0:
        n = len(feedback)
        motion = motion_from_msg(goals[-1]) if goals else PlateMotion.zero()
        dyn.advance(motion, t[0], 0.1)
        t[0] += 0.1
        publish()
        ros.wait_until(lambda n=n: len(feedback) > n or result.done(), 2.0)  # the node stepped on it
    assert result.done(), "MovePart did not finish within 60 s of device time"
    res = result.result().result
    final = dyn.state.configurations[0]
    assert res.success, res.reason
    assert math.hypot(final[0] - 0.01, final[1] + 0.015) <= 1.5e-3
    assert res.position_error_m <= 1e-3
    assert goals, "the planner published plate-motion goals"
    assert {f.feedback.phase for f in feedback} & {"positioning", "holding", "done"}


def test_a_sensorless_move_part_positions_a_part_no_camera_sees(ros):
    from ppod_msgs.action import MovePart
    from ppod_msgs.msg import PlateMotion as PlateMotionMsg
    from rclpy.parameter import Parameter
    from rosgraph_msgs.msg import Clock

    from ppod_nodes.common import qos, topics
    from ppod_nodes.common.actions import ActionClient
    from ppod_nodes.common.convert import motion_from_msg, seconds_to_stamp
    from ppod_nodes.field_planner import FieldPlannerNode
    from ppod_ros.motion import PlateMotion
    from ppod_ros.parts import PointPart
    from ppod_ros.physics import PartDynamics

    # Device time from /clock, as under `ppod up --sim`, stepped here as fast as the node keeps up.
    _active(ros, ros.make(FieldPlannerNode, parameter_overrides=[Parameter("use_sim_time", value=True)]))
    clock_pub = ros.node.create_publisher(Clock, "/clock", 10)
    goals = ros.collect(PlateMotionMsg, topics.GOAL, qos.COMMANDS)
    dyn = PartDynamics([PointPart(0.3)], np.array([[-0.05, 0.04, 0.0]]))
    t = [0.0]
    clock_pub.publish(Clock(clock=seconds_to_stamp(0.0)))
    client = ActionClient(ros.node, MovePart, "/" + topics.MOVE_PART)
    ros.wait_for_action_server(client)
    goal = MovePart.Goal(part_id=3, sensorless=True)  # no tracker: no poses at all
    goal.target.x, goal.target.y = 0.01, -0.015
    feedback = []
    handle = ros.wait_future(client.send_goal_async(goal, feedback_callback=feedback.append), 30, "goal")
    assert handle.accepted
    result = handle.get_result_async()
    silent = 0   # ticks in a row without feedback: a node that stopped stepping fails here, not in 10 min
    while not result.done() and t[0] < 60.0:
        n = len(feedback)
        motion = motion_from_msg(goals[-1]) if goals else PlateMotion.zero()
        dyn.advance(motion, t[0], 0.1)
        t[0] += 0.1
        clock_pub.publish(Clock(clock=seconds_to_stamp(t[0])))
        stepped = ros.wait_until(lambda n=n: len(feedback) > n or result.done(), 1.0)  # the node's timer stepped
        silent = 0 if stepped else silent + 1
        assert silent < 10, f"the node stopped stepping the sensorless goal at t = {t[0]:.1f} s"
    assert result.done(), "the sensorless MovePart did not finish within 60 s of device time"
    res = result.result().result
    assert res.success, res.reason
    assert "sensorless" in res.reason and math.isnan(res.position_error_m)  # nothing seen, nothing claimed
    final = dyn.state.configurations[0]
    assert math.hypot(final[0] - 0.01, final[1] + 0.015) <= 1e-3
    assert len(goals) == 1 and {f.feedback.phase for f in feedback} == {"positioning", "done"}


def test_move_parts_brings_two_parts_to_their_own_goals_and_rejects_colliding_goals(ros):
    from geometry_msgs.msg import Pose2D
    from ppod_msgs.action import MoveParts
    from ppod_msgs.msg import PartPose, PartPoseArray, PlannerProgress
    from ppod_msgs.msg import PlateMotion as PlateMotionMsg

    from ppod_nodes.common import qos, topics
    from ppod_nodes.common.actions import ActionClient
    from ppod_nodes.common.convert import motion_from_msg, seconds_to_stamp
    from ppod_nodes.field_planner import FieldPlannerNode
    from ppod_ros.motion import PlateMotion
    from ppod_ros.parts import Footprint, PointPart
    from ppod_ros.physics import PartDynamics

    _active(ros, ros.make(FieldPlannerNode))
    goals = ros.collect(PlateMotionMsg, topics.GOAL, qos.COMMANDS)
    progress = ros.collect(PlannerProgress, topics.PLANNER_PROGRESS, qos.STREAM)
    poses_pub = ros.node.create_publisher(PartPoseArray, topics.PART_POSES, qos.STREAM)
    washer = PointPart(mu=0.3, footprint=Footprint.from_value({"disk": 0.006}))
    dyn = PartDynamics([washer, washer], np.array([[-0.04, 0.035, 0.0], [0.045, 0.02, 0.0]]))
    t = [0.0]

    def publish() -> None:
        s = dyn.state
        msg = PartPoseArray()
        msg.header.stamp = seconds_to_stamp(t[0])
        for i, pid in enumerate((7, 9)):
            p = PartPose(id=pid, label="washer", status=PartPose.STATUS_TRACKED)
            p.pose.x, p.pose.y = float(s.configurations[i, 0]), float(s.configurations[i, 1])
            p.stamp = msg.header.stamp
            msg.parts.append(p)
        poses_pub.publish(msg)

    for _ in range(5):
        publish()
        ros.wait_until(lambda: False, 0.05)
    client = ActionClient(ros.node, MoveParts, "/" + topics.MOVE_PARTS)
    ros.wait_for_action_server(client)
    clash = MoveParts.Goal(part_ids=[7, 9], targets=[Pose2D(x=0.0, y=0.0), Pose2D(x=0.004, y=0.0)])
    assert not ros.wait_future(client.send_goal_async(clash), 10, "goal").accepted  # footprints overlap
    untracked = MoveParts.Goal(part_ids=[7, 99], targets=[Pose2D(x=0.0, y=0.0), Pose2D(x=0.03, y=0.0)])
    assert not ros.wait_future(client.send_goal_async(untracked), 10, "goal").accepted
    goal = MoveParts.Goal(part_ids=[7, 9], targets=[Pose2D(x=-0.02, y=0.01), Pose2D(x=0.02, y=-0.01)],
                          position_tolerance_m=[2e-3, 2e-3], timeout_s=50.0)
    feedback = []
    handle = ros.wait_future(client.send_goal_async(goal, feedback_callback=feedback.append), 10, "goal")
    assert handle.accepted
    result = handle.get_result_async()
    while not result.done() and t[0] < 55.0:
        n = len(feedback)
        motion = motion_from_msg(goals[-1]) if goals else PlateMotion.zero()
        dyn.advance(motion, t[0], 0.1)
        t[0] += 0.1
        publish()
        ros.wait_until(lambda n=n: len(feedback) > n or result.done(), 5.0)
    assert result.done(), "MoveParts did not finish within 55 s of device time"
    res = result.result().result
    assert res.success, res.reason
    assert list(res.part_ids) == [7, 9] and all(res.reached) and all(v >= 0 for v in res.time_to_goal_s)
    final = dyn.state.configurations
    assert math.hypot(final[0, 0] + 0.02, final[0, 1] - 0.01) <= 2.5e-3
    assert math.hypot(final[1, 0] - 0.02, final[1, 1] + 0.01) <= 2.5e-3
    assert feedback and list(feedback[-1].feedback.part_ids) == [7, 9]
    # Every feedback carries the last replanning step's time, also between replanning steps (the
    # demo prints it: it used to say "replanned in 0 ms" at every line but the first).
    assert all(f.feedback.plan_ms > 0 for f in feedback)
    # The same feedback on the plain, recordable topic.
    assert ros.wait_until(lambda: len(progress) > 0, 5.0)
    assert {p.action for p in progress} == {"move_parts"} and list(progress[-1].part_ids) == [7, 9]
    assert {p.text for p in progress} <= {f.feedback.text for f in feedback}


def test_a_late_plan_stops_the_plate_at_the_lease_and_is_dropped(ros, monkeypatch):
    """Replanning that takes longer than ``plan_lease_s`` of device time (a busy host, a stall)
    must not leave a motion playing that was planned on old poses: the plate stops at the first
    frame past the lease, the late plan is never published, and the task replans from rest."""
    import threading

    from geometry_msgs.msg import Pose2D
    from ppod_msgs.action import MoveParts
    from ppod_msgs.msg import PartPoseArray
    from ppod_msgs.msg import PlateMotion as PlateMotionMsg

    import ppod_nodes.field_planner as fp
    from ppod_nodes.common import qos, topics
    from ppod_nodes.common.actions import ActionClient
    from ppod_nodes.common.convert import motion_from_msg

    gate = threading.Event()
    plans = []

    class SlowSecondPlan(fp.MultiTask):
        def _plan(self, t_s, poses, statuses):
            plans.append(t_s)
            if len(plans) == 2:
                gate.wait(60)  # the second replanning "takes" until the test releases it
            return super()._plan(t_s, poses, statuses)

    monkeypatch.setattr(fp, "MultiTask", SlowSecondPlan)
    _active(ros, ros.make(fp.FieldPlannerNode))
    goals = ros.collect(PlateMotionMsg, topics.GOAL, qos.COMMANDS)
    poses_pub = ros.node.create_publisher(PartPoseArray, topics.PART_POSES, qos.STREAM)

    def frame(t: float) -> None:
        poses_pub.publish(_two_washers(t))
        ros.wait_until(lambda: False, 0.1)

    frame(0.0)
    client = ActionClient(ros.node, MoveParts, "/" + topics.MOVE_PARTS)
    ros.wait_for_action_server(client)
    goal = MoveParts.Goal(part_ids=[7, 9], targets=[Pose2D(x=-0.02, y=0.01), Pose2D(x=0.02, y=-0.01)],
                          timeout_s=50.0)
    feedback = []
    handle = ros.wait_future(client.send_goal_async(goal, feedback_callback=feedback.append), 10, "goal")
    assert handle.accepted
    t = 0.0
    while not goals and t < 0.4:
        t = round(t + 0.1, 1)
        frame(t)
    assert ros.wait_until(lambda: len(goals) == 1, 30.0), "the first plan published no motion"
    assert not motion_from_msg(goals[0]).is_zero()
    first = t
    while len(plans) < 2:  # up to the second replanning, 0.5 s after the first
        t = round(t + 0.1, 1)
        frame(t)
    started = plans[1]
    while t < plans[0] + 1.0 - 1e-9:  # within the lease (1 s of device time from the poses the
        t = round(t + 0.1, 1)         # motion playing was planned on): it plays on
        frame(t)
    assert len(goals) == 1, "the plate was stopped within the lease"
    frame(round(t + 0.1, 1))  # the first frame past the lease
    assert ros.wait_until(lambda: len(goals) == 2, 10.0), "no stop past the lease"
    assert motion_from_msg(goals[1]).is_zero()
    gate.set()  # the late plan comes: it was made on poses from before the stop and is dropped
    ros.wait_until(lambda: False, 0.5)
    assert len(goals) == 2, "the late plan was published"
    t = round(t + 0.1, 1)
    while len(goals) == 2 and t < started + 5.0:  # replanned from rest (after the planner's dwell)
        t = round(t + 0.1, 1)
        n = len(feedback)
        frame(t)
        ros.wait_until(lambda n=n: len(feedback) > n, 5.0)  # the node stepped on this frame
    assert len(goals) == 3, "no new plan after the stop"
    assert not motion_from_msg(goals[2]).is_zero() and plans[-1] > plans[0] + 1.0
    assert plans[0] <= first < started
    ros.wait_future(handle.cancel_goal_async(), 10, "cancel")


def test_a_step_that_cannot_be_applied_ends_the_goal_instead_of_hanging_it(ros, monkeypatch):
    """A sensorless MovePart whose step the node cannot publish (a bug: a step without the fields
    the node reads; a Task's step once met ``step.plan_ms``) ends failed with the reason (the node
    asks the device to stop the plate, as for any failed goal), and the node accepts the next goal;
    it used to wait for steps forever."""
    from ppod_msgs.action import MovePart

    import ppod_nodes.field_planner as fp
    from ppod_nodes.common import topics
    from ppod_nodes.common.actions import ActionClient

    broken = [True]
    real = fp.SensorlessTask.step

    def step(self, t_s, poses=None):
        out = real(self, t_s, poses)
        return object() if broken[0] else out   # no phase, text, motion ...

    monkeypatch.setattr(fp.SensorlessTask, "step", step)
    node = _active(ros, ros.make(fp.FieldPlannerNode))
    client = ActionClient(ros.node, MovePart, "/" + topics.MOVE_PART)
    ros.wait_for_action_server(client)
    goal = MovePart.Goal(part_id=3, sensorless=True)
    goal.target.x, goal.target.y = 0.01, -0.015
    handle = ros.wait_future(client.send_goal_async(goal), 30, "goal")
    assert handle.accepted
    result = handle.get_result_async()
    assert ros.wait_until(result.done, 20.0), "the goal did not end after its step failed to apply"
    res = result.result().result
    assert not res.success and "internal error applying a step" in res.reason
    assert node.running is None
    broken[0] = False  # the node lives on: the next goal runs
    handle = ros.wait_future(client.send_goal_async(goal), 30, "goal")
    assert handle.accepted
    ros.wait_future(handle.cancel_goal_async(), 10, "cancel")


def test_a_planner_error_ends_the_goal_and_stops_the_plate_without_killing_the_node(ros, monkeypatch):
    """An unexpected exception in a planning step (a bug) aborts the goal with the reason and stops
    the plate; the node lives on and accepts the next goal."""
    from geometry_msgs.msg import Pose2D
    from ppod_msgs.action import MoveParts
    from ppod_msgs.msg import PartPose, PartPoseArray

    import ppod_nodes.field_planner as fp
    from ppod_nodes.common import qos, topics
    from ppod_nodes.common.actions import ActionClient
    from ppod_nodes.common.convert import seconds_to_stamp

    broken = [True]

    class Buggy(fp.MultiTask):
        def _plan(self, t_s, poses, statuses):
            if broken[0]:
                raise ZeroDivisionError("a planner bug")
            return super()._plan(t_s, poses, statuses)

    monkeypatch.setattr(fp, "MultiTask", Buggy)
    node = _active(ros, ros.make(fp.FieldPlannerNode))
    poses_pub = ros.node.create_publisher(PartPoseArray, topics.PART_POSES, qos.STREAM)
    t = [0.0]

    def frame() -> None:
        msg = PartPoseArray()
        msg.header.stamp = seconds_to_stamp(t[0])
        p = PartPose(id=7, label="washer", status=PartPose.STATUS_TRACKED)
        p.pose.x, p.pose.y = -0.04, 0.035
        msg.parts.append(p)
        poses_pub.publish(msg)
        t[0] += 0.1
        ros.wait_until(lambda: False, 0.1)

    frame()
    client = ActionClient(ros.node, MoveParts, "/" + topics.MOVE_PARTS)
    ros.wait_for_action_server(client)
    goal = MoveParts.Goal(part_ids=[7], targets=[Pose2D(x=-0.02, y=0.01)], timeout_s=30.0)
    handle = ros.wait_future(client.send_goal_async(goal), 10, "goal")
    assert handle.accepted
    result = handle.get_result_async()
    for _ in range(50):
        if result.done():
            break
        frame()
    assert result.done(), "the goal did not end after the planner's error"
    res = result.result().result
    assert not res.success and "internal error" in res.reason and "ZeroDivisionError" in res.reason
    assert node.running is None
    broken[0] = False  # the node lives on: the next goal runs
    handle = ros.wait_future(client.send_goal_async(goal), 10, "goal")
    assert handle.accepted
    ros.wait_future(handle.cancel_goal_async(), 10, "cancel")


def test_the_node_reports_each_published_plan_s_latency_in_device_time(ros, monkeypatch):
    """The planner lowers its approach gain for its command latency (MpcSettings.latency_ref_s): the
    node reports, with each motion it publishes, the device time from the frame's step to the
    publication. Here the first plan "takes" while /clock advances 0.4 s."""
    import threading

    from ppod_msgs.msg import PartPoseArray
    from ppod_msgs.msg import PlateMotion as PlateMotionMsg
    from rclpy.parameter import Parameter
    from rosgraph_msgs.msg import Clock

    import ppod_nodes.field_planner as fp
    from ppod_nodes.common import qos, topics
    from ppod_nodes.common.convert import seconds_to_stamp

    gate, planning = threading.Event(), threading.Event()
    reported = []

    class SlowFirstPlan(fp.MultiTask):
        def _plan(self, t_s, poses, statuses):
            planning.set()
            gate.wait(60)   # the first replanning "takes" until the test releases it
            return super()._plan(t_s, poses, statuses)

        def command_latency(self, latency_s):
            reported.append(latency_s)
            super().command_latency(latency_s)

    monkeypatch.setattr(fp, "MultiTask", SlowFirstPlan)
    node = _active(ros, ros.make(fp.FieldPlannerNode, parameter_overrides=[Parameter("use_sim_time", value=True)]))
    clock_pub = ros.node.create_publisher(Clock, "/clock", 10)
    goals = ros.collect(PlateMotionMsg, topics.GOAL, qos.COMMANDS)
    poses_pub = ros.node.create_publisher(PartPoseArray, topics.PART_POSES, qos.STREAM)

    def clock(t: float) -> None:
        # Published until the node's clock shows it (the first message can precede discovery).
        def shown() -> bool:
            clock_pub.publish(Clock(clock=seconds_to_stamp(t)))
            return ros.wait_until(lambda: abs(node._now() - t) < 1e-9, 0.2)

        assert ros.wait_until(shown, 10.0), "the node's clock did not follow /clock"

    def frame(t: float) -> None:
        poses_pub.publish(_two_washers(t))

    clock(1.0)

    def seen() -> bool:   # published until the node has poses (the first can precede discovery)
        frame(1.0)
        return ros.wait_until(lambda: node._poses is not None, 0.2)

    assert ros.wait_until(seen, 10.0), "the node never received poses"
    handle, _, _ = _send_two_washer_goal(ros)
    if not ros.wait_until(planning.is_set, 1.0):   # planned at once on the poses it has, or on the next frame
        frame(1.0)
    assert ros.wait_until(planning.is_set, 10.0), "the node did not plan"
    clock(1.4)          # device time passes while the plan is computed (submitted at 1.0)
    gate.set()
    assert ros.wait_until(lambda: len(goals) == 1, 30.0), "the plan published no motion"
    assert ros.wait_until(lambda: len(reported) == 1, 10.0), "the published plan's latency was not reported"
    assert reported[0] == pytest.approx(0.4, abs=1e-6)
    ros.wait_future(handle.cancel_goal_async(), 10, "cancel")


def _two_washer_goal(ros, node_class, overrides=()):
    """An active ``node_class`` (a FieldPlannerNode), the motions it publishes, a function that
    publishes the next _two_washers frame (device time +0.1 s), its clock [t], and an accepted
    MoveParts goal handle for the two washers with the client and goal that sent it."""
    from ppod_msgs.msg import PartPoseArray
    from ppod_msgs.msg import PlateMotion as PlateMotionMsg

    from ppod_nodes.common import qos, topics

    node = _active(ros, ros.make(node_class, parameter_overrides=list(overrides)))
    goals = ros.collect(PlateMotionMsg, topics.GOAL, qos.COMMANDS)
    poses_pub = ros.node.create_publisher(PartPoseArray, topics.PART_POSES, qos.STREAM)
    t = [0.0]

    def frame() -> None:
        poses_pub.publish(_two_washers(t[0]))
        t[0] = round(t[0] + 0.1, 1)
        ros.wait_until(lambda: False, 0.1)

    frame()
    handle, client, goal = _send_two_washer_goal(ros)
    return node, goals, frame, t, handle, client, goal


def _send_two_washer_goal(ros):
    """Send the MoveParts goal of the lease, latency and stuck-step tests (washers 7 and 9) and
    wait until it is accepted: (handle, client, goal)."""
    from geometry_msgs.msg import Pose2D
    from ppod_msgs.action import MoveParts

    from ppod_nodes.common import topics
    from ppod_nodes.common.actions import ActionClient

    client = ActionClient(ros.node, MoveParts, "/" + topics.MOVE_PARTS)
    ros.wait_for_action_server(client)
    goal = MoveParts.Goal(part_ids=[7, 9], targets=[Pose2D(x=-0.02, y=0.01), Pose2D(x=0.02, y=-0.01)],
                          timeout_s=50.0)
    handle = ros.wait_future(client.send_goal_async(goal), 10, "goal")
    assert handle.accepted
    return handle, client, goal


def _second_plan_hangs(monkeypatch, fp):
    """Make ``fp.MultiTask`` a planner whose second replanning step does not come back until the
    returned event is set (the test sets it when done): (event, device times of the steps planned)."""
    import threading

    gate = threading.Event()
    hang = [True]
    plans = []

    class HangsOnce(fp.MultiTask):
        def _plan(self, t_s, poses, statuses):
            plans.append(t_s)
            if len(plans) == 2 and hang[0]:
                hang[0] = False
                gate.wait(120)  # the second replanning never comes back while the test runs
            return super()._plan(t_s, poses, statuses)

    monkeypatch.setattr(fp, "MultiTask", HangsOnce)
    return gate, plans


def test_a_planning_step_that_never_returns_ends_the_goal_and_the_node_plans_the_next(ros, monkeypatch):
    """Regression (a demo run on the simulated device): the planning thread did not come back from a
    step, the lease stopped the plate, and the MoveParts goal hung for 5 minutes until the demo's
    wall-clock guard cancelled it. Past ``plan_stuck_s`` of device time the goal ends as failed with
    the reason, the thread is abandoned, and the next goal plans on a new one."""
    from rclpy.parameter import Parameter

    import ppod_nodes.field_planner as fp
    from ppod_nodes.common.convert import motion_from_msg

    gate, plans = _second_plan_hangs(monkeypatch, fp)
    try:
        node, goals, frame, t, handle, client, goal = _two_washer_goal(
            ros, fp.FieldPlannerNode, [Parameter("plan_stuck_s", value=2.0)])
        result = handle.get_result_async()
        while len(plans) < 2 and t[0] < 5.0:
            frame()
        assert len(plans) == 2, "the second replanning never started"
        hung_at = plans[1]
        while not result.done() and t[0] < hung_at + 6.0:
            frame()
        assert result.done(), "the goal did not end while its planning step hung"
        res = result.result().result
        assert not res.success and "plan_stuck_s" in res.reason
        assert t[0] > hung_at + 2.0 - 1e-9   # not before plan_stuck_s of device time
        assert node.running is None and node._abandoned == 1
        # The node lives on: the next goal plans (on a new thread) while the old one is still stuck.
        published = len(goals)
        handle = ros.wait_future(client.send_goal_async(goal), 10, "goal")
        assert handle.accepted
        for _ in range(10):
            frame()
            if len(goals) > published and not motion_from_msg(goals[-1]).is_zero():
                break
        assert len(goals) > published and not motion_from_msg(goals[-1]).is_zero(), "the next goal did not plan"
        ros.wait_future(handle.cancel_goal_async(), 10, "cancel")
    finally:
        gate.set()


def test_a_finished_step_whose_wake_up_is_lost_is_applied_on_the_next_frame(ros, monkeypatch):
    """The planning thread wakes the executor with a guard condition; a wake-up that never arrives
    must cost a frame, not the goal."""
    import ppod_nodes.field_planner as fp
    from ppod_nodes.common.convert import motion_from_msg

    monkeypatch.setattr(fp.FieldPlannerNode, "_signal_step_done", lambda self, future: None)
    _, goals, frame, _, handle, _, _ = _two_washer_goal(ros, fp.FieldPlannerNode)
    published = len(goals)
    for _ in range(100):   # the first step plans for up to a few seconds of wall time
        frame()
        if len(goals) > published:
            break
    assert len(goals) > published and not motion_from_msg(goals[-1]).is_zero(), \
        "a finished step was never applied"
    ros.wait_future(handle.cancel_goal_async(), 10, "cancel")


def test_a_stuck_step_of_a_cancelled_goal_does_not_block_the_next_goal(ros, monkeypatch):
    """A goal cancelled while its planning step hangs ends at once; the next goal must not wait on
    that step forever: past ``plan_stuck_s`` the thread is abandoned and the new goal plans."""
    from rclpy.parameter import Parameter

    import ppod_nodes.field_planner as fp
    from ppod_nodes.common.convert import motion_from_msg

    gate, plans = _second_plan_hangs(monkeypatch, fp)
    try:
        node, goals, frame, t, handle, client, goal = _two_washer_goal(
            ros, fp.FieldPlannerNode, [Parameter("plan_stuck_s", value=2.0)])
        while len(plans) < 2 and t[0] < 5.0:
            frame()
        assert len(plans) == 2, "the second replanning never started"
        hung_at = plans[1]
        ros.wait_future(handle.cancel_goal_async(), 10, "cancel")
        frame()
        assert node.running is None, "the cancel did not end the goal"
        published = len(goals)
        handle = ros.wait_future(client.send_goal_async(goal), 10, "goal")
        assert handle.accepted
        while t[0] < hung_at + 6.0 and not (len(goals) > published and not motion_from_msg(goals[-1]).is_zero()):
            frame()
        assert len(goals) > published and not motion_from_msg(goals[-1]).is_zero(), \
            "the next goal waited on the cancelled goal's stuck step"
        assert node._abandoned == 1 and node.running is not None   # the new goal runs on
        ros.wait_future(handle.cancel_goal_async(), 10, "cancel")
    finally:
        gate.set()


def test_malformed_move_parts_goals_and_poses_never_stop_the_node(ros):
    """Goals with non-finite, out-of-range or inconsistent fields, and tracked poses that are NaN
    or infinite: each goal is rejected or ends (cancelled at the latest), no callback raises (the
    harness fails the test at once if one does: in the stack the node would exit), and a good goal
    is still accepted at the end. Bounded: 11 goals, at most 20 frames each."""
    from geometry_msgs.msg import Pose2D
    from ppod_msgs.action import MoveParts
    from ppod_msgs.msg import PartPose, PartPoseArray

    import ppod_nodes.field_planner as fp
    from ppod_nodes.common import qos, topics
    from ppod_nodes.common.actions import ActionClient
    from ppod_nodes.common.convert import seconds_to_stamp

    node = _active(ros, ros.make(fp.FieldPlannerNode))
    poses_pub = ros.node.create_publisher(PartPoseArray, topics.PART_POSES, qos.STREAM)
    t = [0.0]
    nan, inf = float("nan"), float("inf")

    def frame() -> None:
        msg = PartPoseArray()
        msg.header.stamp = seconds_to_stamp(t[0])
        for pid, x, y in ((7, -0.04, 0.035), (8, nan, 0.01), (9, inf, -inf)):
            p = PartPose(id=pid, label="washer", status=PartPose.STATUS_TRACKED)
            p.pose.x, p.pose.y = x, y
            msg.parts.append(p)
        poses_pub.publish(msg)
        t[0] += 0.1
        ros.wait_until(lambda: False, 0.05)

    for _ in range(3):
        frame()
    client = ActionClient(ros.node, MoveParts, "/" + topics.MOVE_PARTS)
    ros.wait_for_action_server(client)
    ok = Pose2D(x=-0.02, y=0.01)
    bad = [
        MoveParts.Goal(part_ids=[7], targets=[]),                                   # lengths differ
        MoveParts.Goal(part_ids=[7], targets=[Pose2D(x=nan, y=0.0)]),
        MoveParts.Goal(part_ids=[7], targets=[Pose2D(x=inf, y=0.0)]),
        MoveParts.Goal(part_ids=[7], targets=[Pose2D(x=1.0, y=1.0)]),              # off the plate
        MoveParts.Goal(part_ids=[7, 7], targets=[ok, Pose2D(x=0.02, y=-0.01)]),    # one part twice
        MoveParts.Goal(part_ids=[7], targets=[ok], position_tolerance_m=[-1.0]),
        MoveParts.Goal(part_ids=[7], targets=[ok], position_tolerance_m=[nan]),
        MoveParts.Goal(part_ids=[7], targets=[ok], use_orientation=[True], orientation_tolerance_rad=[inf]),
        MoveParts.Goal(part_ids=[7], targets=[ok], timeout_s=nan),
        MoveParts.Goal(part_ids=[7], targets=[ok], timeout_s=-5.0),
        MoveParts.Goal(part_ids=[8, 9], targets=[ok, Pose2D(x=0.02, y=-0.01)]),     # tracked, never seen
    ]
    outcomes = []
    for goal in bad:
        handle = ros.wait_future(client.send_goal_async(goal), 10, "goal")
        if not handle.accepted:
            outcomes.append("rejected")
            continue
        result = handle.get_result_async()
        for _ in range(20):
            if result.done():
                break
            frame()
        if not result.done():
            ros.wait_future(handle.cancel_goal_async(), 10, "cancel")
            for _ in range(20):
                if result.done():
                    break
                frame()
        assert result.done(), f"goal {goal} neither ended nor cancelled"
        outcomes.append("ended")
        assert ros.wait_until(lambda: node.running is None, 5.0)
    # Every inconsistent, non-finite or out-of-range goal is rejected up front; the parts tracked but
    # never seen are accepted (they are tracked) and the goal ends.
    assert outcomes == ["rejected"] * 10 + ["ended"], outcomes
    assert node.lifecycle_state == "active"
    handle = ros.wait_future(client.send_goal_async(MoveParts.Goal(part_ids=[7], targets=[ok])), 10, "goal")
    assert handle.accepted
    ros.wait_future(handle.cancel_goal_async(), 10, "cancel")

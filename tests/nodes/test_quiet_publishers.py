"""PPOD nodes' publishers carry no QoS-event handlers (each one is a waitable the executor walks at
every wake-up), and an incompatible QoS is still reported where messages are lost: on the
subscribing side."""

import threading

import pytest

pytestmark = pytest.mark.ros


def test_publishers_quiet_subscriptions_keep_their_handlers_clock_quiet(ros):
    from ppod_nodes.field_planner import FieldPlannerNode

    node = FieldPlannerNode(context=ros.context, parameter_overrides=[])
    try:
        from rclpy.parameter import Parameter

        node.set_parameters([Parameter("use_sim_time", Parameter.Type.BOOL, True)])   # the /clock subscription
        pubs = list(node.publishers)
        assert any(p.topic_name == "/parameter_events" for p in pubs)
        assert pubs and all(p.event_handlers == [] for p in pubs)
        subs = {s.topic_name: s for s in node.subscriptions}
        assert subs["/clock"].event_handlers == []
        others = [s for name, s in subs.items() if name != "/clock"]
        assert others and all(len(s.event_handlers) >= 1 for s in others)
    finally:
        node.destroy_node()


def test_lifecycle_publishers_quiet(ros):
    from ppod_nodes.waveform_generator import WaveformGeneratorNode

    node = WaveformGeneratorNode(context=ros.context)
    try:
        assert node._managed_entities   # its lifecycle publishers
        assert all(p.event_handlers == [] for p in node.publishers)
    finally:
        node.destroy_node()


def test_incompatible_qos_still_reported_on_the_subscribing_side(ros):
    from rclpy.event_handler import SubscriptionEventCallbacks
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    from ppod_nodes.common.events import QuietPublishers

    class Quiet(QuietPublishers, Node):
        pass

    quiet = Quiet("quiet_publisher", context=ros.context)
    ros.add(quiet)
    seen = threading.Event()
    quiet.create_publisher(String, "/test/qos_mismatch", QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
    ros.helper.create_subscription(
        String, "/test/qos_mismatch", lambda _m: None, QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE),
        event_callbacks=SubscriptionEventCallbacks(incompatible_qos=lambda _e: seen.set()))
    assert seen.wait(10.0)

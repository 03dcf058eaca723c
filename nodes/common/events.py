"""Publishers without rclpy's default QoS-event handlers: a cheaper executor in every PPOD process.

By default rclpy gives every publisher and every subscription two event handlers (incompatible QoS,
incompatible type) that only log a warning. Each is a waitable the executor walks in Python at
every wake-up, and under ``use_sim_time`` every node wakes at each /clock message (100 Hz). Measured
with 20 publishers and 20 subscriptions receiving 190 messages/s: 2.3 ms of CPU per message with
the defaults, 1.0 ms without (``docs/ros.md``, "Executor cost").

What the warning is for survives: when a publisher and a subscription cannot match, *both* sides
are told by the middleware, so the subscribing side (the one that loses messages: a lab's tool on
our topics, or our nodes on a lab's goal topic) still logs "offering incompatible QoS". PPOD's
publishers therefore drop their handlers (:class:`QuietPublishers`); subscriptions keep them, except
the time source's /clock (rclpy's own QoS, our simulator's publisher) and a recorder's, which takes
whatever QoS the publishers offer (:func:`quiet_subscription`).
"""

from __future__ import annotations

from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks

from ppod_nodes.common import topics


def quiet_publisher() -> PublisherEventCallbacks:
    """Event callbacks for a publisher with no handler at all (none given, no default)."""
    return PublisherEventCallbacks(use_default_callbacks=False)


def quiet_subscription() -> SubscriptionEventCallbacks:
    """Event callbacks for a subscription with no handler at all (none given, no default)."""
    return SubscriptionEventCallbacks(use_default_callbacks=False)


class QuietPublishers:
    """Node mixin (before rclpy's Node in the bases): publishers made without default event handlers,
    the node's own (/parameter_events) and lifecycle publishers included, and the /clock subscription
    ``use_sim_time`` makes, unless callbacks are given."""

    def create_subscription(self, msg_type, topic, *args, event_callbacks=None, **kwargs):
        if event_callbacks is None and topic == topics.CLOCK:   # as rclpy's TimeSource names it
            event_callbacks = quiet_subscription()
        return super().create_subscription(msg_type, topic, *args, event_callbacks=event_callbacks, **kwargs)

    def create_publisher(self, *args, event_callbacks=None, **kwargs):
        return super().create_publisher(*args, event_callbacks=event_callbacks or quiet_publisher(), **kwargs)

    def create_lifecycle_publisher(self, *args, event_callbacks=None, **kwargs):
        # rclpy's LifecycleNode calls Node.create_publisher directly, past this class's override.
        return super().create_lifecycle_publisher(*args, event_callbacks=event_callbacks or quiet_publisher(),
                                                  **kwargs)

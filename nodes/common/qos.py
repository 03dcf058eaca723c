"""QoS profiles used across the PPOD topics (one place, so publishers and subscribers match)."""

from __future__ import annotations

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)

#: Latched state: late joiners get the last message (active motion, status, camera info).
LATCHED = QoSProfile(
    depth=1,
    history=HistoryPolicy.KEEP_LAST,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

#: Commands and goals: reliable, a short queue, no latching (an old goal must not replay).
COMMANDS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)

#: Streams (poses, accelerations, diagnostics): reliable, keep a few.
STREAM = QoSProfile(depth=20, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE)

#: A stream whose reader wants the newest message only (the field planner's poses): a replanning step
#: that takes longer than a camera frame must not leave a backlog of old frames to plan on (seen in the
#: demo on a loaded machine: with replanning at 0.3-0.9 s and a queue of 20, the node stepped through
#: queued frames in bursts, five within one clock tick, while the parts swung through their goals).
LATEST = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE)

#: Camera images: best effort, newest only.
SENSOR_DATA = qos_profile_sensor_data

__all__ = ["COMMANDS", "LATCHED", "LATEST", "SENSOR_DATA", "STREAM"]

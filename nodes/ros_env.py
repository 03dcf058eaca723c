"""Process environment for ROS 2: loopback-only DDS discovery unless a deployment opts out.

``ROS_AUTOMATIC_DISCOVERY_RANGE`` must be in the environment before ``rclpy.init()``. We default
it to ``LOCALHOST`` (unicast 127.0.0.1 and shared memory, no multicast). A lab that runs nodes on
several machines sets ``PPOD_DISCOVERY_RANGE=SUBNET`` (or ``discovery_range: SUBNET`` in the
``ppod up`` config). ``ROS_LOCALHOST_ONLY`` is deprecated and overrides the range: we remove it.
"""

from __future__ import annotations

import os
from collections.abc import MutableMapping

VALID_RANGES = ("LOCALHOST", "SUBNET", "OFF", "SYSTEM_DEFAULT")

#: Environment variable a launcher sets to ask a node's process for SCHED_FIFO at this priority
#: (1-99; unset or 0: normal scheduling): set by ``NodeSpec.env``, taken by
#: ``ppod_nodes.common.runner.take_realtime_priority``.
REALTIME_ENV = "PPOD_REALTIME_PRIORITY"


def configure_ros_environment(env: MutableMapping[str, str] | None = None, discovery_range: str | None = None
                              ) -> str:
    """Set the DDS discovery range in ``env`` (default: ``os.environ``) and return it.

    Precedence: the ``discovery_range`` argument, then ``PPOD_DISCOVERY_RANGE``, then an existing
    ``ROS_AUTOMATIC_DISCOVERY_RANGE``, then ``LOCALHOST``.
    """
    env = os.environ if env is None else env
    chosen = (discovery_range or env.get("PPOD_DISCOVERY_RANGE") or env.get("ROS_AUTOMATIC_DISCOVERY_RANGE")
              or "LOCALHOST").upper()
    if chosen not in VALID_RANGES:
        raise ValueError(f"discovery range must be one of {', '.join(VALID_RANGES)}, got {chosen!r}")
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = chosen
    env.pop("ROS_LOCALHOST_ONLY", None)
    return chosen

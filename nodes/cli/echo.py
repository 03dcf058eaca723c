"""Print messages of a topic as YAML, or list the topics (ros2 topic echo has no wheel here).

The message type is discovered from the ROS graph; the subscription matches the publisher's
durability, so latched topics (the active motion, its status) print their last message at once.

examples:
  ppod echo --list
  ppod echo /ppod/plate_motion_status --once
  ppod echo /ppod/part_poses --count 5
  ppod echo /diagnostics --timeout 10
  ppod echo /ppod/plate_acceleration --field error_relative
"""

from __future__ import annotations

import argparse
import sys
import threading
import time

HELP = "print a topic's messages as YAML (or --list topics)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("topic", nargs="?", help="topic name, e.g. /ppod/plate_motion_status")
    parser.add_argument("--list", action="store_true", help="list topics and their types, then exit")
    parser.add_argument("--once", action="store_true", help="print one message and exit (same as --count 1)")
    parser.add_argument("--count", type=int, default=0, help="exit after N messages (default: until Ctrl-C)")
    parser.add_argument("--timeout", type=float, default=0.0,
                        help="give up after S seconds without the expected messages (exit 1)")
    parser.add_argument("--field", help="print only this field (dotted path, e.g. header.stamp.sec)")
    parser.add_argument("--discovery-wait", type=float, default=5.0, metavar="S",
                        help="how long to wait for the topic to appear in the graph (default: %(default)s)")


def run(args: argparse.Namespace) -> int:
    import yaml
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from ppod_nodes.common.msgdict import type_from_name
    from ppod_nodes.common.session import RosSession

    if not args.list and not args.topic:
        print("ppod echo: give a topic, or --list", file=sys.stderr)
        return 2
    session = RosSession("ppod_echo")
    node = session.node
    done = threading.Event()
    try:
        topic = None if args.topic is None else "/" + args.topic.lstrip("/")
        deadline = time.monotonic() + args.discovery_wait
        types: dict[str, list[str]] = {}
        # --list waits the whole discovery time (nodes keep appearing); a topic stops at first sight.
        while time.monotonic() < deadline:
            types = dict(node.get_topic_names_and_types())
            if topic is not None and topic in types:
                break
            time.sleep(0.1)
        if args.list:
            for name, tnames in sorted(types.items()):
                print(f"{name}  [{', '.join(tnames)}]")
            return 0
        if topic not in types:
            print(f"ppod echo: no publisher of {topic} found within {args.discovery_wait:g} s", file=sys.stderr)
            return 1
        msg_type = type_from_name(types[topic][0])
        infos = node.get_publishers_info_by_topic(topic)
        latched = any(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
        best_effort = any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos)
        qos = QoSProfile(depth=10,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
                         reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE)
        limit = 1 if args.once else args.count
        seen = [0]
        lock = threading.Lock()

        failure: list[str] = []

        def on_msg(msg):
            # Runs in the session's executor thread: an exception here would only kill that thread
            # and leave us waiting forever, so any failure is recorded and ends the wait (exit 1).
            try:
                text = _render(msg, args.field, yaml)
            except Exception as exc:  # noqa: BLE001 - reported as one line, then exit 1
                failure.append(f"{type(exc).__name__}: {exc}")
                done.set()
                return
            with lock:
                if done.is_set():
                    return
                sys.stdout.write(text)
                sys.stdout.flush()
                seen[0] += 1
                if limit and seen[0] >= limit:
                    done.set()

        node.create_subscription(msg_type, topic, on_msg, qos)
        try:
            finished = done.wait(args.timeout if args.timeout > 0 else None)
        except KeyboardInterrupt:
            return 0
        if failure:
            print(f"ppod echo: cannot print a message of {topic}: {failure[0]}", file=sys.stderr)
            return 1
        if not finished:
            print(f"ppod echo: {seen[0]} message(s) on {topic} within {args.timeout:g} s", file=sys.stderr)
            return 1
        return 0
    finally:
        session.close()


def _render(msg, field: str | None, yaml) -> str:
    """One message as YAML (a document ending in ``---``), or one field's scalar value."""
    from ppod_nodes.common.msgdict import to_data

    data = to_data(msg)
    if field:
        for part in field.split("."):
            data = data[int(part)] if isinstance(data, list) else data[part]
    if isinstance(data, (dict, list)):
        return yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=110) + "---\n"
    return f"{data}\n"

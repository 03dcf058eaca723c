"""Record the stack's topics to an MCAP file (ROS 2 serialization; rosbag2 and Foxglove read it).

By default every /ppod topic (goals, status, accelerations, poses, simulation ground truth, the
scenario the simulated device publishes, the drawable /ppod/viz topics), MovePart's action feedback
and status, /tf, /rosout and /diagnostics, except camera images (large: add --images). The file
follows the MCAP ros2 profile as rosbag2 writes it (ros2msg schemas, cdr channels with
offered_qos_profiles, the rosbag2 metadata record). Stop with Ctrl-C or --duration.

examples:
  ppod record out/session.mcap --duration 30
  ppod record out/session.mcap --images
  ppod record out/session.mcap --topics /ppod/part_poses /ppod/plate_motion_goal
"""

from __future__ import annotations

import argparse
import signal
import threading
import time
from pathlib import Path

from ppod_nodes.common import topics

HELP = "record ppod topics to MCAP (ROS 2 serialization)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("output", type=Path, help="the .mcap file to write")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="record exactly these topics")
    parser.add_argument("--images", action="store_true", help="also record camera images")
    parser.add_argument("--action-feedback", action="store_true",
                        help="also record the hidden _action/feedback topics (their content is always recorded "
                             "as /ppod/planner/progress)")
    parser.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")


#: Recorded by default besides /ppod/... (names from nodes/common/topics.py).
ALWAYS = frozenset({topics.DIAGNOSTICS, topics.TF, topics.ROSOUT})


def default_include(images: bool, action_feedback: bool = False):
    """What ``ppod record`` keeps by default. The planner's action feedback is always kept as the
    plain ppod/planner/progress topic; the hidden ``_action/feedback`` topics only on request
    (``action_feedback``), as ``ros2 bag record --include-hidden-topics`` does: their generated type
    names (``Name_FeedbackMessage``) are rejected by some readers (mcap-ros2-support)."""

    def include(topic: str, type_name: str) -> bool:
        if type_name == "sensor_msgs/msg/Image" and not images:
            return False
        if "/_action/" in topic:
            # Status is what an operator saw; goal/result/cancel are services anyway.
            return topic.endswith("/_action/status") or (action_feedback and topic.endswith("/_action/feedback"))
        return topic.startswith("/ppod/") or topic in ALWAYS

    return include


def run(args: argparse.Namespace) -> int:
    from ppod_nodes.common.session import RosSession
    from ppod_nodes.record.mcap_io import McapRecorder

    args.output.parent.mkdir(parents=True, exist_ok=True)
    wanted = None if not args.topics else {"/" + t.lstrip("/") for t in args.topics}
    include = (lambda topic, _type: topic in wanted) if wanted else default_include(args.images, args.action_feedback)
    stop = threading.Event()
    previous = {s: signal.signal(s, lambda *_: stop.set()) for s in (signal.SIGINT, signal.SIGTERM)}
    started = time.monotonic()
    with RosSession("ppod_record") as session:
        meta = {"ppod": {"recorded_by": "ppod record", "started_unix_s": f"{time.time():.3f}"}}
        recorder = McapRecorder(session.node, args.output, include, metadata=meta)
        session.node.get_logger().info(f"recording to {args.output} (Ctrl-C to stop)")
        try:
            last_report = started
            while not stop.wait(0.2):
                now = time.monotonic()
                if args.duration is not None and now - started >= args.duration:
                    break
                if now - last_report >= 5.0:
                    last_report = now
                    print(f"recording: {sum(recorder.counts.values())} messages on {len(recorder.counts)} topics",
                          flush=True)
        finally:
            recorder.close()
            for s, h in previous.items():
                signal.signal(s, h)
    print(f"wrote {args.output}: {sum(recorder.counts.values())} messages in {time.monotonic() - started:.1f} s")
    for topic, n in sorted(recorder.counts.items()):
        print(f"  {topic}: {n}")
    return 0

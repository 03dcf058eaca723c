"""Send several parts to their own goal poses at once on a running stack (the MoveParts action).

GOALS.yaml (docs/formats.md): a list of {part, pose[, tol_mm, tol_deg]}; parts are named by the
tracker's label (the first tracked part with that label not already named) or by track id; pose
x, y in m and theta in degrees (no theta: position only). Prints the planner's progress and each
part's outcome; Ctrl-C cancels the goals (the plate ramps down and holds the parts).

examples:
  ppod move goals.yaml
  ppod move goals.yaml --timeout 90 --keep-clear
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

from ppod_ros.errors import ConfigError, DeviceError

HELP = "move several tracked parts to their own goal poses at once (GOALS.yaml)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("goals", type=Path, help="GOALS.yaml: parts (tracker label or track id) and goal poses")
    parser.add_argument("--timeout", type=float, default=0.0,
                        help="device-clock s for the whole set (default 0: the planner's default)")
    parser.add_argument("--keep-clear", action="store_true",
                        help="also keep the predicted paths clear of the parts not listed")
    parser.add_argument("--wait", type=float, default=10.0, help="seconds to wait for the tracker and the planner")


def run(args: argparse.Namespace) -> int:
    from ppod_ros.planning.goals import load_goals_file, resolve_parts

    entries = load_goals_file(args.goals)
    if not (math.isfinite(args.timeout) and args.timeout >= 0):
        raise ConfigError(f"--timeout: expected seconds >= 0, got {args.timeout}")

    from geometry_msgs.msg import Pose2D
    from ppod_msgs.action import MoveParts
    from ppod_msgs.msg import PartPoseArray

    from ppod_nodes.common import qos, topics
    from ppod_nodes.common.actions import ActionClient
    from ppod_nodes.common.session import RosSession

    with RosSession("ppod_move") as ros:
        latest = []
        ros.node.create_subscription(PartPoseArray, topics.PART_POSES, latest.append, qos.STREAM)
        if not ros.wait_until(lambda: bool(latest), args.wait):
            raise DeviceError(f"no part poses on /{topics.PART_POSES} within {args.wait:g} s: is the stack up?")
        parts = [p for p in latest[-1].parts]
        ids = [int(p.id) for p in parts]
        rows = resolve_parts(entries, [p.label for p in parts], ids=ids)
        goal = MoveParts.Goal(part_ids=[ids[r] for r in rows], timeout_s=float(args.timeout),
                              keep_others_clear=bool(args.keep_clear))
        for e in entries:
            goal.targets.append(Pose2D(x=e.x_m, y=e.y_m, theta=math.radians(e.theta_deg or 0.0)))
            goal.use_orientation.append(e.theta_deg is not None)
            goal.position_tolerance_m.append(1e-3 * e.tol_mm)
            goal.orientation_tolerance_rad.append(math.radians(e.tol_deg))
        client = ActionClient(ros.node, MoveParts, "/" + topics.MOVE_PARTS)
        if not client.wait_for_server(timeout_sec=args.wait):
            raise DeviceError(f"the field_planner's /{topics.MOVE_PARTS} action is not available")
        last = [0.0]

        def on_feedback(msg) -> None:
            if time.monotonic() - last[0] >= 1.0:
                last[0] = time.monotonic()
                print(f"  {msg.feedback.text}", flush=True)

        handle = ros.wait_future(client.send_goal_async(goal, feedback_callback=on_feedback), args.wait, "goals")
        if not handle.accepted:
            raise DeviceError("the field_planner rejected the goals (its log says why: colliding goals, a goal "
                              "outside the working region, a part not tracked, or another goal running)")
        print(f"moving tracks {list(goal.part_ids)}", flush=True)
        result = handle.get_result_async()
        try:
            while not result.done():
                ros.wait_until(result.done, 0.5)
        except KeyboardInterrupt:
            ros.wait_future(handle.cancel_goal_async(), 5.0, "cancel")
            print("cancelled")
            return 130
        res = result.result().result
    for pid, ok, e, a, ttg in zip(res.part_ids, res.reached, res.position_error_m, res.orientation_error_rad,
                                  res.time_to_goal_s):
        print(f"  track {pid}: {'reached' if ok else 'NOT reached'}, {1e3 * e:.2f} mm, {math.degrees(a):+.2f} deg"
              + (f", in {ttg:.1f} s" if ttg >= 0 else ""))
    print(("done: " if res.success else "not reached: ") + res.reason + f" ({res.elapsed_s:.1f} s)")
    return 0 if res.success else 1

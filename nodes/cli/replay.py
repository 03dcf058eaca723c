"""Replay a recorded session against the simulated device and compare the outcome with the recording.

The recording (`ppod record` during `ppod up --sim`) carries the simulated device's scenario (device,
mismatch, seed, camera, the placed parts) and the goals the waveform generator accepted. The replay
starts the same stack on the same scenario, re-sends every goal at its recorded device time, records
the outcome and compares it with the recording by device time: the true plate acceleration, the
measured acceleration, the true and the tracked part positions. Exit status 0 when every difference
is within its tolerance (a regression test), 1 otherwise.

examples:
  ppod replay tests/fixtures/session_linesinkx.mcap --against-sim
  ppod replay out/session.mcap --against-sim --position-tol-mm 1 --accel-tol 0.01
  ppod replay out/session.mcap --info        what the recording holds, without running anything
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import yaml

from ppod_ros.errors import ConfigError, DeviceError

HELP = "replay a recorded session against the simulated device and compare (regression test)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("recording", type=Path, help="an .mcap file written by `ppod record`")
    parser.add_argument("--against-sim", action="store_true", help="replay against the simulated device")
    parser.add_argument("--info", action="store_true", help="print what the recording holds and exit")
    # A goal replayed a cycle (33 ms) later than recorded, and corrections applied at slightly other
    # times, move parts by up to about 2 mm over a 10 s session (measured); a changed model moves them
    # by centimetres.
    parser.add_argument("--position-tol-mm", type=float, default=3.0, help="part positions (default: %(default)s)")
    parser.add_argument("--accel-tol", type=float, default=0.02,
                        help="plate acceleration, relative to the motion (default: %(default)s)")
    parser.add_argument("--transient-s", type=float, default=2.5,
                        help="after each goal's ramp, seconds of learning transient not compared for the plate "
                             "acceleration (default: %(default)s)")
    parser.add_argument("--log-dir", type=Path, help="write the replayed stack's logs here")


def _print_plan(plan) -> None:
    sc = plan.scenario
    print(f"scenario: device {sc.get('device')}, mismatch {sc.get('mismatch')}, seed {sc.get('seed')}, "
          f"{len(sc['scene']['parts'])} parts, camera {'on' if sc.get('camera') else 'off'}")
    for t, motion in plan.goals:
        print(f"  t = {t:7.2f} s  goal {motion.name or '(unnamed)'}: {motion.describe()}")
    print(f"nodes: {', '.join(plan.nodes)}; outcome until t = {plan.duration_s:.1f} s: "
          + ", ".join(f"{k} ({len(v)})" for k, v in plan.outcome.items() if v))


def run(args: argparse.Namespace) -> int:
    from ppod_nodes.record.replay import compare, plan_replay

    plan = plan_replay(args.recording)
    _print_plan(plan)
    if args.info:
        return 0
    if not args.against_sim:
        raise ConfigError("replay needs --against-sim (replaying against real hardware is not supported)")
    replayed, offset = _replay(plan, args)
    transients = [(t, t + (m.ramp_time_s or 0.5) + args.transient_s) for t, m in plan.goals]
    diffs = compare(plan.outcome, replayed, position_tol_m=args.position_tol_mm / 1000, accel_tol=args.accel_tol,
                    transients=transients)
    print(f"\nreplay vs recording (device times matched{f', replay {offset:.2f} s later' if offset else ''})")
    print(f"{'compared':32s} {'samples':>8s} {'worst':>12s} {'rms':>12s} {'tolerance':>12s}  result")
    for d in diffs:
        scale, unit = (1000, "mm") if d.unit == "m" else (100, "%")
        print(f"{d.what:32s} {d.compared:8d} {scale * d.worst:10.3f}{unit:>2s} {scale * d.rms:10.3f}{unit:>2s} "
              f"{scale * d.tolerance:10.3f}{unit:>2s}  {'ok' if d.ok else 'DIFFERS'}")
    ok = bool(diffs) and all(d.ok for d in diffs)
    print("replay matches the recording" if ok else "replay DIFFERS from the recording")
    return 0 if ok else 1


def _replay(plan, args) -> tuple[dict, float]:
    from dataclasses import replace

    from ppod_msgs.srv import SetPlateMotion
    from rosgraph_msgs.msg import Clock
    from std_srvs.srv import Trigger

    from ppod_nodes.common import qos, topics
    from ppod_nodes.common.convert import motion_to_msg, stamp_to_seconds
    from ppod_nodes.common.msgdict import type_from_name
    from ppod_nodes.common.session import RosSession
    from ppod_nodes.launch.spec import load_launch_spec
    from ppod_nodes.launch.stack import Stack
    from ppod_nodes.record.replay import COMPARED

    sc = plan.scenario
    tmp = Path(tempfile.mkdtemp(prefix="ppod-replay-"))
    scene_file = tmp / "scene.yaml"
    scene_file.write_text(yaml.safe_dump(sc["scene"]))
    spec = load_launch_spec()
    spec = replace(spec, nodes=tuple(n for n in spec.nodes if n.name in plan.nodes))
    extra = {
        "sim_device": {"scene": str(scene_file), "seed": int(sc["seed"]), "mismatch": sc["mismatch"],
                       "camera": bool(sc.get("camera", True)), "device_config": sc.get("device_config", "")},
        "waveform_generator": {"device_config": sc.get("device_config", "")},
        "accel_feedback": {"device_config": sc.get("device_config", ""), "cache_dir": str(tmp / "cache")},
    }
    if sc.get("camera_config"):
        extra["sim_device"]["camera_config"] = sc["camera_config"]
    types = {t: type_from_name(n) for t, n in (
        ("/" + topics.SIM_TRUE_POSES, "ppod_msgs/msg/PartPoseArray"),
        ("/" + topics.SIM_TRUE_ACCELERATION, "ppod_msgs/msg/PlateAcceleration"),
        ("/" + topics.ACCELERATION, "ppod_msgs/msg/PlateAcceleration"),
        ("/" + topics.PART_POSES, "ppod_msgs/msg/PartPoseArray"))}
    got: dict[str, list] = {t: [] for t in COMPARED}
    clock: list[float] = [0.0]
    log_dir = args.log_dir or tmp
    log_dir.mkdir(parents=True, exist_ok=True)
    with open(log_dir / "replay_stack.log", "w") as log, Stack(spec, sim=True, out=log, log_dir=args.log_dir,
                                                               extra_params=extra, handle_signals=False) as stack:
        try:
            stack.start()
        except DeviceError as exc:
            raise DeviceError(f"{exc} (log: {log_dir / 'replay_stack.log'})") from exc
        with RosSession("ppod_replay") as ros:
            ros.node.create_subscription(Clock, topics.CLOCK,
                                         lambda m: clock.__setitem__(0, stamp_to_seconds(m.clock)), 10)
            for topic, cls in types.items():
                ros.node.create_subscription(
                    cls, topic, lambda m, t=topic: got[t].append((stamp_to_seconds(m.header.stamp), m)), qos.STREAM)
            ros.wait_until(lambda: clock[0] > 0, 10)
            # A late start shifts everything by whole 0.1 s steps: cycles (30 Hz idle) and the ground
            # truth's 0.1 s ticks stay aligned between the two runs.
            offset = math.ceil(max(0.0, clock[0] + 0.5 - plan.goals[0][0]) * 10 - 1e-9) / 10
            if offset:
                print(f"the stack was ready at device time {clock[0]:.2f} s, after the first recorded goal: "
                      f"goals are sent {offset:.2f} s later and compared {offset:.2f} s later")
            for t_goal, motion in plan.goals:
                ros.wait_until(lambda t=t_goal: clock[0] >= t + offset, 120, step_s=0.002)
                if motion.is_zero():
                    ros.call(Trigger, "/" + topics.STOP, Trigger.Request(), 10)
                    print(f"  t = {clock[0]:7.2f} s  stop")
                else:
                    resp = ros.call(SetPlateMotion, "/" + topics.SET_MOTION,
                                    SetPlateMotion.Request(motion=motion_to_msg(motion)), 10)
                    print(f"  t = {clock[0]:7.2f} s  goal {motion.name}: "
                          f"{'accepted' if resp.accepted else 'REJECTED: ' + resp.reason}")
            end = plan.duration_s + offset
            last = time.monotonic()
            while clock[0] < end and stack.alive():
                if time.monotonic() - last > 5:
                    print(f"  t = {clock[0]:7.2f} s / {end:.1f} s", flush=True)
                    last = time.monotonic()
                time.sleep(0.05)
            if not stack.alive():
                print(f"the stack stopped early; log: {log_dir / 'replay_stack.log'}", file=sys.stderr)
    shifted = {t: [(s - offset, m) for s, m in msgs] for t, msgs in got.items()}
    return shifted, offset

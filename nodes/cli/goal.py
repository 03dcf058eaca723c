"""Send a plate-motion goal to the waveform generator and print whether it was accepted.

The goal file uses the MOTION.yaml format (docs/formats.md), with its optional name and ramp time.
It is validated here first (a bad file never reaches the device); the waveform generator then checks
it against the device limits and either accepts it (printing the predicted peak coil currents) or
rejects it naming the limit. Nothing is sent to the device for a rejected goal.

examples:
  ppod goal config/motions/LineSinkX.yaml
  ppod goal config/motions/LineSinkX.yaml --dry-run      validate and predict only
  ppod goal --stop                                       ramp the plate down to rest
  ppod goal --preset LineSinkX                           a named preset (ppod goal --list-presets)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ppod_ros.errors import ConfigError

HELP = "send a MOTION.yaml goal to the waveform generator (or --stop)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("motion", nargs="?", type=Path, help="MOTION.yaml file")
    parser.add_argument("--preset", help="a named motion preset instead of a file")
    parser.add_argument("--list-presets", action="store_true", help="list the named presets and exit")
    parser.add_argument("--stop", action="store_true", help="ramp the plate to rest")
    parser.add_argument("--dry-run", action="store_true", help="validate and predict; send nothing to the device")
    parser.add_argument("--ramp", type=float, metavar="S", help="override the goal's ramp time (s)")
    parser.add_argument("--timeout", type=float, default=10.0, help="seconds to wait for the generator")


def presets_dir() -> Path:
    from importlib import resources

    return Path(str(resources.files("ppod_ros") / "data" / "motions"))


def load_goal(args: argparse.Namespace):
    from ppod_ros.motion import PlateMotion

    if args.preset:
        path = presets_dir() / f"{args.preset}.yaml"
        if not path.is_file():
            names = ", ".join(sorted(p.stem for p in presets_dir().glob("*.yaml")))
            raise ConfigError(f"--preset: no preset named {args.preset!r}; available: {names}")
    elif args.motion is not None:
        path = args.motion
    else:
        raise ConfigError("give a MOTION.yaml file, --preset NAME or --stop")
    motion = PlateMotion.from_yaml(path)
    if args.ramp is not None:
        motion = PlateMotion(motion.frequency_hz, motion.k, motion.amplitude, motion.phase, name=motion.name,
                             ramp_time_s=args.ramp)
    return motion


def run(args: argparse.Namespace) -> int:
    if args.list_presets:
        for p in sorted(presets_dir().glob("*.yaml")):
            print(p.stem)
        return 0
    motion = None if args.stop else load_goal(args)

    from ppod_msgs.srv import SetPlateMotion
    from std_srvs.srv import Trigger

    from ppod_nodes.common import topics
    from ppod_nodes.common.convert import motion_to_msg
    from ppod_nodes.common.session import RosSession

    with RosSession("ppod_goal") as client:
        if args.stop:
            resp = client.call(Trigger, "/" + topics.STOP, Trigger.Request(), args.timeout)
            print(("stopping: " if resp.success else "stop refused: ") + resp.message)
            return 0 if resp.success else 1
        req = SetPlateMotion.Request(motion=motion_to_msg(motion), dry_run=args.dry_run)
        resp = client.call(SetPlateMotion, "/" + topics.SET_MOTION, req, args.timeout)
    label = motion.name or (args.preset or str(args.motion))
    currents = ", ".join(f"{a:.2f}" for a in resp.predicted_current_peak_a)
    if resp.accepted:
        verb = "valid (dry run, nothing sent)" if args.dry_run else "accepted"
        print(f"{label}: {verb}; predicted peak coil currents [{currents}] A; "
              f"contact margin {resp.contact_margin_mps2:.2f} m/s^2")
        return 0
    detail = ""
    if resp.limit:
        detail = f" (limit {resp.limit} = {resp.limit_value:g}, goal needs {resp.requested_value:g})"
    print(f"{label}: rejected: {resp.reason}{detail}", file=sys.stderr)
    return 1


"""Start the PPOD stack: each node in its own process, lifecycle nodes brought to active.

Logs of every node are forwarded with a [name] prefix. A node that dies is reported with its
exit status and never silently restarted; a required node's death stops the stack (exit 1).
Ctrl-C or SIGTERM stops the nodes in reverse order (the waveform generator ramps the plate to
zero first) and waits until every child process has exited.

DDS discovery stays on loopback (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) unless the config's
discovery_range or the environment's PPOD_DISCOVERY_RANGE says SUBNET (lab networks).

examples:
  ppod up --sim                         the stack against the simulated device, until Ctrl-C
  ppod up --sim --duration 20           ... for 20 seconds
  ppod up --config config/lab.yaml      against the real device (copy config/lab.example.yaml)
  ppod up --sim --only sim_device waveform_generator --log-dir out/logs
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ppod_nodes.launch.spec import load_launch_spec
from ppod_nodes.launch.stack import Stack
from ppod_ros.errors import DeviceError

HELP = "start the stack's nodes (against the device, or --sim)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--sim", action="store_true", help="start the simulated device and use it")
    parser.add_argument("--config", type=Path, help="launch configuration YAML (default: the packaged one)")
    parser.add_argument("--only", nargs="+", metavar="NODE", help="start only these nodes")
    parser.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    parser.add_argument("--log-dir", type=Path, help="also write each node's output to DIR/NAME.log")
    parser.add_argument("--no-activate", action="store_true",
                        help="leave lifecycle nodes unconfigured (manage them yourself)")


def run(args: argparse.Namespace) -> int:
    spec = load_launch_spec(args.config)
    if args.log_dir:
        args.log_dir.mkdir(parents=True, exist_ok=True)
    with Stack(spec, sim=args.sim, only=args.only, log_dir=args.log_dir) as stack:
        try:
            stack.start(activate=not args.no_activate)
        except DeviceError as exc:
            stack.supervisor.say(f"start-up failed: {exc}")
            return 1
        status = stack.wait(args.duration)
        clean = stack.stop()
    return status or (0 if clean else 1)

"""Run the simulated PPOD device in its own process, reachable over a localhost CAN bridge.

The device plays the device side of the CAN protocol (docs/can_protocol.md) on a python-can
virtual channel served to other processes by python-can-remote on 127.0.0.1. Connect with
``interface: remote`` and ``channel: ws://127.0.0.1:PORT/`` (the line printed at start-up).

examples:
  python -m ppod_sim                              # default device, port 54701, real time
  python -m ppod_sim --port 0 --duration 30       # any free port, stop after 30 s of device time
  python -m ppod_sim --rate 10 --mismatch zero    # 10x real time, plant exactly the nominal model
  python -m ppod_sim --config config/device.yaml --seed 3 --truth-out out/truth.jsonl
"""

from __future__ import annotations

import argparse
import logging
import math
import signal
import sys
import threading
from urllib.parse import urlparse

from ppod_ros.device.config import Mismatch, load_device_config
from ppod_ros.errors import PpodError

DEFAULT_PORT = 54701


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m ppod_sim", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--config", help="device YAML (default: the packaged default device)")
    p.add_argument(
        "--port",
        type=int,
        help="bridge TCP port on 127.0.0.1; 0 = any free port "
        "(default: the port of can.channel when it is a ws:// address, else 54701)",
    )
    p.add_argument(
        "--rate", type=float, default=1.0, help="device seconds per wall second (default 1: real time)"
    )
    p.add_argument("--fast", action="store_true", help="run as fast as possible (same as --rate inf)")
    p.add_argument("--seed", type=int, help="simulation seed (default: sim.seed of the config)")
    p.add_argument(
        "--mismatch",
        choices=["config", "zero"],
        default="config",
        help="plant mismatch: as configured, or zero (the plant is the nominal model)",
    )
    p.add_argument("--linear", action="store_true", help="simulate the linearised plant (no exact geometry)")
    p.add_argument("--duration", type=float, help="stop after this much device time (s)")
    p.add_argument(
        "--truth-out", help="append each cycle's true plate acceleration harmonics to this JSON-lines file"
    )
    p.add_argument("-v", "--verbose", action="count", default=0)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.WARNING - 10 * min(args.verbose, 2),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    # Imported here so that --help stays fast.
    from ppod_sim.process import SimProcess
    from ppod_sim.truth import TruthWriter

    try:
        config = load_device_config(args.config)
        if args.mismatch == "zero":
            config = config.with_mismatch(Mismatch.zero())
        if args.linear:
            config = config.replace("sim", exact_geometry=False)
        port = args.port
        if port is None:
            url = urlparse(config.can.channel)
            port = url.port if url.scheme in ("ws", "wss") and url.port else DEFAULT_PORT
        rate = math.inf if args.fast else args.rate
        sim = SimProcess(config, port=port, rate=rate, seed=args.seed)
    except PpodError as exc:
        print(f"ppod_sim: error: {exc}", file=sys.stderr)
        return 2
    writer = TruthWriter(args.truth_out) if args.truth_out else None
    if writer:
        sim.device.cycle_callbacks.append(writer)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    print(
        f"ppod_sim: device node {config.can.device_node_id} on {sim.url} (rate {rate:g}, seed "
        f"{config.sim.seed if args.seed is None else args.seed}, mismatch {args.mismatch})",
        flush=True,
    )
    try:
        sim.run(stop, args.duration)
    finally:
        dev = sim.device
        factor = dev.time_s / sim.wall_s if sim.wall_s > 0 else math.nan
        print(
            f"ppod_sim: stopped at device time {dev.time_s:.3f} s after {sim.wall_s:.3f} s wall "
            f"({factor:.1f}x real time); frames sent {dev.frames_tx}, received {dev.counters.accepted}, "
            f"rejected {dev.counters.rejected_total}; max lag {sim.pacer.max_lag_s * 1e3:.1f} ms, "
            f"slipped {sim.pacer.slipped_s:.3f} s in {sim.pacer.slips} stalls",
            flush=True,
        )
        sim.close()
        if writer:
            writer.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Emergency stop: write the top-priority ESTOP frame straight to the CAN bus.

No ROS, no handshake, no state: it works whatever the nodes are doing (or if none runs). The
device ramps to zero within its e-stop ramp (100 ms) and latches ESTOP until reset
(`ppod estop --reset` asks the waveform generator to reset it).
The bus is the device description's (config/device.yaml: can.interface and can.channel), or the
simulated device's bridge when a `ppod up --sim` is running, or what --interface/--channel say.

examples:
  ppod estop                                   the running stack's device (real or simulated)
  ppod estop --interface socketcan --channel can0
  ppod estop --reset                           leave the latched emergency stop (via the generator)
"""

from __future__ import annotations

import argparse

HELP = "emergency stop: the ESTOP frame straight on the bus (or --reset)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--device-config", help="device description YAML (default: the packaged one)")
    parser.add_argument("--interface", help="CAN backend (virtual, remote, socketcan, ...)")
    parser.add_argument("--channel", help="CAN channel (can0, ws://127.0.0.1:PORT/, ...)")
    parser.add_argument("--reset", action="store_true", help="reset a latched e-stop through the waveform generator")


def run(args: argparse.Namespace) -> int:
    if args.reset:
        from std_srvs.srv import Trigger

        from ppod_nodes.common.session import RosSession
        from ppod_nodes.waveform_generator import RESET_ESTOP

        with RosSession("ppod_estop") as session:
            resp = session.call(Trigger, "/" + RESET_ESTOP, Trigger.Request(), 10.0)
        print(resp.message)
        return 0 if resp.success else 1

    from ppod_nodes.launch import runfile
    from ppod_ros.can import open_bus, send_estop
    from ppod_ros.device import load_device_config

    config = load_device_config(args.device_config)
    stack = runfile.read()
    interface, channel = args.interface, args.channel
    if interface is None and channel is None and stack and stack.get("sim_bridge"):
        interface, channel = "remote", stack["sim_bridge"]
    bus = open_bus(config.can, interface=interface, channel=channel)
    try:
        send_estop(bus, config.can.device_node_id)
    finally:
        bus.shutdown()
    print(f"ESTOP frame sent to device node {config.can.device_node_id} on "
          f"{interface or config.can.interface} {channel or config.can.channel}")
    return 0

"""Live 3D view of the running stack for Foxglove: parts, MovePart targets, the current field.

Starts a Foxglove WebSocket server on 127.0.0.1 (never another interface) fed from the stack's
ROS topics: the tracked parts, the targets of MovePart goals and the active motion's field for a
point part (arrows: velocity x 1.5 s), in the frame ``plate``, with the ``plate -> camera``
transform. In Foxglove: Open connection -> Foxglove WebSocket -> ws://127.0.0.1:8765, add a 3D
panel. The same scene is recorded by ``ppod record`` as MarkerArray + TF (the viz node).

examples:
  ppod up --sim &                                   the stack against the simulated device
  ppod view                                         serve ws://127.0.0.1:8765 until Ctrl-C
  ppod view --port 8800 --duration 60
  ppod view --camera-config config/my_camera.yaml   the lab camera's mounting pose for the TF
"""

from __future__ import annotations

import argparse
import signal
import threading
import time

HELP = "live 3D view for Foxglove (websocket on 127.0.0.1)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--port", type=int, default=8765, help="TCP port on 127.0.0.1 (default: %(default)s)")
    parser.add_argument("--rate", type=float, default=5.0, metavar="HZ", help="scene updates per second")
    parser.add_argument("--device-config", help="device description (plate radius); default: the packaged one")
    parser.add_argument("--camera-config", help="camera YAML (plate -> camera); default: the simulated camera")
    parser.add_argument("--field-grid", type=int, default=9, help="field arrows across the plate (0: none)")
    parser.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")


def run(args: argparse.Namespace) -> int:
    from ppod_nodes.common.session import RosSession
    from ppod_nodes.view.live import LiveView
    from ppod_ros.device.config import load_device_config
    from ppod_ros.errors import ConfigError
    from ppod_ros.view.scene import camera_transform
    from ppod_ros.vision import CameraConfig

    if not 0 <= args.port <= 65535:
        raise ConfigError(f"--port: expected 0..65535, got {args.port}")
    if not args.rate > 0:
        raise ConfigError(f"--rate: must be > 0 Hz, got {args.rate}")
    radius = load_device_config(args.device_config).plate.radius_m
    camera = CameraConfig.from_yaml(args.camera_config) if args.camera_config else CameraConfig()
    stop = threading.Event()
    previous = {s: signal.signal(s, lambda *_: stop.set()) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with RosSession("ppod_view") as session, LiveView(session.node, radius, camera_transform(camera),
                                                          args.port, args.rate, args.field_grid) as view:
            print(f"live view on ws://127.0.0.1:{view.port} (Foxglove: Open connection -> Foxglove WebSocket); "
                  f"Ctrl-C to stop", flush=True)
            started = time.monotonic()
            while not stop.wait(0.2):
                if args.duration is not None and time.monotonic() - started >= args.duration:
                    break
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
    return 0

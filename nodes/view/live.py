"""The live view's server: the scene as Foxglove schemas over a websocket bound to 127.0.0.1.

:class:`LiveView` feeds a foxglove-sdk ``WebSocketServer`` from ROS: channel ``/ppod/scene``
(foxglove.SceneUpdate: plate, parts, MovePart targets, the field) and ``/ppod/tf``
(foxglove.FrameTransform: plate -> camera), at ``rate_hz``. Open Foxglove, connect to
``ws://127.0.0.1:PORT`` (Foxglove WebSocket) and add a 3D panel; its display frame is ``plate``.
"""

from __future__ import annotations

import threading

import foxglove
from foxglove.channels import FrameTransformChannel, SceneUpdateChannel

from ppod_nodes.common import topics
from ppod_nodes.view.foxglove_scene import camera_frame_transform, scene_update
from ppod_nodes.view.state import SceneState

SCENE_CHANNEL = topics.VIEW_SCENE
TF_CHANNEL = topics.VIEW_TF
HOST = "127.0.0.1"  # never another interface (project rule: traffic stays on loopback)


class LiveView:
    """Start with :meth:`start`, stop with :meth:`stop` (or use as a context manager)."""

    def __init__(self, node, plate_radius_m: float, camera_pose, port: int = 8765, rate_hz: float = 5.0,
                 field_grid: int = 9):
        self.state = SceneState(node, plate_radius_m, field_grid=field_grid)
        self.camera_pose = camera_pose
        self.port = port
        self.period_s = 1.0 / rate_hz
        self.server = None
        self.sent = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> LiveView:
        self.context = foxglove.Context()
        self.server = foxglove.start_server(name="ppod", host=HOST, port=self.port, context=self.context)
        self.port = self.server.port
        self.scene_channel = SceneUpdateChannel(SCENE_CHANNEL, context=self.context)
        self.tf_channel = FrameTransformChannel(TF_CHANNEL, context=self.context)
        self._thread = threading.Thread(target=self._loop, name="live-view", daemon=True)
        self._thread.start()
        return self

    def publish_once(self) -> None:
        self.tf_channel.log(camera_frame_transform(*self.camera_pose))
        self.scene_channel.log(scene_update(self.state.scene()))
        self.sent += 1

    def _loop(self) -> None:
        while not self._stop.wait(self.period_s):
            self.publish_once()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self.server is not None:
            self.server.stop()
            self.server = None

    def __enter__(self) -> LiveView:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

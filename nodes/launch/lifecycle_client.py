"""Drive other processes' lifecycle nodes through their standard services.

Uses ``/<node>/change_state`` and ``/<node>/get_state`` (lifecycle_msgs), with a private rclpy
context spun in a background thread and blocking ``Client.call`` from the caller's thread (fast and
safe per ROS_NOTES.md). Used by ``ppod up`` and by the system tests.
"""

from __future__ import annotations

import threading
import time

import rclpy
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from ppod_nodes.ros_env import configure_ros_environment
from ppod_ros.errors import DeviceError

TRANSITIONS = {
    "configure": Transition.TRANSITION_CONFIGURE,
    "activate": Transition.TRANSITION_ACTIVATE,
    "deactivate": Transition.TRANSITION_DEACTIVATE,
    "cleanup": Transition.TRANSITION_CLEANUP,
}


class LifecycleClient:
    """A small ROS node that calls lifecycle services of other nodes."""

    def __init__(self, name: str = "ppod_launcher"):
        configure_ros_environment()
        self._context = Context()
        rclpy.init(context=self._context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self._context)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True, name="lifecycle-client")
        self._thread.start()
        self._clients: dict[tuple[str, str], object] = {}

    def _spin(self) -> None:
        try:
            self._executor.spin()
        except ExternalShutdownException:
            pass

    def _client(self, node: str, kind: str):
        key = (node, kind)
        if key not in self._clients:
            srv_type = ChangeState if kind == "change_state" else GetState
            self._clients[key] = self.node.create_client(srv_type, f"/{node}/{kind}")
        return self._clients[key]

    def wait_for(self, node: str, timeout_s: float) -> bool:
        """Wait until ``node``'s lifecycle services are available."""
        deadline = time.monotonic() + timeout_s
        for kind in ("change_state", "get_state"):
            left = deadline - time.monotonic()
            if left <= 0 or not self._client(node, kind).wait_for_service(timeout_sec=left):
                return False
        return True

    def _call(self, client, request, timeout_s: float, what: str):
        future = client.call_async(request)
        done = threading.Event()
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(timeout_s):
            client.remove_pending_request(future)
            raise DeviceError(f"{what}: no answer within {timeout_s:g} s")
        return future.result()

    def get_state(self, node: str, timeout_s: float = 5.0) -> str:
        resp = self._call(self._client(node, "get_state"), GetState.Request(), timeout_s, f"{node} get_state")
        return resp.current_state.label

    def change_state(self, node: str, transition: str, timeout_s: float = 30.0) -> bool:
        """Request a transition; True if the node accepted and completed it."""
        req = ChangeState.Request()
        req.transition.id = TRANSITIONS[transition]
        resp = self._call(self._client(node, "change_state"), req, timeout_s, f"{node} {transition}")
        return bool(resp.success)

    def close(self) -> None:
        self._executor.shutdown()
        self._thread.join(timeout=5.0)
        self.node.destroy_node()
        self._context.try_shutdown()

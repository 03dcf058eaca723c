"""Drive other processes' lifecycle nodes through their standard services.

Uses ``/<node>/change_state`` and ``/<node>/get_state`` (lifecycle_msgs) from a
:class:`~ppod_nodes.common.session.RosSession`. Used by ``ppod up`` and by the system tests.
"""

from __future__ import annotations

import time

from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState

from ppod_nodes.common.session import RosSession

TRANSITIONS = {
    "configure": Transition.TRANSITION_CONFIGURE,
    "activate": Transition.TRANSITION_ACTIVATE,
    "deactivate": Transition.TRANSITION_DEACTIVATE,
    "cleanup": Transition.TRANSITION_CLEANUP,
}


class LifecycleClient(RosSession):
    """A small ROS session that calls lifecycle services of other nodes."""

    def __init__(self, name: str = "ppod_launcher"):
        super().__init__(name)
        self._clients: dict[tuple[str, str], object] = {}

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

    def get_state(self, node: str, timeout_s: float = 5.0) -> str:
        resp = self.call(GetState, f"/{node}/get_state", GetState.Request(), timeout_s,
                         client=self._client(node, "get_state"))
        return resp.current_state.label

    def change_state(self, node: str, transition: str, timeout_s: float = 30.0) -> bool:
        """Request a transition; True if the node accepted and completed it."""
        req = ChangeState.Request()
        req.transition.id = TRANSITIONS[transition]
        resp = self.call(ChangeState, f"/{node}/change_state", req, timeout_s,
                         client=self._client(node, "change_state"))
        return bool(resp.success)

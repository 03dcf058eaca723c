"""Drive other processes' lifecycle nodes through their standard services.

Uses ``/<node>/change_state`` and ``/<node>/get_state`` (lifecycle_msgs) from a
:class:`~ppod_nodes.common.session.RosSession`. Used by ``ppod up`` and by the system tests.

A service becomes "available" once its request channel is matched; the response channel may still
be unmatched, and under load a response sent in that window is lost (the server drops it after a
short wait). :meth:`LifecycleClient.change_state` therefore never waits on one request alone: when
no answer comes within an attempt it asks ``get_state`` where the node is, takes the target state as
success, keeps waiting while the node is still transitioning, and sends the request again otherwise.
"""

from __future__ import annotations

import time

from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState

from ppod_nodes.common.session import RosSession
from ppod_ros.errors import DeviceError

TRANSITIONS = {
    "configure": Transition.TRANSITION_CONFIGURE,
    "activate": Transition.TRANSITION_ACTIVATE,
    "deactivate": Transition.TRANSITION_DEACTIVATE,
    "cleanup": Transition.TRANSITION_CLEANUP,
}
# The primary state each transition ends in, and the transition states a node passes through.
TARGET_STATE = {"configure": "inactive", "activate": "active", "deactivate": "inactive", "cleanup": "unconfigured"}
TRANSITION_STATES = {"configuring", "activating", "deactivating", "cleaningup", "shuttingdown", "errorprocessing"}


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

    def change_state(self, node: str, transition: str, timeout_s: float = 30.0, attempt_s: float = 5.0) -> bool:
        """Request a transition; True if the node completed it (its answer, or its state, says so).

        Each attempt waits ``attempt_s`` for the answer; then ``get_state`` decides: the target
        state means done (the answer was lost), a transition state means wait on, anything else
        means send the request again. DeviceError when nothing settles within ``timeout_s``.
        """
        deadline = time.monotonic() + timeout_s
        name = f"/{node}/change_state"
        client = self._client(node, "change_state")
        if not client.wait_for_service(timeout_sec=timeout_s):
            raise DeviceError(f"service {name} is not available (is the node running?)")
        target = TARGET_STATE[transition]
        while True:
            req = ChangeState.Request()
            req.transition.id = TRANSITIONS[transition]
            future = client.call_async(req)
            while True:
                left = deadline - time.monotonic()
                if left <= 0:
                    client.remove_pending_request(future)
                    raise DeviceError(f"service {name}: no answer within {timeout_s:g} s")
                try:
                    resp = self.wait_future(future, min(attempt_s, left), f"service {name}")
                except DeviceError:
                    label = self._state_or_none(node, min(2.0, max(0.1, deadline - time.monotonic())))
                    if label == target:
                        client.remove_pending_request(future)
                        return True
                    if label is None or label in TRANSITION_STATES:
                        continue  # still at work, or get_state lost too: wait on this request
                    client.remove_pending_request(future)
                    break  # the request never arrived: send it again
                if resp.success:
                    return True
                # A repeated request finds the node already there when an earlier one got through.
                return self._state_or_none(node, 2.0) == target

    def _state_or_none(self, node: str, timeout_s: float) -> str | None:
        try:
            return self.get_state(node, timeout_s)
        except DeviceError:
            return None

"""An rclpy action client whose goal, result and cancel futures always complete.

rclpy's ``ActionClient`` (Jazzy's 7.1.6 wheel) sends a request and only then records its sequence
number. When the caller's thread is not the executor's (every PPOD tool: a ``RosSession`` spins in
its own thread) and is preempted between the two, the executor can take the server's response
first; it then logs "Ignoring unexpected goal response" and the future never completes
(ros2/rclpy#1123, fixed upstream by a lock in later releases). Seen in ``ppod demo``: the planner
accepted MoveParts and moved the parts, its feedback arrived, and the demo failed after 30 s with
"MoveParts goal: no answer".

:class:`ActionClient` closes the race as the upstream fix does: sending a request and recording it
is one step under a lock, and the executor takes responses under the same lock, so a response is
never taken before its request is known.
"""

from __future__ import annotations

import threading

from rclpy.action import ActionClient as _RclpyActionClient


class ActionClient(_RclpyActionClient):
    """``rclpy.action.ActionClient`` with requests recorded before their responses can be taken."""

    def __init__(self, *args, **kwargs):
        self._request_lock = threading.Lock()
        super().__init__(*args, **kwargs)

    def take_data(self):
        with self._request_lock:
            return super().take_data()

    def send_goal_async(self, goal, feedback_callback=None, goal_uuid=None):
        with self._request_lock:
            return super().send_goal_async(goal, feedback_callback=feedback_callback, goal_uuid=goal_uuid)

    def _cancel_goal_async(self, goal_handle):
        with self._request_lock:
            return super()._cancel_goal_async(goal_handle)

    def _get_result_async(self, goal_handle):
        with self._request_lock:
            return super()._get_result_async(goal_handle)

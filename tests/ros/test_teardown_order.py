"""The executor is shut down only after its spin thread has stopped (run_node, RosSession).

rclpy 7.1's ``Executor.shutdown()`` does not wait for the callback being dispatched (its wait is
skipped) and destroys the guard condition that callback's handler triggers next. A demo's viz node
printed that traceback on the way out (``InvalidHandle: cannot use Destroyable because destruction was
requested``, from ``gc.trigger()`` in the spin thread). The window is microseconds wide, so these
tests check the order itself: ``shutdown()`` must never run while the spin thread is inside
``spin``/``spin_once``. On the code before they fail: the executor was shut down to stop ``spin()``.
"""

from __future__ import annotations

import threading

import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

import ppod_nodes.common.runner as runner
import ppod_nodes.common.session as session

pytestmark = pytest.mark.ros


class _Recording(SingleThreadedExecutor):
    """Counts the threads inside spin/spin_once; records shutdown() calls made while one is."""

    made: list[_Recording] = []

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.inside = 0
        self.lock = threading.Lock()
        self.shutdown_while_spinning = 0
        self.shutdowns = 0
        self.spun = 0
        _Recording.made.append(self)

    def _enter(self):
        with self.lock:
            self.inside += 1
            self.spun += 1

    def _leave(self):
        with self.lock:
            self.inside -= 1

    def spin(self):
        self._enter()
        try:
            super().spin()
        finally:
            self._leave()

    def spin_once(self, timeout_sec=None):
        self._enter()
        try:
            super().spin_once(timeout_sec)
        finally:
            self._leave()

    def shutdown(self, timeout_sec=None):
        with self.lock:
            self.shutdowns += 1
            self.shutdown_while_spinning += self.inside > 0
        return super().shutdown(timeout_sec)


class _QuitsAtOnce(Node):
    """A node whose autostart fails: run_node tears down at once, its spin thread still spinning."""

    ticks = 0

    def __init__(self, **kwargs):
        super().__init__("teardown_order", **kwargs)
        self.started = threading.Event()
        self.create_timer(0.001, self._tick)

    def _tick(self):
        _QuitsAtOnce.ticks += 1
        self.started.set()

    def autostart(self):
        self.started.wait(5.0)    # the spin thread is running callbacks
        return False


@pytest.fixture
def recording(monkeypatch):
    _Recording.made.clear()
    monkeypatch.setattr(runner, "SingleThreadedExecutor", _Recording)
    monkeypatch.setattr(session, "SingleThreadedExecutor", _Recording)
    return _Recording.made


def test_run_node_stops_the_spin_thread_before_shutting_the_executor_down(recording):
    _QuitsAtOnce.ticks = 0
    status = runner.run_node(_QuitsAtOnce, ["teardown_order"])
    assert status == 1                                    # autostart failed, as the node said
    (executor,) = recording
    assert _QuitsAtOnce.ticks > 0 and executor.spun > 0   # it did spin callbacks
    assert executor.shutdowns == 1 and executor.shutdown_while_spinning == 0


def test_a_session_closes_in_the_same_order(recording):
    s = session.RosSession("teardown_order_tool")
    ticked = threading.Event()
    s.node.create_timer(0.001, ticked.set)
    assert ticked.wait(5.0)
    s.close()
    (executor,) = recording
    assert executor.shutdowns == 1 and executor.shutdown_while_spinning == 0
    assert s.failures == []

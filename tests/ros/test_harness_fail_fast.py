"""The node tests' harness fails a test at once when a node's callback raised: the executor thread
has then stopped spinning (in the stack the node's process ends), and a test that waited on the
nodes used to run into its own timeout (a sensorless MovePart test waited 10 minutes)."""

from __future__ import annotations

import time

import pytest


def test_a_raising_callback_fails_the_next_wait_naming_the_exception(ros):
    ticks = []

    def tick() -> None:
        ticks.append(1)
        if len(ticks) == 3:
            raise ZeroDivisionError("a node bug")

    ros.node.create_timer(0.01, tick)
    assert ros.wait_until(lambda: len(ticks) >= 2, 10.0)   # spinning, nothing raised yet
    for _ in range(1000):   # the third tick raises on the executor thread
        if ros.failures:
            break
        time.sleep(0.01)
    assert ros.failures
    asked = []
    with pytest.raises(AssertionError, match="callback raised ZeroDivisionError: a node bug"):
        ros.wait_until(lambda: asked.append(1) or False, 60.0)
    assert asked == []   # failed before waiting on anything, not at the end of its 60 s
    ros.failures.clear()   # the fixture's teardown closes the stopped session as usual

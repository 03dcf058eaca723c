"""A launcher's request for real-time scheduling (PPOD_REALTIME_PRIORITY), as a node's process takes it.

The waveform generator's heartbeat thread shares the GIL with its goal checks: on a loaded machine
the process was preempted while a goal check held the GIL, and heartbeats went out up to 156 ms apart
(the device's watchdog allows 150). Under SCHED_FIFO the process is not preempted by the others.
"""

import json
import os
import subprocess
import sys

import pytest

from ppod_nodes.common.runner import REALTIME_ENV, take_realtime_priority

pytestmark = pytest.mark.ros


@pytest.mark.parametrize("value", [None, "", "0"])
def test_no_request_changes_nothing(value):
    env = {} if value is None else {REALTIME_ENV: value}
    assert take_realtime_priority(env) is None


@pytest.mark.parametrize("value", ["high", "100", "-3"])
def test_a_bad_request_is_one_warning_and_normal_scheduling(value, monkeypatch):
    monkeypatch.setattr(os, "sched_setscheduler", lambda *a: pytest.fail("must not be called"))
    level, text = take_realtime_priority({REALTIME_ENV: value})
    assert level == "warning" and "expected an integer 1-99" in text


def test_a_refused_request_says_so_and_the_node_runs_on(monkeypatch):
    def refuse(*args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    level, text = take_realtime_priority({REALTIME_ENV: "10"})
    assert level == "warning"
    assert "not granted (Operation not permitted)" in text and "normal scheduling" in text


def test_the_process_has_what_its_message_says_in_every_thread_started_after():
    """In a child process (never this one): granted (root, CAP_SYS_NICE or an rtprio limit), the
    calling thread and a thread started after it run SCHED_FIFO at the priority asked; refused, both
    run at normal priority and the message says so."""
    code = (
        "import json, os, threading\n"
        "from ppod_nodes.common.runner import take_realtime_priority\n"
        "level, text = take_realtime_priority()\n"
        "seen = {}\n"
        "t = threading.Thread(target=lambda: seen.update(policy=os.sched_getscheduler(0),"
        " priority=os.sched_getparam(0).sched_priority))\n"
        "t.start(); t.join()\n"
        "print(json.dumps({'level': level, 'text': text, 'main': os.sched_getscheduler(0),"
        " 'thread': seen['policy'], 'priority': seen['priority'], 'fifo': os.SCHED_FIFO}))\n"
    )
    env = {**os.environ, REALTIME_ENV: "7"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout.strip().splitlines()[-1])
    if got["level"] == "info":
        assert got["main"] == got["thread"] == got["fifo"] and got["priority"] == 7
        assert "real-time priority 7 (SCHED_FIFO)" in got["text"]
    else:
        assert got["main"] != got["fifo"] and got["thread"] != got["fifo"]
        assert "not granted" in got["text"]

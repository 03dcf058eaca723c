"""`ppod up` starts nodes as processes, manages their lifecycles and stops them all."""

import re
import signal
from pathlib import Path

import pytest

from tests.ros.helpers import LISTENER_ELEVENTH, ROOT, pid_alive, ppod, wait_gone

pytestmark = [pytest.mark.ros, pytest.mark.slow]
CONFIG = str(ROOT / "tests" / "support" / "two_nodes.yaml")


def _started_pids(proc) -> dict[str, int]:
    return {m.group(1): int(m.group(2)) for m in
            (re.search(r"started (\w+) \(pid (\d+)\)", line) for line in proc.lines) if m}


def test_sigint_to_the_launcher_stops_every_child_after_they_exchanged_messages():
    proc = ppod("up", "--config", CONFIG)
    try:
        proc.wait_for(r"all nodes up", 60)
        proc.wait_for(LISTENER_ELEVENTH, 30)
        pids = _started_pids(proc)
        assert set(pids) == {"motion_listener", "motion_talker"}
        assert all(pid_alive(p) for p in pids.values())
        proc.p.send_signal(signal.SIGINT)
        assert proc.wait(30) == 0
        assert wait_gone(list(pids.values()), 5) == []
        out = proc.output
        assert "[motion_talker] [INFO] deactivate: now inactive" in out
        assert "[motion_talker] [INFO] shutdown: now finalized" in out
        assert "all children exited" in out
    finally:
        proc.kill()


def test_a_dying_node_is_reported_and_stops_the_stack():
    proc = ppod("up", "--config", CONFIG)
    try:
        proc.wait_for(r"all nodes up", 60)
        pids = _started_pids(proc)
        import os

        os.kill(pids["motion_talker"], signal.SIGKILL)
        proc.wait_for(r"motion_talker exited unexpectedly \(killed by SIGKILL\)", 10)
        assert proc.wait(30) == 1
        assert wait_gone(list(pids.values()), 5) == []
    finally:
        proc.kill()


def test_children_do_not_outlive_a_killed_launcher():
    proc = ppod("up", "--config", CONFIG)
    try:
        proc.wait_for(r"all nodes up", 60)
        pids = _started_pids(proc)
        proc.p.send_signal(signal.SIGKILL)
        proc.wait(10)
        assert wait_gone(list(pids.values()), 15) == []
    finally:
        proc.kill()


def test_a_failing_configure_is_reported_and_nothing_is_left_running(tmp_path):
    cfg = tmp_path / "fail.yaml"
    cfg.write_text(Path(CONFIG).read_text().replace("params: {rate_hz: 20.0}", "params: {fail_configure: true}"))
    proc = ppod("up", "--config", str(cfg))
    try:
        proc.wait_for(r"motion_talker: configure failed", 60)
        assert proc.wait(30) == 1
        assert "configure failed: fail_configure is set" in proc.output
        assert wait_gone(list(_started_pids(proc).values()), 5) == []
    finally:
        proc.kill()


def test_bad_launch_config_is_one_clear_error(tmp_path):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text("nodes:\n  - name: a\n    module: x\n    colour: red\n")
    proc = ppod("up", "--config", str(cfg))
    assert proc.wait(30) == 2
    assert "nodes[0].colour" in proc.output


def test_a_node_started_with_nice_runs_at_that_lower_priority(tmp_path):
    import io
    import os

    from ppod_nodes.launch.spec import NodeSpec
    from ppod_nodes.launch.supervisor import Supervisor

    sup = Supervisor(dict(os.environ), sim=True, out=io.StringIO())
    try:
        plain = sup.start(NodeSpec("plain", "tests.support.sleeper", lifecycle=False))
        lowered = sup.start(NodeSpec("lowered", "tests.support.sleeper", lifecycle=False, nice=5))
        assert os.getpriority(os.PRIO_PROCESS, lowered.process.pid) == os.getpriority(os.PRIO_PROCESS, 0) + 5
        assert os.getpriority(os.PRIO_PROCESS, plain.process.pid) == os.getpriority(os.PRIO_PROCESS, 0)
    finally:
        assert sup.stop_all(10)
        sup.close()


@pytest.mark.parametrize("inherited", ["ignored", "blocked"])
def test_a_child_stops_at_the_first_sigint_whatever_the_launcher_inherited(inherited):
    """A launcher started as a background job of a non-interactive shell (a script, CI) has SIGINT
    ignored, and a disposition of SIG_IGN (or a blocked signal) survives fork and exec: its children
    ignored the SIGINT of the stop sequence and were stopped by SIGTERM after the shutdown timeout
    (these tests' sleepers took 10 s each to stop in CI). The children start with the stop signals
    at their defaults."""
    import io
    import os
    import time

    from ppod_nodes.launch.spec import NodeSpec
    from ppod_nodes.launch.supervisor import Supervisor

    stop = {signal.SIGINT, signal.SIGTERM}
    if inherited == "ignored":
        was = signal.signal(signal.SIGINT, signal.SIG_IGN)
    else:
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, stop)
    out = io.StringIO()
    sup = Supervisor(dict(os.environ), sim=True, out=out)
    try:
        child = sup.start(NodeSpec("plain", "tests.support.sleeper", lifecycle=False))
    finally:
        if inherited == "ignored":
            signal.signal(signal.SIGINT, was)
        else:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    try:
        # Signalled once it runs its module (a SIGINT during the interpreter's start-up can end it
        # with a fatal error instead of the KeyboardInterrupt this test looks for).
        deadline = time.monotonic() + 30.0
        while "[plain] sleeping" not in out.getvalue() and time.monotonic() < deadline:
            time.sleep(0.02)
        assert "[plain] sleeping" in out.getvalue(), out.getvalue()
        assert sup.stop_all(10)
        assert child.process.returncode == -signal.SIGINT, out.getvalue()   # not SIGTERM's, after the timeout
    finally:
        sup.close()


def test_nice_outside_0_to_19_is_one_clear_error(tmp_path):
    from ppod_nodes.launch.spec import launch_spec_from_dict
    from ppod_ros.errors import ConfigError

    with pytest.raises(ConfigError, match=r"nodes\[0\].nice"):
        launch_spec_from_dict({"nodes": [{"name": "a", "module": "x", "nice": 25}]})


def test_a_node_asking_for_real_time_priority_gets_the_request_and_no_other_node_does(tmp_path):
    """The generator's heartbeat thread shares its process's GIL with the goal checks; preempted while
    holding it, the process sent heartbeats up to 156 ms apart (the watchdog allows 150). The launcher
    passes the node's realtime_priority to it, and only to it (not one inherited from its own environment)."""
    import io
    import os

    from ppod_nodes.launch.spec import NodeSpec
    from ppod_nodes.launch.supervisor import Supervisor

    env = {**os.environ, "PPOD_REALTIME_PRIORITY": "33"}   # the launcher's own: never passed on
    sup = Supervisor(env, sim=True, out=io.StringIO())
    try:
        plain = sup.start(NodeSpec("plain", "tests.support.sleeper", lifecycle=False))
        rt = sup.start(NodeSpec("rt", "tests.support.sleeper", lifecycle=False, realtime_priority=10))

        def environ(pid):
            raw = Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
            return dict(item.decode().split("=", 1) for item in raw if b"=" in item)

        assert environ(rt.process.pid).get("PPOD_REALTIME_PRIORITY") == "10"
        assert "PPOD_REALTIME_PRIORITY" not in environ(plain.process.pid)
        # Its BLAS on the calling thread: no worker at normal priority for a goal check to wait on.
        assert environ(rt.process.pid).get("OPENBLAS_NUM_THREADS") == "1"
        assert environ(plain.process.pid).get("OPENBLAS_NUM_THREADS") == os.environ.get("OPENBLAS_NUM_THREADS")
    finally:
        assert sup.stop_all(10)
        sup.close()


def test_realtime_priority_outside_0_to_99_is_one_clear_error():
    from ppod_nodes.launch.spec import launch_spec_from_dict
    from ppod_ros.errors import ConfigError

    with pytest.raises(ConfigError, match=r"nodes\[0\].realtime_priority"):
        launch_spec_from_dict({"nodes": [{"name": "a", "module": "x", "realtime_priority": 100}]})


@pytest.mark.parametrize("domain, refused", [("same", True), ("other", False)])
def test_a_second_stack_in_the_same_ros_domain_is_refused_before_it_starts_anything(tmp_path, monkeypatch,
                                                                                      domain, refused):
    # Two stacks in one domain share node, service and topic names: a second `ppod demo` started
    # beside a running one failed with "waveform_generator: configure failed" (its lifecycle
    # response timed out). The second is refused with the reason; another domain is fine.
    import io
    import os
    import subprocess
    import sys

    from ppod_nodes.launch import runfile
    from ppod_nodes.launch.spec import launch_spec_from_dict
    from ppod_nodes.launch.stack import Stack
    from ppod_ros.errors import DeviceError

    monkeypatch.setenv("PPOD_RUN_DIR", str(tmp_path))
    mine = os.environ.get("ROS_DOMAIN_ID", "0")
    launcher = subprocess.Popen([sys.executable, "-m", "tests.support.sleeper"], cwd=ROOT)  # the other stack
    theirs = mine if domain == "same" else str(int(mine) + 1)
    try:
        runfile.write({"pid": launcher.pid, "sim": True, "domain": theirs})
        assert runfile.read(theirs) is not None and (runfile.read(mine) is not None) == refused
        spec = launch_spec_from_dict({"shutdown_timeout_s": 5, "nodes": [
            {"name": "sleeper", "module": "tests.support.sleeper", "lifecycle": False}]})
        out = io.StringIO()
        stack = Stack(spec, sim=True, out=out, handle_signals=False)
        try:
            if refused:
                with pytest.raises(DeviceError, match=f"another ppod stack is running in ROS domain {mine} "
                                                      f"\\(launcher pid {launcher.pid}"):
                    stack.start()
                assert stack.supervisor.children == []
                assert runfile.read()["pid"] == launcher.pid       # the running stack's file is kept
            else:
                stack.start()
                assert [c.spec.name for c in stack.supervisor.children] == ["sleeper"]
                info = runfile.read()
                assert info["pid"] == os.getpid() and info["domain"] == mine
                # The other domain's stack keeps its own file (one run file held both, and the second
                # stack overwrote the first's: its `ppod estop` then found the second's simulator).
                assert runfile.read(theirs)["pid"] == launcher.pid
        finally:
            stack.stop()
        assert runfile.read(theirs)["pid"] == launcher.pid and (runfile.read(mine) is None) != refused
    finally:
        launcher.kill()
        launcher.wait(10)

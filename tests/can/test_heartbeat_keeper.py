"""The heartbeat keeper process (ppod_ros.can.keeper): heartbeats through a stall of the host's GIL,
none once the host is dead or frozen.

Found in CI and in demos: rclpy's ``Publisher.publish`` held the waveform generator's GIL for about
330 ms while Fast DDS matched a new reader, its heartbeat thread could not run, and the device's
watchdog (150 ms) ramped the plate to rest mid-goal. The device and its bridge run in a process of
their own here (as in the stack), so that holding this process's GIL holds only the host.

The windows below are generous against the 50 ms heartbeat period: they check which process can
beat, not how fast it does.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from ppod_bench.can import HeartbeatRecorder, hold_the_gil
from ppod_ros.can import DeviceLink, open_bus
from ppod_ros.can.keeper import HeartbeatKeeper, keeper_spec, keeper_supported
from ppod_ros.device import default_device_config
from ppod_ros.errors import ConfigError

#: A host in a process of its own: a link with a keeper; prints the keeper's pid once it is ready.
_HOST = textwrap.dedent("""
    import sys, time
    from ppod_ros.can import DeviceLink, open_bus
    from ppod_ros.device import default_device_config
    config = default_device_config().with_can(interface="remote", channel=sys.argv[1])
    link = DeviceLink(open_bus(config.can), config)
    link.start_heartbeat(keeper_lease_s=float(sys.argv[2]))
    deadline = time.monotonic() + 20
    while not link._keeper.ready() and time.monotonic() < deadline:
        time.sleep(0.01)
    print(link._keeper.pid, flush=True)
    time.sleep(60)
""")


@pytest.fixture
def recorder():
    config = default_device_config()
    rec = HeartbeatRecorder(config.can.device_node_id)
    yield rec
    rec.kill()


def _remote_config(url: str):
    return default_device_config().with_can(interface="remote", channel=url)


def _wait(predicate, timeout_s: float = 20.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def _gone(pid: int) -> bool:
    """The process has exited (a zombie no one reaps counts as exited)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except FileNotFoundError:
        return True


def _stall(link: DeviceLink, seconds: float) -> tuple[float, float]:
    time.sleep(0.3)   # a few ordinary beats first
    t0 = time.monotonic()
    hold_the_gil(seconds)
    t1 = time.monotonic()
    time.sleep(0.2)
    link.stop_heartbeat()
    return t0, t1


@pytest.mark.slow
def test_the_keeper_beats_through_a_stall_of_the_hosts_gil_where_the_thread_cannot(recorder):
    period = default_device_config().can.heartbeat_period_s
    config = _remote_config(recorder.url)
    bus = open_bus(config.can)
    try:
        # The thread alone: nothing reaches the device while the GIL is held (8 periods).
        alone = DeviceLink(bus, config)
        alone.start_heartbeat()
        a0, a1 = _stall(alone, 8 * period)
        # With a keeper: it beats on.
        kept = DeviceLink(bus, config)
        kept.start_heartbeat(keeper_lease_s=0.5)
        assert _wait(lambda: kept._keeper.ready()), "the keeper never became ready"
        k0, k1 = _stall(kept, 8 * period)
    finally:
        bus.shutdown()
    beats = recorder.beats()
    inside = lambda t0, t1: [t for t in beats if t0 + period < t < t1 - period / 2]  # noqa: E731
    assert len([t for t in beats if t < a0]) >= 3          # the thread did beat before the stall
    assert inside(a0, a1) == []                             # ... and not during it
    assert len(inside(k0, k1)) >= 2                         # the keeper did (about 7 expected)
    assert kept.counters.keeper_renewals >= 3
    assert kept.counters.keeper.startswith("sent ")
    assert "while the host's renewal was late" in kept.counters.keeper


@pytest.mark.slow
def test_the_keeper_stops_at_once_when_its_host_is_killed(recorder):
    """SIGKILL: the kernel closes the host's pipe and the keeper ends (a lease of 5 s shows it is the
    end-of-file that stops it, not the lease)."""
    host = subprocess.Popen([sys.executable, "-c", _HOST, recorder.url, "5.0"], stdout=subprocess.PIPE, text=True)
    try:
        keeper_pid = int(host.stdout.readline())
        time.sleep(0.3)
        t_kill = time.monotonic()
        host.kill()
        host.wait(10)
        assert _wait(lambda: _gone(keeper_pid), 10.0), "the keeper outlived its host"
    finally:
        if host.poll() is None:
            host.kill()
    beats = recorder.beats()
    assert len([t for t in beats if t < t_kill]) >= 3
    assert max(beats) < t_kill + 1.0     # the lease would have let it beat 5 s more


@pytest.mark.slow
def test_the_keeper_stops_when_its_host_freezes_and_beats_again_when_it_resumes(recorder):
    lease = 0.3
    host = subprocess.Popen([sys.executable, "-c", _HOST, recorder.url, str(lease)], stdout=subprocess.PIPE,
                            text=True)
    try:
        int(host.stdout.readline())
        time.sleep(0.3)
        t_stop = time.monotonic()
        os.kill(host.pid, signal.SIGSTOP)
        time.sleep(1.5)
        t_cont = time.monotonic()
        os.kill(host.pid, signal.SIGCONT)
        time.sleep(1.0)
        t_end = time.monotonic()
    finally:
        host.kill()
        host.wait(10)
    beats = recorder.beats()
    assert len([t for t in beats if t < t_stop]) >= 3
    assert [t for t in beats if t_stop + lease + 0.3 < t < t_cont] == []   # the lease ran out: silence
    assert len([t for t in beats if t_cont + 0.3 < t < t_end]) >= 3        # renewed: beating again


def test_a_backend_one_process_owns_keeps_the_thread(caplog):
    """python-can's virtual bus is in-process only: no keeper, the thread beats, and the log says why."""
    config = default_device_config().with_can(interface="virtual", channel="keeper-virtual")
    assert not keeper_supported("virtual") and keeper_supported("remote") and keeper_supported("socketcan")
    bus = open_bus(config.can)
    link = DeviceLink(bus, config)
    try:
        with caplog.at_level("INFO", logger="ppod_ros.can.host"):
            link.start_heartbeat(keeper_lease_s=0.5)
            assert link._keeper is None and link._hb_thread.is_alive()
            link.stop_heartbeat()
    finally:
        bus.shutdown()
    assert any("cannot be opened by a keeper process" in r.getMessage() for r in caplog.records)
    assert link.counters.sent >= 1 and link.counters.keeper == ""


def test_a_lease_shorter_than_two_heartbeat_periods_is_refused():
    can = _remote_config("ws://127.0.0.1:9/").can
    with pytest.raises(ConfigError, match="at least two heartbeat periods"):
        keeper_spec(can, can.heartbeat_period_s)
    with pytest.raises(ConfigError, match="cannot be opened by a second process"):
        HeartbeatKeeper(default_device_config().with_can(interface="virtual", channel="x").can, 0.5)
    spec = keeper_spec(can, 0.5)
    assert spec["lease_s"] == 0.5 and spec["interface"] == "remote" and spec["period_s"] == can.heartbeat_period_s


@pytest.mark.slow
def test_a_keeper_that_dies_hands_the_heartbeats_back_to_the_thread(recorder, caplog):
    config = _remote_config(recorder.url)
    bus = open_bus(config.can)
    link = DeviceLink(bus, config)
    try:
        with caplog.at_level("WARNING", logger="ppod_ros.can.host"):
            link.start_heartbeat(keeper_lease_s=0.5)
            assert _wait(lambda: link._keeper.ready())
            sent_before = link.counters.sent
            link._keeper.process.kill()
            assert _wait(lambda: link._keeper is None, 10.0)
            assert _wait(lambda: link.counters.sent >= sent_before + 3, 10.0)   # the thread beats again
            link.stop_heartbeat()
    finally:
        bus.shutdown()
    assert any("heartbeat keeper" in r.getMessage() and "is gone" in r.getMessage() for r in caplog.records)
    assert link.counters.keeper.startswith("gone (exit code")

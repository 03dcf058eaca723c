"""Bus factory, fault injection and the host-side DeviceLink against the simulated device."""

import itertools
import socket
import threading
import time

import can
import numpy as np
import pytest

from ppod_bench.can import hold_the_gil
from ppod_ros.actuation.planning import GoalPlanner
from ppod_ros.can import PROTOCOL_VERSION, AckResult, DeviceLink, DeviceState, FaultInjectingBus, open_bus, send_estop
from ppod_ros.can.codec import FrameCounters, Heartbeat, Version
from ppod_ros.can.protocol import Fn
from ppod_ros.device import default_device_config
from ppod_ros.errors import ConfigError, DeviceError, ProtocolError
from ppod_ros.motion import PlateMotion
from ppod_sim.device import SimDevice

_channels = itertools.count()
LINESINKX = PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0], ramp_time_s=0.1)


@pytest.fixture
def config():
    return default_device_config().with_can(interface="virtual", channel=f"test-link-{next(_channels)}")


@pytest.fixture
def buses(config):
    opened = []

    def make(**kw):
        bus = open_bus(config.can, **kw)
        opened.append(bus)
        return bus

    yield make
    for bus in opened:
        bus.shutdown()


def run(device, link, seconds, heartbeat=True):
    """Advance the device in heartbeat periods, the host answering in between."""
    end = device.time_s + seconds
    while device.time_s < end - 1e-9:
        if heartbeat:
            link.heartbeat()
        device.advance(0.05)
        link.poll()


def test_open_bus_chooses_the_backend_by_name(config, buses):
    a, b = buses(), buses()
    a.send(Heartbeat(3).encode(1))
    assert b.recv(1.0).arbitration_id == Heartbeat(3).encode(1).arbitration_id


def test_open_bus_rejects_unknown_backends_and_malformed_channels(config):
    with pytest.raises(ConfigError, match="unknown backend 'carrier-pigeon'"):
        open_bus(config.can, interface="carrier-pigeon")
    with pytest.raises(ConfigError, match="ws://HOST:PORT/"):
        open_bus(config.can, interface="remote", channel="127.0.0.1")


def test_open_bus_reports_an_unreachable_bridge_as_a_device_error(config):
    with socket.socket() as s:  # a port that nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(DeviceError, match="cannot open the remote bus"):
        open_bus(config.can, interface="remote", channel=f"ws://127.0.0.1:{port}/")


def test_fault_injection_drops_corrupts_and_counts(config, buses):
    rx = buses()
    lossy = FaultInjectingBus(buses(), drop=1.0)
    lossy.send(Heartbeat(1).encode(1))
    assert rx.recv(0.05) is None and lossy.stats["dropped_send"] == 1
    noisy = FaultInjectingBus(buses(), corrupt=1.0, seed=4)
    counters = FrameCounters(1, "to_device")
    for i in range(30):
        noisy.send(Heartbeat(i).encode(1))
    for _ in range(30):
        counters.decode(rx.recv(1.0))
    assert noisy.stats["corrupted_send"] == 30
    assert counters.rejected_total + counters.accepted == 30 and counters.rejected_total >= 15


def test_fault_injection_delays_frames(config, buses):
    rx = buses()
    slow = FaultInjectingBus(buses(), delay_s=0.05)
    t0 = time.monotonic()
    slow.send(Heartbeat(1).encode(1))
    assert rx.recv(0.01) is None
    assert rx.recv(1.0) is not None
    assert time.monotonic() - t0 >= 0.045
    slow.shutdown()


def test_bus_off_refuses_sends_until_it_recovers(config, buses):
    bus = FaultInjectingBus(buses())
    bus.go_bus_off()
    with pytest.raises(can.CanOperationError):
        bus.send(Heartbeat(1).encode(1))
    bus.recover()
    bus.send(Heartbeat(1).encode(1))
    bus.go_bus_off(0.02)
    time.sleep(0.03)
    assert not bus.is_bus_off


def test_shutting_the_wrapper_down_shuts_the_wrapped_bus_down(buses):
    """The wrapper owns its bus (python-can warned "VirtualBus was not properly shut down" when the
    safety campaign's wrapped host bus was collected)."""
    inner = buses()
    bus = FaultInjectingBus(inner, delay_s=0.01)
    bus.send(Heartbeat(1).encode(1))
    bus.shutdown()
    assert inner._is_shutdown and not bus._worker.is_alive()
    bus.shutdown()  # twice is harmless


def answering(device, stop):
    """Run the simulated device in a thread (real time is irrelevant here) until ``stop`` is set."""

    def loop():
        while not stop.is_set():
            device.step()
            time.sleep(0.001)

    thread = threading.Thread(target=loop, daemon=True)
    thread.start()
    return thread


def test_handshake_reports_the_devices_protocol_and_layout(config, buses):
    device = SimDevice(config, buses())
    link = DeviceLink(buses(), config)
    stop = threading.Event()
    thread = answering(device, stop)
    try:
        v = link.handshake(timeout_s=2.0)
    finally:
        stop.set()
        thread.join()
    assert (v.major, v.n_actuators, v.n_channels, v.simulated) == (PROTOCOL_VERSION[0], 6, 12, True)


def test_handshake_times_out_without_a_device(config, buses):
    link = DeviceLink(buses(), config)
    with pytest.raises(DeviceError, match="no VERSION reply"):
        link.handshake(timeout_s=0.05)


def test_handshake_refuses_an_incompatible_major_version(config, buses):
    fake = buses()
    link = DeviceLink(buses(), config)

    def reply():
        msg = fake.recv(2.0)
        assert msg is not None and msg.arbitration_id >> 4 == Fn.VERSION_REQUEST
        fake.send(Version(PROTOCOL_VERSION[0] + 1, 0, 6, 12, 5, 1, False).encode(1))

    thread = threading.Thread(target=reply)
    thread.start()
    try:
        with pytest.raises(DeviceError, match="incompatible major version"):
            link.handshake(timeout_s=2.0)
    finally:
        thread.join()


def test_a_table_that_cannot_be_encoded_sends_nothing(config, buses):
    spy = buses()
    link = DeviceLink(buses(), config)
    table = np.zeros((2, 6), complex)
    table[1, 3] = 20.0  # beyond the protocol's +-16 A
    with pytest.raises(ProtocolError, match="out of range"):
        link.send_table(table, 30.0, 0.5)
    assert spy.recv(0.05) is None


def test_send_estop_writes_the_top_priority_frame(config, buses):
    spy = buses()
    send_estop(buses(), config.can.device_node_id)
    msg = spy.recv(1.0)
    assert msg.arbitration_id == config.can.device_node_id  # function 0


def test_link_decodes_status_summaries_and_acknowledgements(config, buses):
    device = SimDevice(config, buses())
    link = DeviceLink(buses(), config)
    got = []
    link.on_summary.append(got.append)
    link.enable()
    plan = GoalPlanner(config).plan(LINESINKX)
    seq = link.send_plan(plan)
    run(device, link, 0.5)
    assert [a.result for a in link.acks[seq]] == [AckResult.ACCEPTED, AckResult.ACTIVE]
    assert link.wait_for_ack(seq, AckResult.ACTIVE, timeout_s=0.0).seq == seq
    assert link.status.state in (DeviceState.ENABLED, DeviceState.RAMPING)
    assert link.status.active_seq == seq
    assert got and got[-1].phasors.shape == (3, 12) and got[-1].frequency_hz == 30.0
    assert link.counters.summaries_incomplete == 0 and link.counters.frames.rejected_total == 0


def test_link_survives_a_lossy_corrupting_bus_and_counts_what_it_lost(config, buses):
    device = SimDevice(config, buses())
    noisy = FaultInjectingBus(buses(), drop=0.02, corrupt=0.02, seed=11, affect="receive")
    link = DeviceLink(noisy, config)
    link.enable()
    link.send_plan(GoalPlanner(config).plan(LINESINKX))
    run(device, link, 1.0)
    c = link.counters
    assert c.summaries > 0
    assert c.summaries_incomplete > 0
    assert c.frames.rejected_total > 0
    assert noisy.stats["dropped_receive"] > 0 and noisy.stats["corrupted_receive"] > 0


def test_a_bus_off_host_gets_device_errors_and_resumes_after_recovery(config, buses):
    device = SimDevice(config, buses())
    bus = FaultInjectingBus(buses())
    link = DeviceLink(bus, config)
    link.enable()
    run(device, link, 0.1)
    bus.go_bus_off()
    with pytest.raises(DeviceError, match="CAN send failed"):
        link.heartbeat()
    assert link.counters.send_errors == 1
    device.advance(0.3)  # the device sees no heartbeat: its watchdog stops it
    bus.recover()
    link.poll()
    assert link.status.state == DeviceState.WATCHDOG
    link.enable()
    run(device, link, 0.1)
    assert link.status.state == DeviceState.ENABLED


class _StallingBus(can.BusABC):
    """A bus whose third send blocks for ``stall_s`` (the sending process starved in the middle)."""

    def __init__(self, stall_s: float):
        super().__init__(channel="stall")
        self.stall_s, self.sends = stall_s, 0

    def send(self, msg, timeout=None):
        self.sends += 1
        if self.sends == 3:
            time.sleep(self.stall_s)

    def _recv_internal(self, timeout):
        return None, False


def test_a_starved_heartbeat_thread_says_so_where_it_happens(config, caplog):
    """A watchdog trip in a loaded CI run left no sign of which side stalled: the host's heartbeat
    thread now counts and logs an interval over two periods (the device's watchdog allows three)."""
    bus = _StallingBus(stall_s=4 * config.can.heartbeat_period_s)
    link = DeviceLink(bus, config)
    with caplog.at_level("WARNING", logger="ppod_ros.can.host"):
        link.start_heartbeat()
        deadline = time.monotonic() + 5.0
        while bus.sends < 6 and time.monotonic() < deadline:
            time.sleep(0.01)
        link.stop_heartbeat()
    assert bus.sends >= 6
    assert link.counters.heartbeats_late == 1
    assert link.counters.heartbeat_max_interval_s >= 4 * config.can.heartbeat_period_s
    assert any("this process is starved" in r.getMessage() for r in caplog.records)


def test_heartbeats_stop_when_the_process_exits(config):
    """At exit the heartbeat threads ran on through the interpreter's teardown, starved, and reported
    it; a process on its way out stops them first (the device's watchdog ramps the plate down)."""
    from ppod_ros.can import host

    link = DeviceLink(_StallingBus(stall_s=0.0), config)
    link.start_heartbeat()
    thread = link._hb_thread
    assert thread.is_alive() and link in host._HEARTBEATING
    host._stop_heartbeats_at_exit()
    thread.join(timeout=5.0)
    assert not thread.is_alive()
    link.stop_heartbeat()
    assert link not in host._HEARTBEATING


def test_a_stalled_heartbeat_thread_dumps_what_held_the_process(config, tmp_path):
    """The generator's heartbeat thread woke 317 ms late at a fresh-clone CI run's first goal and the
    device's watchdog tripped; the log said the process was starved, not by what. With ``stall_dump``
    the threads' stacks are written from outside the interpreter while the stall lasts: here the GIL
    held (in C) by this test's own function for 20 heartbeat periods."""
    period = config.can.heartbeat_period_s
    bus = _StallingBus(stall_s=0.0)
    link = DeviceLink(bus, config)
    with open(tmp_path / "dump.txt", "w+") as dump:
        link.start_heartbeat(stall_dump=dump)
        deadline = time.monotonic() + 5.0
        while bus.sends < 2 and time.monotonic() < deadline:   # the thread beats, so it has armed
            time.sleep(0.01)
        for _ in range(3):   # (a hold that began between a disarm and the next arm: held again)
            hold_the_gil(20 * period)
            if (tmp_path / "dump.txt").read_text():
                break
        link.stop_heartbeat()
        text = (tmp_path / "dump.txt").read_text()
    assert "Timeout" in text
    assert "test_a_stalled_heartbeat_thread_dumps_what_held_the_process" in text and "hold_the_gil" in text
    assert "_hb_loop" in text
    # Disarmed with the heartbeat thread: a stall after it dumps nothing.
    size = len(text)
    hold_the_gil(5 * period)
    assert len((tmp_path / "dump.txt").read_text()) == size


def test_a_heartbeat_stall_dump_without_a_file_descriptor_is_refused_with_a_warning(config, caplog):
    import io

    link = DeviceLink(_StallingBus(stall_s=0.0), config)
    with caplog.at_level("WARNING", logger="ppod_ros.can.host"):
        link.start_heartbeat(stall_dump=io.StringIO())
        link.stop_heartbeat()
    assert link._stall_dump is None
    assert any("no stack dump" in r.getMessage() for r in caplog.records)

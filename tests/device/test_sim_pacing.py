"""The simulated device's pacing against the host's heartbeats: the catch-up never stretches a heartbeat
interval in device time beyond the catch-up rate, and a heartbeat due waits in no socket.

Found in ``ppod demo`` (thirty-second session): with the catch-up's credit alone (test_sim_clock.py)
the device clock kept up with real time, but the bridge's reading thread, waiting for the GIL, left
heartbeats up to 120 ms in its socket while the device ran on: the watchdog saw the host's 50 ms
heartbeats up to 152 ms of device time apart (its limit is 150).
"""

import socket
import time
from types import SimpleNamespace

import pytest

from ppod_ros.can import DeviceState
from ppod_ros.device import default_device_config
from ppod_sim.process import SimProcess


@pytest.fixture
def process():
    p = SimProcess(default_device_config(), rate=1.0, seed=0)
    yield p
    p.close()


def _armed(p, age_s):
    dev = p.device
    dev.state = DeviceState.ENABLED
    dev.last_heartbeat_s = dev.time_s - age_s


def test_the_bridge_sees_frames_its_reading_thread_has_not_read(process):
    a, b = socket.socketpair()
    try:
        client = SimpleNamespace(_ws=SimpleNamespace(socket=a, closed=False))
        process.bridge.server.clients.append(client)
        assert not process.bridge.pending()
        b.sendall(b"\x82\x0f")
        assert process.bridge.pending()
        a.recv(16)
        assert not process.bridge.pending()
        client._ws.closed = True
        b.sendall(b"\x82\x0f")
        assert not process.bridge.pending()  # a closing connection holds nothing back
    finally:
        process.bridge.server.clients.remove(client)
        a.close()
        b.close()


def test_a_due_heartbeat_is_read_before_the_device_steps_on(process):
    calls = []

    def pending():
        calls.append(1)
        return len(calls) <= 3  # the reading thread needs three turns

    process.bridge.pending = pending
    # The wait's wall-clock bound far away: the reading thread's turns end it here, not a loaded
    # machine's slow sleeps (a CI run on a busy machine gave up after three turns at the 5 ms bound;
    # the bound has its own test below).
    process.deliver_wait_s = 60.0
    _armed(process, 0.02)  # no heartbeat due: the device does not wait
    process._deliver()
    assert calls == [] and process.deliver_waits == 0
    _armed(process, 0.06)  # one is due
    process._deliver()
    assert len(calls) == 4 and process.deliver_waits == 1
    process.device.state = DeviceState.DISABLED  # no watchdog armed: nothing to wait for
    calls.clear()
    process._deliver()
    assert calls == []


def test_a_socket_that_stays_readable_cannot_hold_the_device(process):
    process.bridge.pending = lambda: True
    _armed(process, 0.1)
    process._deliver()  # returns after deliver_wait_s
    assert process.deliver_waits == 1


def test_the_catch_up_holds_device_age_to_the_rate_times_wall_age(process):
    dev = process.device
    assert process._may_catch_up()  # disabled: catch up freely
    _armed(process, 0.01)
    dev.last_heartbeat_wall_s = None
    assert process._may_catch_up()  # no heartbeat seen on the bus yet (the enable's own)
    dev.last_heartbeat_wall_s = time.time() - 0.04
    assert process._may_catch_up()  # 10 ms of device time for 40 ms at the bus
    _armed(process, 1.0)
    assert not process._may_catch_up()  # 1 s of device time for 40 ms: hold at the rate

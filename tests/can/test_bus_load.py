"""Bus load from the frames a host sees (DeviceStatus.bus_load), against the documented frame times."""

import can
import pytest

from ppod_ros.can.load import BusLoadMeter, MeteredBus
from ppod_ros.can.protocol import frame_bits
from ppod_ros.errors import ConfigError


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def test_the_documented_steady_state_is_fifteen_percent_of_one_megabit():
    # docs/can_protocol.md: 1110 summary frames + 20 STATUS/STATUS_EXT (8 bytes), 2 coil frames (6 bytes)
    # and 20 heartbeats (2 bytes) per second: 15.4 % of 1 Mbit/s.
    clock = FakeClock()
    meter = BusLoadMeter(1_000_000, clock=clock)
    clock.t += 1.0
    frames = [8] * (1110 + 20) + [6] * 2 + [2] * 20
    for i, n in enumerate(frames):
        meter.add(n, t=clock.t - 1.0 + (i + 0.5) / len(frames))
    expected = (1130 * 135 + 2 * frame_bits(6) + 20 * 75) / 1e6
    assert meter.load() == pytest.approx(expected, rel=1e-12)
    assert meter.load() == pytest.approx(0.154, abs=0.001)


def test_frames_older_than_the_window_no_longer_count():
    clock = FakeClock()
    meter = BusLoadMeter(500_000, window_s=1.0, clock=clock)
    clock.t += 2.0
    meter.add(8, t=clock.t - 1.5)
    meter.add(8, t=clock.t - 0.5)
    assert meter.load() == pytest.approx(135 / 500_000)
    clock.t += 1.0
    assert meter.load() == 0.0


def test_a_meter_needs_a_positive_bitrate():
    with pytest.raises(ConfigError, match="bitrate"):
        BusLoadMeter(0)


def test_a_metered_bus_counts_what_it_sends_and_receives():
    a = can.Bus(interface="virtual", channel="load-test", receive_own_messages=False)
    b = MeteredBus(can.Bus(interface="virtual", channel="load-test", receive_own_messages=False), 1_000_000)
    try:
        a.send(can.Message(arbitration_id=0x81, data=bytes(8), is_extended_id=False))
        assert b.recv(2.0) is not None
        b.send(can.Message(arbitration_id=0x31, data=bytes(2), is_extended_id=False))
        assert a.recv(2.0) is not None
        assert b.meter._bits == 135 + 75
        assert b.load() > 0
    finally:
        a.shutdown()
        b.shutdown()

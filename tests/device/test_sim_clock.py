"""The simulated device's pacer: real-time pacing, reported lag, and stalls given up instead of raced."""

import math

import pytest

from ppod_ros.errors import ConfigError
from ppod_sim.clock import Pacer


class FakeWall:
    def __init__(self):
        self.t = 100.0
        self.slept = []

    def clock(self):
        return self.t

    def sleep(self, dt):
        self.slept.append(dt)
        self.t += dt


def test_paces_device_time_to_the_wall_clock_at_the_rate():
    wall = FakeWall()
    pacer = Pacer(2.0, clock=wall.clock, sleep=wall.sleep)
    pacer.start(0.0)
    for k in range(1, 11):
        pacer.wait(0.01 * k)  # 10 ms of device time per step, computed instantly
    assert wall.t - 100.0 == pytest.approx(0.05)  # 0.1 s of device time at 2x: 0.05 s of wall time
    assert pacer.max_lag_s == 0.0 and pacer.slips == 0


def test_small_lag_is_caught_up_and_reported():
    wall = FakeWall()
    pacer = Pacer(1.0, max_catch_up_s=0.02, clock=wall.clock, sleep=wall.sleep)
    pacer.start(0.0)
    wall.t += 0.015  # the first step took 15 ms of wall time for 5 ms of device time
    pacer.wait(0.005)
    assert pacer.lag_s == pytest.approx(0.010) and pacer.slips == 0
    pacer.wait(0.010)  # still 5 ms late: no sleep, the device runs on to catch up
    assert wall.slept == []
    pacer.wait(0.020)  # caught up: sleeps again, on the original schedule
    assert wall.slept and wall.t == pytest.approx(100.020)


def test_a_stall_is_given_up_so_device_time_never_races_the_wall_clock():
    wall = FakeWall()
    pacer = Pacer(1.0, max_catch_up_s=0.02, clock=wall.clock, sleep=wall.sleep)
    pacer.start(0.0)
    pacer.wait(0.01)
    wall.t += 0.3  # a 300 ms stall (starved process)
    pacer.wait(0.02)
    assert pacer.slips == 1 and pacer.slipped_s == pytest.approx(0.29)
    # After the slip the device runs at the rate again: 50 ms of device time take 50 ms of wall time,
    # so heartbeats sent every 50 ms of wall time still arrive every 50 ms of device time.
    t0 = wall.t
    for k in range(1, 6):
        pacer.wait(0.02 + 0.01 * k)
    assert wall.t - t0 == pytest.approx(0.05)
    assert pacer.max_lag_s == pytest.approx(0.29)


def test_free_running_and_bad_settings():
    wall = FakeWall()
    pacer = Pacer(math.inf, clock=wall.clock, sleep=wall.sleep)
    pacer.start(0.0)
    pacer.wait(10.0)
    assert wall.slept == [] and pacer.slips == 0
    with pytest.raises(ConfigError, match="rate"):
        Pacer(0.0)
    with pytest.raises(ConfigError, match="max_catch_up_s"):
        Pacer(1.0, max_catch_up_s=-1.0)

"""The simulated device's pacer: real-time pacing, reported lag made up at a bounded rate, long stalls given up."""

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


def test_a_lag_is_caught_up_and_reported_never_faster_than_the_catch_up_rate():
    wall = FakeWall()
    pacer = Pacer(1.0, max_catch_up_s=1.0, clock=wall.clock, sleep=wall.sleep, catch_up_rate=1.25)
    pacer.start(0.0)
    wall.t += 0.2  # the first step took 200 ms of wall time for 10 ms of device time (a stall)
    pacer.wait(0.01)
    assert pacer.lag_s == pytest.approx(0.19) and pacer.slips == 0 and wall.slept == []
    # Then 10 ms steps computed instantly: device time runs at 1.25x the wall clock until caught up
    # (the stalled step leaves 25 ms of wall time as credit), so heartbeats sent every 50 ms of wall
    # time arrive at most 1.25 x (50 + 25) = 94 ms of device time apart.
    t0, k = wall.t, 1
    while pacer.lag_s > 0 or k == 1:
        k += 1
        pacer.wait(0.01 * k)
    dev = 0.01 * (k - 1)
    assert wall.t - t0 == pytest.approx(dev / 1.25 - pacer.catch_up_credit_s, abs=0.011)
    assert wall.t - 100.0 == pytest.approx(0.01 * k, abs=0.011)  # caught up: on the original schedule
    assert all(dt <= 0.01 / 1.25 + 1e-12 for dt in wall.slept)
    assert pacer.slips == 0 and pacer.slipped_s == 0.0 and pacer.max_lag_s == pytest.approx(0.19)
    pacer.wait(0.01 * (k + 1))  # on schedule again: 10 ms of device time take 10 ms of wall time
    assert wall.slept[-1] == pytest.approx(0.01)


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
    with pytest.raises(ConfigError, match="catch_up_rate"):
        Pacer(1.0, catch_up_rate=5.0)
    with pytest.raises(ConfigError, match="catch_up_credit_s"):
        Pacer(1.0, catch_up_credit_s=0.2)


def _run_uneven(pacer, wall, cycles, chunk_s=0.005, chunks=7, expensive_s=0.012, cheap_s=0.001):
    """Device steps as the simulated device takes them: per cycle, one step that simulates the whole
    cycle ahead (``expensive_s`` of wall time) and cheap ones after it; returns (wall, device) after
    every step."""
    dev, trace = 0.0, []
    for _ in range(cycles):
        for k in range(chunks):
            wall.t += expensive_s if k == 0 else cheap_s
            dev += chunk_s
            pacer.wait(dev)
            trace.append((wall.t, dev))
    return trace


def test_uneven_steps_catch_up_when_the_computer_can():
    # Found in `ppod demo`: the device step that simulates a cycle ahead takes longer than its chunk
    # of device time, the steps after it are cheap. The catch-up rate was applied step by step from
    # the last step's end, so an expensive step's overrun was never made up and the cheap ones were
    # held to 1.25x: the device clock ran at 0.88x of the wall clock with the simulator's main thread
    # asleep a third of the time. Here the steps need 18 ms of wall time per 35 ms of device time.
    wall = FakeWall()
    pacer = Pacer(1.0, max_catch_up_s=1.0, clock=wall.clock, sleep=wall.sleep)
    pacer.start(0.0)
    wall.t += 0.5  # behind by half a second (a start-up burst)
    trace = _run_uneven(pacer, wall, cycles=200)
    assert pacer.slips == 0
    assert pacer.lag_s == pytest.approx(0.0, abs=0.013)  # caught up (within one expensive step)
    # ... never faster than the catch-up rate over any 50 ms of wall time, give or take the credit:
    # heartbeats sent every 50 ms of wall time arrive well inside the 150 ms watchdog.
    worst = 0.0
    for i, (w0, d0) in enumerate(trace):
        for w1, d1 in trace[i + 1:]:
            if w1 - w0 > 0.05:
                break
            worst = max(worst, d1 - d0)
    assert worst <= 1.25 * (0.05 + pacer.catch_up_credit_s) + 0.005 + 1e-12
    assert worst < 0.15 * 0.75


def test_uneven_steps_on_schedule_stay_on_it():
    # A computer fast enough on average, never behind by more than an expensive step: real time.
    wall = FakeWall()
    pacer = Pacer(1.0, clock=wall.clock, sleep=wall.sleep)
    pacer.start(0.0)
    trace = _run_uneven(pacer, wall, cycles=100)
    w, d = trace[-1]
    assert d / (w - 100.0) == pytest.approx(1.0, abs=0.01)
    assert pacer.slips == 0 and pacer.max_lag_s < 0.013

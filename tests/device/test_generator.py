"""WaveformGenerator (ROS-free): goals, corrections and the ways down, against the simulated device."""

import itertools
import threading
import time

import numpy as np
import pytest

from ppod_ros.actuation.generator import GeneratorState, WaveformGenerator
from ppod_ros.actuation.planning import GoalPlanner
from ppod_ros.can import DeviceLink, DeviceState, open_bus
from ppod_ros.device import default_device_config
from ppod_ros.motion import PlateMotion
from ppod_sim.device import SimDevice

_channels = itertools.count()
LINESINKX = PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0], name="LineSinkX",
                               ramp_time_s=0.1)


@pytest.fixture
def rig():
    config = default_device_config().with_can(interface="virtual", channel=f"test-gen-{next(_channels)}")
    dev_bus, host_bus, spy = open_bus(config.can), open_bus(config.can), open_bus(config.can)
    device = SimDevice(config, dev_bus, seed=1)
    link = DeviceLink(host_bus, config)
    gen = WaveformGenerator(link, GoalPlanner(config))
    yield config, device, link, gen, spy
    for bus in (dev_bus, host_bus, spy):
        bus.shutdown()


def run(device, link, seconds, gen=None):
    end = device.time_s + seconds
    while device.time_s < end - 1e-9:
        link.heartbeat()
        device.advance(0.05)
        link.poll()
        if gen is not None:
            gen.state()  # as the node's status timer does: also checks for missing acknowledgements


def drain(bus) -> list:
    out = []
    while (msg := bus.recv(0.0)) is not None:
        out.append(msg)
    return out


def test_an_accepted_goal_ramps_then_becomes_active_as_reported_by_the_device(rig):
    _, device, link, gen, _ = rig
    out = gen.submit(LINESINKX)
    assert out.accepted and out.seq is not None and out.plan is not None
    run(device, link, 0.06)
    state, _, progress = gen.state()
    assert state == GeneratorState.RAMPING and 0.0 <= progress < 1.0
    run(device, link, 0.4)
    assert gen.state()[0] == GeneratorState.ACTIVE
    truth = device.last_truth()
    assert truth is not None and abs(truth.accel[0, 0]) > 5.0  # the plate really moves


def test_over_limit_and_dry_run_goals_send_nothing(rig):
    _, device, link, gen, spy = rig
    drain(spy)
    too_big = PlateMotion.single(30, [200, 0, 0, 0, 0, 0], name="huge")
    out = gen.submit(too_big)
    assert not out.accepted and out.limit.startswith("limits.") and out.requested > out.limit_value
    dry = gen.submit(LINESINKX, dry_run=True)
    assert dry.accepted and dry.dry_run and dry.plan.prediction.current_peak_a.max() > 0
    assert drain(spy) == []
    assert gen.state()[0] == GeneratorState.IDLE


def test_corrections_apply_only_to_the_active_goal_and_are_clipped(rig):
    config, device, link, gen, _ = rig
    gen.submit(LINESINKX)
    run(device, link, 0.3)
    k = np.array([1, 3])
    small = np.full((2, 6), 0.01 + 0.005j)
    assert not gen.apply_correction(PlateMotion.single(30, [1, 0, 0, 0, 0, 0]).key, k, small).applied
    ok = gen.apply_correction(LINESINKX.key, k, small)
    assert ok.applied and ok.reason == ""
    np.testing.assert_allclose(gen.applied_correction_a[[0, 2]], small, atol=1e-3)
    big = np.full((2, 6), 50.0 + 0j)
    clipped = gen.apply_correction(None, k, big)
    assert clipped.applied and "clipped" in clipped.reason
    step = np.abs(gen.applied_correction_a[[0, 2]] - small)
    assert step.max() <= config.limits.correction_step_a + 1e-3
    bad = gen.apply_correction(None, np.array([11]), np.zeros((1, 6)))
    assert not bad.applied and "k in 1.." in bad.reason


def _table_ramps(config, frames) -> list[float]:
    from ppod_ros.can.codec import TableHeader, decode
    from ppod_ros.errors import ProtocolError

    out = []
    for msg in frames:
        try:
            rec = decode(msg, node_id=config.can.device_node_id, direction="to_device")
        except ProtocolError:  # the device's own frames: not what this test looks at
            continue
        if isinstance(rec, TableHeader):
            out.append(rec.ramp_s)
    return out


def test_a_goals_starting_correction_may_reach_its_own_limit_once_and_ramps_with_the_goal(rig):
    config, device, link, gen, spy = rig
    # Alternating signs (a yaw torque): uniform 0.6 A would lift the plate past LineSinkX's contact
    # margin, which the envelope refuses for corrected tables too; this test is about the caps.
    yaw = np.array([1, -1, 1, -1, 1, -1])
    goal = PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0], name="LineSinkX",
                              ramp_time_s=0.4)
    gen.submit(goal)
    run(device, link, 0.05)
    drain(spy)
    k = np.array([1])
    start = 0.6 * yaw[None, :] + 0.0j  # over one learning step (0.2 A), within start_correction_a (1 A)
    assert config.limits.correction_step_a < 0.6 < config.limits.start_correction_a
    out = gen.apply_correction(goal.key, k, start, start=True)
    assert out.applied and "clipped" not in out.reason
    np.testing.assert_allclose(gen.applied_correction_a[0], start[0], atol=2e-3)
    # The goal's ramp, not 50 ms (what is left of it at the latest: it starts at the next cycle start).
    [ramp] = _table_ramps(config, drain(spy))
    assert 0.4 - 1e-3 <= ramp <= 0.4 + 1 / 30 + 1e-3
    # Only the first correction of a goal is a start: a second one is an ordinary, clipped learning step.
    again = gen.apply_correction(goal.key, k, 1.4 * yaw[None, :] + 0.0j, start=True)
    assert again.applied and "correction_step_a" in again.reason
    assert np.abs(gen.applied_correction_a[0] - start[0]).max() <= config.limits.correction_step_a + 2e-3
    # ... sent at once, within the goal's ramp: over what is left of it, never the 50 ms correction ramp.
    [ramp] = _table_ramps(config, drain(spy))
    assert config.timing.min_ramp_s < ramp <= 0.4 + 2 / 30 + 1e-3
    # A start larger than its own limit is clipped to it, on the next goal.
    gen.submit(LINESINKX)
    big = gen.apply_correction(LINESINKX.key, k, 3.0 * yaw[None, :] + 0.0j, start=True)
    assert big.applied and "start_correction_a" in big.reason
    assert np.abs(gen.applied_correction_a[0]).max() <= config.limits.start_correction_a + 2e-3


def test_stop_ramps_to_rest_and_estop_latches_until_reset(rig):
    _, device, link, gen, _ = rig
    gen.submit(LINESINKX)
    run(device, link, 0.3)
    gen.stop(0.1)
    run(device, link, 0.02)
    assert gen.state()[0] == GeneratorState.STOPPING
    run(device, link, 0.3)
    assert gen.state()[0] == GeneratorState.IDLE and gen.at_rest()
    gen.submit(LINESINKX)
    run(device, link, 0.3)
    gen.estop()
    run(device, link, 0.1)
    state, reason, _ = gen.state()
    assert state == GeneratorState.FAULT and "ESTOP" in reason
    refused = gen.submit(LINESINKX)
    assert not refused.accepted and "ESTOP" in refused.reason
    gen.reset_estop()
    run(device, link, 0.1)
    assert gen.submit(LINESINKX).accepted


def test_ramp_down_and_disable_waits_for_rest_while_the_device_runs(rig):
    _, device, link, gen, _ = rig
    gen.submit(LINESINKX)
    run(device, link, 0.3)
    stop = threading.Event()

    def device_loop():  # the device in real time, in its own thread, as in its own process
        while not stop.is_set():
            device.advance(0.005)
            time.sleep(0.005)

    link.start()
    thread = threading.Thread(target=device_loop, daemon=True)
    thread.start()
    try:
        assert gen.ramp_down_and_disable(timeout_s=3.0)
        assert not np.any(device.player.played_table())  # at rest before the disable was sent
        assert link.wait_for(lambda: link.status.state == DeviceState.DISABLED, 2.0)
    finally:
        stop.set()
        thread.join(2)
        link.stop()


@pytest.fixture
def faulty_rig():
    from ppod_ros.can import FaultInjectingBus

    config = default_device_config().with_can(interface="virtual", channel=f"test-gen-{next(_channels)}")
    dev_bus, inner = open_bus(config.can), open_bus(config.can)
    host_bus = FaultInjectingBus(inner, seed=3, affect="send")
    device = SimDevice(config, dev_bus, seed=1)
    # Acknowledgement timeouts on the device's clock: these tests run the device faster than real time.
    link = DeviceLink(host_bus, config, clock=lambda: device.time_s)
    gen = WaveformGenerator(link, GoalPlanner(config))
    yield config, device, link, gen, host_bus
    host_bus.shutdown()
    dev_bus.shutdown()


def test_bus_errors_never_escape_the_generator_and_goals_are_answered_after_a_bus_off(faulty_rig):
    _, device, link, gen, bus = faulty_rig
    assert gen.submit(LINESINKX).accepted
    run(device, link, 0.5)
    bus.go_bus_off()
    out = gen.submit(LINESINKX.scaled(0.5))
    assert not out.accepted and "not sent" in out.reason and "CAN send failed" in out.reason
    correction = gen.apply_correction(None, np.array([1]), np.full((1, 6), 0.01 + 0j))
    assert not correction.applied and "not sent" in correction.reason
    bus.recover()
    run(device, link, 0.5)  # the device's watchdog may have tripped meanwhile; a goal re-enables it
    assert gen.submit(LINESINKX).accepted
    run(device, link, 1.0)
    assert gen.state()[0] == GeneratorState.ACTIVE


def test_a_lost_table_is_sent_again_and_played(faulty_rig):
    _, device, link, gen, bus = faulty_rig
    run(device, link, 0.1)
    bus.drop = 1.0
    out = gen.submit(LINESINKX)  # every frame of the table is lost: no acknowledgement comes
    bus.drop = 0.0
    assert out.accepted
    run(device, link, 1.5, gen)
    assert gen.ack_counters.get("ack_timeout", 0) >= 1 and gen.ack_counters.get("retries", 0) >= 1
    assert gen.state()[0] == GeneratorState.ACTIVE


def test_a_table_the_device_keeps_refusing_ends_in_a_reported_rejection_not_endless_ramping(faulty_rig):
    _, device, link, gen, bus = faulty_rig
    run(device, link, 0.1)
    bus.drop = 1.0  # nothing reaches the device, ever
    assert gen.submit(LINESINKX).accepted
    run(device, link, 3.0, gen)
    state, reason, _ = gen.state()
    assert state == GeneratorState.REJECTED and "not played" in reason and "acknowledgement" in reason
    assert gen.ack_counters["retries"] == 2 and gen.ack_counters["goals_rejected"] == 1


def test_an_over_limit_answer_rejects_the_goal_with_the_devices_reason():
    config = default_device_config().with_can(interface="virtual", channel=f"test-gen-{next(_channels)}")
    dev_bus, host_bus = open_bus(config.can), open_bus(config.can)
    try:
        # The device is stricter than the host here (its own configuration): it answers OVER_LIMIT.
        device = SimDevice(config.replace("limits", coil_current_a=0.5), dev_bus, seed=1)
        link = DeviceLink(host_bus, config, clock=lambda: device.time_s)
        gen = WaveformGenerator(link, GoalPlanner(config))
        assert gen.submit(LINESINKX).accepted
        run(device, link, 0.3, gen)
        state, reason, _ = gen.state()
        assert state == GeneratorState.REJECTED and "OVER_LIMIT" in reason
        assert gen.ack_counters == {"ack_over_limit": 1, "goals_rejected": 1}
    finally:
        dev_bus.shutdown()
        host_bus.shutdown()


def test_a_lost_older_correction_is_never_resent_over_a_newer_one(faulty_rig):
    _, device, link, gen, bus = faulty_rig
    assert gen.submit(LINESINKX).accepted
    run(device, link, 0.8, gen)
    k = np.array([1])
    bus.drop = 1.0
    lost = gen.apply_correction(None, k, np.full((1, 6), 0.05 + 0j))
    bus.drop = 0.0
    newer = gen.apply_correction(None, k, np.full((1, 6), 0.02j))
    assert lost.applied and newer.applied
    run(device, link, 1.5, gen)
    assert gen.ack_counters.get("superseded_by_newer", 0) == 1 and gen.ack_counters.get("retries", 0) == 0
    played = device.player.active
    assert played.seq == newer.seq
    sent = newer.result.currents_a
    rows = played.currents.shape[0]
    np.testing.assert_allclose(played.currents, sent[:rows], atol=1e-9)
    assert not np.any(sent[rows:])
    np.testing.assert_allclose(gen.applied_correction_a, newer.result.applied_a)


def test_a_correction_is_judged_on_the_measured_plate_only_when_measured_on_the_table_playing(rig):
    _, device, link, gen, _ = rig
    out = gen.submit(LINESINKX)
    run(device, link, 0.3)
    k = np.array([1])
    small = np.full((1, 6), 0.01 + 0j)
    measured = device.last_truth().accel
    stale = gen.apply_correction(None, k, small, measured_accel=measured, measured_seq=(out.seq % 255) + 7)
    assert stale.applied and stale.result.measured_ratios is None  # not the table playing: nominal plant
    playing = stale.seq
    fresh = gen.apply_correction(None, k, 2 * small, measured_accel=measured, measured_seq=playing)
    assert fresh.applied and fresh.result.measured_ratios is not None
    assert set(fresh.result.measured_ratios) == {"limits.plate_accel_mps2", "limits.plate_angular_accel_radps2",
                                                 "limits.contact_margin_mps2"}


@pytest.fixture
def leg_rig():
    """The simulated device of the demo's seed on the device's own clock, every firmware period's
    largest leg displacement recorded as (end time, m) in ``legs``."""
    config = default_device_config().with_can(interface="virtual", channel=f"test-gen-{next(_channels)}")
    dev_bus, host_bus, spy = open_bus(config.can), open_bus(config.can), open_bus(config.can)
    device = SimDevice(config, dev_bus, seed=7)
    link = DeviceLink(host_bus, config, clock=lambda: device.time_s)
    gen = WaveformGenerator(link, GoalPlanner(config))
    legs = []
    check = device._check_faults

    def watch(current, voltage, leg, end_s):
        legs.append((end_s, float(np.max(np.abs(leg)))))
        return check(current, voltage, leg, end_s)

    device._check_faults = watch
    yield config, device, link, gen, spy, legs
    for bus in (dev_bus, host_bus, spy):
        bus.shutdown()


def test_a_correction_during_a_goals_ramp_never_shortens_it(leg_rig):
    """Found in the demo: the planner reversed a spin (alpha_z 312 -> 331 rad/s^2, opposite phase) and the
    feedback's next correction arrived 16 ms into the goal's 0.5 s ramp. Sent with the 50 ms correction
    ramp, it crossfaded from the mix playing (still the old motion) to the new one in 50 ms: the legs
    overshot to 2.4 mm and the device faulted on stroke (limit 2 mm)."""
    config, device, link, gen, spy, legs = leg_rig
    amp = [5.2, 8.4, 0.4, 12.8, 34.2, 312.0]
    one = PlateMotion.single(30, amp, [0.26, -0.44, -1.39, 0.33, -2.17, np.pi], name="mpc")
    other = PlateMotion.single(30, amp, [-3.11, 2.69, -1.57, 0.54, 0.81, 0.0], name="mpc")
    assert gen.submit(one).accepted
    run(device, link, 1.5, gen)
    steady = max(m for t, m in legs if t > device.time_s - 0.5)
    drain(spy)
    assert gen.submit(other).accepted
    t_goal = device.time_s
    run(device, link, 0.02, gen)
    out = gen.apply_correction(None, np.array([1]), np.full((1, 6), 0.01 + 0j))
    assert out.applied
    ramps = _table_ramps(config, drain(spy))
    # The goal's table (0.5 s), then the correction over what is left of it, not 50 ms.
    assert ramps[0] == pytest.approx(config.timing.default_ramp_s, abs=1e-3)
    assert ramps[-1] >= config.timing.default_ramp_s - (device.time_s - t_goal) - 1e-3
    run(device, link, 1.5, gen)
    assert device.state == DeviceState.ENABLED and not device.faults
    during = max(m for t, m in legs if t > t_goal)
    assert during <= 1.05 * steady < config.limits.leg_stroke_m
    # After the ramp a correction is crossfaded in over the short correction ramp again.
    drain(spy)
    assert gen.apply_correction(None, np.array([1]), np.full((1, 6), 0.02 + 0j)).applied
    assert _table_ramps(config, drain(spy)) == [pytest.approx(config.timing.min_ramp_s, abs=1e-3)]


@pytest.mark.parametrize("reverse", [False, True])
def test_a_goal_asking_for_a_50_ms_ramp_is_crossfaded_slowly_enough_for_the_legs(reverse, leg_rig):
    """Crossfaded in 50 ms, a spin at 61 % of the legs' stroke overshot its steady stroke by 37 % from
    rest and by 80 % reversed (the device faulted); timing.min_goal_ramp_s (0.2 s) bounds it."""
    config, device, link, gen, _, legs = leg_rig
    amp = [5.2, 8.4, 0.4, 12.8, 34.2, 312.0]
    phase = np.array([0.26, -0.44, -1.39, 0.33, -2.17, np.pi])
    run(device, link, 0.3, gen)
    if reverse:
        assert gen.submit(PlateMotion.single(30, amp, phase, name="one")).accepted
        run(device, link, 1.5, gen)
    out = gen.submit(PlateMotion.single(30, amp, phase + (np.pi if reverse else 0.0), name="fast",
                                        ramp_time_s=0.05))
    assert out.accepted and out.plan.ramp_s == pytest.approx(config.timing.min_goal_ramp_s)
    t_goal = device.time_s
    run(device, link, 1.5, gen)
    steady = max(m for t, m in legs if t > device.time_s - 0.5)
    during = max(m for t, m in legs if t > t_goal)
    assert device.state == DeviceState.ENABLED and not device.faults
    assert during <= 1.03 * steady

"""The simulated device in its own process, reached across processes through the localhost bridge.

Bounded: the simulator stops by itself after --duration seconds of device time, every wait has a
timeout, and the process is terminated (then killed) in any case.
"""

import json
import re
import select
import subprocess
import sys
import time

import numpy as np
import pytest

from ppod_ros.actuation.planning import GoalPlanner
from ppod_ros.can import AckResult, DeviceLink, DeviceState, open_bus
from ppod_ros.device import default_device_config
from ppod_ros.motion import PlateMotion, acceleration_error
from ppod_sim.sensors import SensorErrors

LINESINKX = PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0], ramp_time_s=0.2)


@pytest.fixture
def sim_process(tmp_path):
    truth = tmp_path / "truth.jsonl"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "ppod_sim",
            "--port",
            "0",
            "--duration",
            "20",
            "--mismatch",
            "zero",
            "--truth-out",
            str(truth),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 30.0)
        line = proc.stdout.readline() if ready else ""
        match = re.search(r"on (ws://127\.0\.0\.1:\d+/)", line)
        assert match, (line, proc.stderr.read() if proc.poll() is not None else "")
        yield match.group(1), truth, proc
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=10)
        proc.stdout.close()
        proc.stderr.close()


@pytest.mark.slow
def test_a_goal_runs_across_processes_and_the_watchdog_stops_it_when_heartbeats_stop(sim_process):
    url, truth_path, proc = sim_process
    config = default_device_config().with_can(interface="remote", channel=url)
    bus = open_bus(config.can)
    link = DeviceLink(bus, config)
    try:
        link.start(heartbeat=True)
        assert link.handshake(timeout_s=5.0).simulated
        link.enable()
        seq, plan = link.send_goal(GoalPlanner(config), LINESINKX)
        link.wait_for_ack(seq, AckResult.ACTIVE, timeout_s=5.0)
        at_start = link.counters.summaries
        assert link.wait_for(lambda: link.counters.summaries >= at_start + 20, timeout_s=10.0)
        assert link.status.state == DeviceState.ENABLED and link.status.active_seq == seq
        # The device's accelerometer summaries agree with the goal through the first-order model of
        # its (default, lab-like) sensors: gains, tilted axes, bending.
        s = link.summaries[-1]
        layout = config.accelerometers
        w, bend = SensorErrors.default(12).sensing(np.asarray(layout.position_m), np.asarray(layout.axis))
        H = np.hstack([w, np.cross(layout.position_m, w)])
        H[:, 2] += bend
        expected = H @ LINESINKX.phasor_table(1)[0]
        assert np.max(np.abs(s.phasors[0] - expected)) < 0.02 * np.max(np.abs(expected))
        assert s.frequency_hz == 30.0 and s.table_seq == seq
        # The plate's true acceleration harmonics, written by the simulator, match the goal within 1 %.
        records = [json.loads(x) for x in truth_path.read_text().splitlines()]
        last = [r for r in records if r["table_seq"] == seq][-1]
        achieved = np.array(last["accel_re"]) + 1j * np.array(last["accel_im"])
        assert acceleration_error(LINESINKX.phasor_table(achieved.shape[0]), achieved)[1] <= 0.01
        # Stop the heartbeats: the device's watchdog ramps the plate down on its own clock.
        link.stop()
        t0 = time.monotonic()
        assert link.wait_for(lambda: link.status.state == DeviceState.WATCHDOG, timeout_s=2.0)
        assert time.monotonic() - t0 < 1.5
    finally:
        link.stop()
        bus.shutdown()
    proc.terminate()
    out, _ = proc.communicate(timeout=10)
    assert "stopped at device time" in out and proc.returncode == 0

"""CAN bus load, goal-to-frame latency on the ROS-free path, bridge throughput, simulator speed.

Sections (all on this machine, no ROS):
  load     steady-state bus load from the frames actually sent (both directions, worst-case bit
           stuffing), simulated device and host link on a virtual bus, per goal
  latency  a two-harmonic goal: plan + encode until the first and the commit frame are on the bus
           (in process, wall clock), and goal to the device's ACCEPTED / ACTIVE acknowledgements
           across processes through the localhost bridge (simulator in real time)
  node     the waveform_generator node: a two-harmonic goal received on its topic (and by its
           SetPlateMotion service) until the first frame of its table is on the bus (ROS in process,
           simulated device on a virtual bus)
  bridge   frames per second the python-can-remote bridge carries from the device to a client
  sim      how much faster than real time the simulated plant and the whole device run
  heartbeat  the host's heartbeat thread (50 ms) on a loaded machine: the interval between its
           sends while a thread of the same process runs bursts of Python code (40 ms of CPU five
           times a second: the generator's goal checks, holding the GIL) and --busy processes keep
           the cores busy, at normal scheduling and at the real-time priority ppod up asks for the
           waveform generator, alternating runs; the device's watchdog trips after 150 ms without one
  stalls   the host's GIL held in C for --stall-ms (default 330: rclpy's publish holds it that long
           while Fast DDS matches a new reader of its topic) --stalls times, 1 s apart: the heartbeats'
           intervals as the device receives them (the bridge and the device's listener in a process of
           their own), with the host's heartbeat thread alone and with the keeper process whose lease
           it renews (ppod_ros/can/keeper.py, lease 0.5 s); the device's watchdog trips after 150 ms

examples:
  ppod bench can
  ppod bench can --sections load latency --repeats 500
  ppod bench can --quick
  ppod bench can --sections heartbeat --busy 6 --seconds 15
  ppod bench can --sections stalls --stalls 20
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import json
import math
import os
import re
import select
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import numpy as np

HELP = "CAN bus load and goal-to-frame latency (ROS-free path), bridge throughput, simulator speed, heartbeats"
SECTIONS = ("load", "latency", "node", "bridge", "sim", "heartbeat", "stalls")
_channels = itertools.count()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--sections",
        nargs="+",
        choices=SECTIONS,
        default=list(SECTIONS),
        help="which sections to run (default: all)",
    )
    parser.add_argument(
        "--seconds", type=float, default=3.0, help="device seconds per bus-load run (default 3)"
    )
    parser.add_argument(
        "--repeats", type=int, default=200, help="goals per latency measurement (default 200)"
    )
    parser.add_argument("--busy", type=int, default=6,
                        help="heartbeat, stalls: busy processes beside the heartbeat's process (default 6)")
    parser.add_argument("--stalls", type=int, default=20, help="stalls: GIL holds per arm (default 20)")
    parser.add_argument("--stall-ms", type=float, default=330.0,
                        help="stalls: how long each GIL hold lasts (ms, default 330)")
    parser.add_argument("--quick", action="store_true", help="short runs (a smoke test of the benchmark)")


def _goals():
    from ppod_ros.motion import PlateMotion

    two = PlateMotion(
        30.0,
        [1, 2],
        [[10, 0, 0, 0, 100, 0], [1, 0, 0, 0, 10, 0]],
        [[0, 0, 0, 0, 4.71238898, 0], [0, 0, 0, 0, 0, 0]],
        name="two-harmonic",
        ramp_time_s=0.1,
    )
    amp = np.zeros((5, 6))
    amp[:, 0] = [5, 0.5, 0.5, 0.2, 0.2]
    return [
        ("idle (no table)", None),
        (
            "LineSinkX, 30 Hz",
            PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0], ramp_time_s=0.1),
        ),
        ("two harmonics, 30 Hz", two),
        ("five harmonics, 30 Hz", PlateMotion(30.0, [1, 2, 3, 4, 5], amp, np.zeros((5, 6)), ramp_time_s=0.1)),
        ("two harmonics, 45 Hz", PlateMotion(45.0, two.k, two.amplitude, two.phase, ramp_time_s=0.1)),
        (
            "LineSinkX at 20 Hz",
            PlateMotion.single(20, [4, 0, 0, 0, 40, 0], [0, 0, 0, 0, 4.71238898, 0], ramp_time_s=0.1),
        ),
    ]


def _rig(config):
    from ppod_ros.can import DeviceLink, open_bus
    from ppod_sim.device import SimDevice

    cfg = config.with_can(interface="virtual", channel=f"bench-can-{next(_channels)}")
    buses = [open_bus(cfg.can) for _ in range(3)]
    return cfg, buses, SimDevice(cfg, buses[0]), DeviceLink(buses[1], cfg)


def _run_rig(dev, link, spy, duration: float, record: list[int] | None = None) -> None:
    """Advance the device in heartbeat periods, the host answering; record the sizes of all frames."""
    end = dev.time_s + duration
    while dev.time_s < end - 1e-9:
        link.heartbeat()
        dev.advance(link.config.can.heartbeat_period_s)
        link.poll()
        while (msg := spy.recv(0)) is not None:
            if record is not None:
                record.append(len(msg.data))


def bench_load(args) -> list[dict]:
    from ppod_ros.actuation.planning import GoalPlanner
    from ppod_ros.can.protocol import bus_load, frame_bits
    from ppod_ros.device import default_device_config

    rows = []
    seconds = 1.0 if args.quick else args.seconds
    for name, goal in _goals():
        cfg, buses, dev, link = _rig(default_device_config())
        spy = buses[2]
        link.enable()
        if goal is not None:
            link.send_plan(GoalPlanner(cfg).plan(goal))
        _run_rig(dev, link, spy, 0.5)  # ramp and first summaries
        sizes: list[int] = []
        t0 = dev.time_s
        _run_rig(dev, link, spy, seconds, sizes)
        duration = dev.time_s - t0
        load = bus_load(sizes, duration, cfg.can.bitrate)
        rows.append(
            {
                "goal": name,
                "frames_per_s": len(sizes) / duration,
                "bits_per_s": sum(frame_bits(n) for n in sizes) / duration,
                "load": load,
                "limit": cfg.can.bus_load_limit,
                "summary_harmonics": (link.summaries[-1].k.size if link.summaries else 0),
            }
        )
        for bus in buses:
            bus.shutdown()
    return rows


def _percentiles(values: list[float]) -> dict:
    v = np.asarray(values)
    return {
        "median": float(np.median(v)),
        "p99": float(np.percentile(v, 99)),
        "max": float(v.max()),
        "n": len(v),
    }


class _StampingBus(can.BusABC):
    """Records when each frame is handed to the inner bus (for the latency measurement)."""

    def __init__(self, inner):
        self.inner = inner
        self.stamps: list[tuple[float, int]] = []
        super().__init__(channel=None)

    def send(self, msg, timeout=None):
        self.inner.send(msg, timeout)
        self.stamps.append((time.perf_counter(), msg.arbitration_id))

    def _recv_internal(self, timeout):
        return self.inner.recv(timeout), False


def bench_latency_in_process(args) -> dict:
    """Goal in hand -> first frame and -> commit frame on a virtual bus (plan, quantise, encode, send)."""
    from ppod_ros.actuation.planning import GoalPlanner
    from ppod_ros.can import DeviceLink, open_bus
    from ppod_ros.can.protocol import Fn
    from ppod_ros.device import default_device_config

    cfg = default_device_config().with_can(interface="virtual", channel=f"bench-lat-{next(_channels)}")
    sink, raw = open_bus(cfg.can), open_bus(cfg.can)
    bus = _StampingBus(raw)
    link = DeviceLink(bus, cfg)
    planner = GoalPlanner(cfg)
    goal = dict(_goals())["two harmonics, 30 Hz"]
    first, commit, plan_only = [], [], []
    for i in range(20 if args.quick else args.repeats):
        motion = goal.scaled(1.0 - 0.001 * (i % 100))  # a new goal every time: no cache can help
        bus.stamps.clear()
        t0 = time.perf_counter()
        plan = planner.plan(motion)
        t1 = time.perf_counter()
        link.send_plan(plan)
        plan_only.append(t1 - t0)
        first.append(bus.stamps[0][0] - t0)
        commit.append(next(t for t, arb in bus.stamps if arb >> 4 == Fn.TABLE_COMMIT) - t0)
        while sink.recv(0) is not None:
            pass
    frames = len(bus.stamps)
    for b in (bus, sink, raw):
        b.shutdown()
    return {
        "plan": _percentiles(plan_only),
        "first_frame": _percentiles(first),
        "commit_frame": _percentiles(commit),
        "frames_per_goal": frames,
    }


def bench_latency_node(args) -> dict:
    """Goal published to / requested from the waveform_generator node -> its first table frame on the bus."""
    from ppod_msgs.msg import PlateMotion as PlateMotionMsg
    from ppod_msgs.srv import SetPlateMotion
    from rclpy.parameter import Parameter

    from ppod_nodes.common import qos, topics
    from ppod_nodes.common.convert import motion_to_msg
    from ppod_nodes.common.session import RosSession
    from ppod_nodes.waveform_generator import WaveformGeneratorNode
    from ppod_ros.can.protocol import Fn
    from ppod_ros.device import default_device_config
    from ppod_sim.process import SimProcess

    channel = f"bench-node-{next(_channels)}"
    cfg = default_device_config().with_can(interface="virtual", channel=channel)
    sim = SimProcess(cfg, port=0, rate=1.0, seed=1, channel=channel)
    stop = threading.Event()
    sim_thread = threading.Thread(target=sim.run, kwargs={"stop": stop}, daemon=True)
    sim_thread.start()
    spy = can.Bus(interface="virtual", channel=channel)
    goal = dict(_goals())["two harmonics, 30 Hz"]
    n = 10 if args.quick else max(20, args.repeats // 4)
    out: dict = {}
    with RosSession("bench_can") as ros:
        node = ros.add(WaveformGeneratorNode(context=ros.context, parameter_overrides=[
            Parameter("can_interface", value="virtual"), Parameter("can_channel", value=channel)]))
        node.trigger_configure()
        node.trigger_activate()
        pub = ros.node.create_publisher(PlateMotionMsg, topics.GOAL, qos.COMMANDS)
        ros.wait_until(lambda: pub.get_subscription_count() > 0, 5.0)
        client = ros.node.create_client(SetPlateMotion, topics.SET_MOTION)
        client.wait_for_service(timeout_sec=5.0)

        def first_table_frame(after: float) -> float:
            deadline = time.time() + 2.0
            while time.time() < deadline:
                msg = spy.recv(0.5)
                if msg is not None and msg.arbitration_id >> 4 == Fn.TABLE_HEADER and msg.timestamp >= after:
                    return msg.timestamp
            raise RuntimeError("no table frame within 2 s")

        for path in ("topic", "service"):
            lat = []
            for i in range(n):
                msg = motion_to_msg(goal.scaled(0.9 + 0.001 * i))
                while spy.recv(0) is not None:
                    pass
                t0 = time.time()
                if path == "topic":
                    pub.publish(msg)
                else:
                    client.call_async(SetPlateMotion.Request(motion=msg))
                lat.append(first_table_frame(t0) - t0)
                time.sleep(0.1)
            out[path] = _percentiles(lat)
        node.trigger_deactivate()
    spy.shutdown()
    stop.set()
    sim_thread.join(5)
    sim.close()
    return out


def _start_sim(extra: list[str]) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "ppod_sim", "--port", "0", *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    ready, _, _ = select.select([proc.stdout], [], [], 30.0)
    line = proc.stdout.readline() if ready else ""
    match = re.search(r"on (ws://127\.0\.0\.1:\d+/)", line)
    if not match:
        proc.kill()
        raise RuntimeError(f"simulator did not start: {line!r}")
    return proc, match.group(1)


def _stop_sim(proc: subprocess.Popen) -> None:
    proc.terminate()
    try:
        proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate(timeout=10)


def bench_latency_bridge(args) -> dict:
    """Goal -> ACCEPTED and -> ACTIVE acknowledgements, simulator in its own process at real time."""
    from ppod_ros.actuation.planning import GoalPlanner
    from ppod_ros.can import AckResult, DeviceLink, open_bus
    from ppod_ros.device import default_device_config

    repeats = 10 if args.quick else max(20, args.repeats // 5)
    proc, url = _start_sim(["--duration", str(10 + repeats)])
    accepted, active = [], []
    try:
        cfg = default_device_config().with_can(interface="remote", channel=url)
        bus = open_bus(cfg.can)
        link = DeviceLink(bus, cfg)
        link.start(heartbeat=True)
        link.handshake(timeout_s=5.0)
        link.enable()
        planner = GoalPlanner(cfg)
        goal = dict(_goals())["two harmonics, 30 Hz"]
        rng = np.random.default_rng(0)
        for i in range(repeats):
            time.sleep(0.1 + 0.05 * rng.random())  # land at random points of the device's cycle
            t0 = time.perf_counter()
            seq = link.send_plan(planner.plan(goal.scaled(1.0 - 0.01 * (i % 10))))
            link.wait_for_ack(seq, AckResult.ACCEPTED, timeout_s=2.0)
            accepted.append(time.perf_counter() - t0)
            link.wait_for_ack(seq, AckResult.ACTIVE, timeout_s=2.0)
            active.append(time.perf_counter() - t0)
        link.stop()
        bus.shutdown()
    finally:
        _stop_sim(proc)
    return {"accepted": _percentiles(accepted), "active": _percentiles(active)}


def bench_bridge(args) -> list[dict]:
    """Frames per second from the device's virtual bus to a remote client, paced, counting losses."""
    from ppod_ros.can.codec import SummaryData
    from ppod_sim.bridge import Bridge

    channel = f"bench-bridge-{next(_channels)}"
    bridge = Bridge(channel)
    device = can.Bus(interface="virtual", channel=channel)
    client = can.Bus(interface="remote", channel=bridge.url)
    time.sleep(0.2)
    rows = []
    seconds = 0.5 if args.quick else 2.0
    for rate in (1000, 2000, 4000, 8000, 16000):
        n = int(rate * seconds)
        got: list[float] = []

        def receive(n=n, got=got):
            deadline = time.monotonic() + seconds + 5.0
            while len(got) < n and time.monotonic() < deadline:
                if client.recv(0.2) is not None:
                    got.append(time.monotonic())

        rx = threading.Thread(target=receive)
        rx.start()
        msg = SummaryData(0, 0, 1, 1 + 1j).encode(1)
        t0 = time.monotonic()
        for i in range(n):
            delay = t0 + i / rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            device.send(msg)
        sent_s = time.monotonic() - t0
        rx.join()
        done_s = (got[-1] - t0) if got else math.nan
        rows.append(
            {
                "offered_fps": rate,
                "sent_fps": n / sent_s,
                "received": len(got),
                "sent": n,
                "delivered_fps": len(got) / done_s if got else 0.0,
                "lag_s": done_s - sent_s,
            }
        )
    client.shutdown()
    device.shutdown()
    bridge.close()
    return rows


def bench_sim(args) -> list[dict]:
    from ppod_ros.actuation.planning import GoalPlanner
    from ppod_ros.device import default_device_config
    from ppod_ros.motion import PlateMotion
    from ppod_sim.plant import PlantSimulator

    motion = PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0], ramp_time_s=0.1)
    seconds = 1.0 if args.quick else 3.0
    rows = []
    base = default_device_config()
    for exact in (True, False):
        cfg = base.replace("sim", exact_geometry=exact)
        # The plant alone, one cycle (280 control steps, 70 reported rows) per call.
        plant = PlantSimulator(cfg)
        table = GoalPlanner(cfg).plant.feedforward(motion, 1)
        from ppod_ros.actuation.harmonics import synthesize

        ref = synthesize(table, [1], 2 * np.pi * np.arange(281) / 280)
        plant.simulate(ref, 1 / 30 / 280, every=4)
        cycles = int(30 * seconds)
        t0 = time.perf_counter()
        for _ in range(cycles):
            plant.simulate(ref, 1 / 30 / 280, every=4)
        wall = time.perf_counter() - t0
        rows.append(
            {
                "what": "plant, one cycle per call",
                "exact_geometry": exact,
                "device_s": cycles / 30,
                "wall_s": wall,
                "factor": cycles / 30 / wall,
            }
        )
        # The whole device (firmware, plant, sensors, CAN output) with a host link answering.
        for batch, label in (
            (1, "device + host link in one process, 5 ms periods (real-time mode)"),
            (1 << 30, "device + host link in one process, cycle batches (fast mode)"),
        ):
            cfg2, buses, dev, link = _rig(cfg)
            link.enable()
            link.send_plan(GoalPlanner(cfg2).plan(motion))
            dev.advance(0.2, batch)
            t0 = time.perf_counter()
            end = dev.time_s + seconds
            while dev.time_s < end:
                link.heartbeat()
                dev.advance(0.05, batch)
                link.poll()
                while buses[2].recv(0) is not None:
                    pass
            wall = time.perf_counter() - t0
            rows.append(
                {
                    "what": label,
                    "exact_geometry": exact,
                    "device_s": seconds,
                    "wall_s": wall,
                    "factor": seconds / wall,
                }
            )
            for bus in buses:
                bus.shutdown()
    return rows


class _SendTimes(can.BusABC):
    """A bus that keeps the monotonic time of every send (in the sending thread)."""

    def __init__(self):
        super().__init__(channel="heartbeat-bench")
        self.times: list[float] = []

    def send(self, msg, timeout=None):
        self.times.append(time.monotonic())

    def _recv_internal(self, timeout):
        time.sleep(min(timeout or 0.0, 0.01))
        return None, False


def _heartbeat_child(priority: int, seconds: float, queue) -> None:
    """In a process of its own: ask for ``priority`` as a launched node does, run bursts of Python code
    in one thread (the generator's goal checks) and a link's heartbeat thread; report the send times."""
    from ppod_nodes.common.runner import REALTIME_ENV, take_realtime_priority
    from ppod_ros.can import DeviceLink
    from ppod_ros.device import default_device_config

    said = take_realtime_priority({REALTIME_ENV: str(priority)})
    stop = threading.Event()

    def python_work():   # 40 ms of CPU five times a second, as a goal's checks come (holding the GIL)
        a = np.random.default_rng(0).random((40, 40))
        while not stop.is_set():
            t0 = time.thread_time()
            while time.thread_time() - t0 < 0.04:
                s = 0
                for i in range(2000):
                    s += i
                a = a @ a.T
                a /= np.abs(a).max()
            stop.wait(0.2)

    worker = threading.Thread(target=python_work, daemon=True)
    worker.start()
    bus = _SendTimes()
    link = DeviceLink(bus, default_device_config())
    link.start_heartbeat()
    time.sleep(seconds)
    link.stop_heartbeat()
    bus.shutdown()
    stop.set()
    worker.join()
    queue.put({"said": said, "policy": os.sched_getscheduler(0), "times": bus.times})


def bench_heartbeat(args) -> list[dict]:
    """Heartbeat intervals of a process running Python code beside busy processes, at normal
    scheduling and at the real-time priority ``ppod up`` asks for the waveform generator."""
    import multiprocessing
    from unittest import mock

    from ppod_bench.solver_stalls import busy_core
    from ppod_nodes.launch.spec import NodeSpec

    seconds = 2.0 if args.quick else max(2.0, float(args.seconds))
    arms = [("normal scheduling", 0), ("SCHED_FIFO 10 (ppod up's waveform_generator)", 10)]
    intervals: dict[str, list[float]] = {name: [] for name, _ in arms}
    granted: dict[str, bool] = {}
    said: dict[str, str] = {}
    ctx = multiprocessing.get_context("spawn")
    for _ in range(1 if args.quick else 2):
        for name, priority in arms:
            queue = ctx.Queue()
            child = ctx.Process(target=_heartbeat_child, args=(priority, seconds, queue), daemon=True)
            with busy_core(count=args.busy):
                # The environment ppod up gives such a node (its BLAS on one thread), for the child's start.
                with mock.patch.dict(os.environ, NodeSpec("heartbeat", "-", realtime_priority=priority).env):
                    child.start()
                got = queue.get(timeout=seconds + 60.0)
                child.join()
            intervals[name] += list(np.diff(got["times"]))
            granted[name] = priority == 0 or got["policy"] == os.SCHED_FIFO
            said[name] = got["said"][1] if got["said"] else ""
    rows = []
    for name, priority in arms:
        iv = 1e3 * np.asarray(intervals[name])
        rows.append({"scheduling": name if granted[name] else f"{name}: not granted, normal",
                     "priority": priority, "granted": granted[name], "n": int(iv.size),
                     "median_ms": float(np.median(iv)), "p99_ms": float(np.percentile(iv, 99)),
                     "max_ms": float(iv.max()), "over_100_ms": int(np.sum(iv > 100.0)),
                     "busy_processes": args.busy, "seconds_per_run": seconds, "node_said": said[name]})
    return rows


#: The device's side of the stall measurement: the localhost bridge on a virtual channel and a listener
#: that stamps every heartbeat frame with this machine's monotonic clock (shared by its processes);
#: prints the bridge's address, then the stamps (JSON) at end-of-file on its input.
_RECORDER = """
import json, sys, threading, time
import can
from ppod_ros.can.protocol import Fn, can_id
from ppod_sim.bridge import Bridge
node, channel = int(sys.argv[1]), sys.argv[2]
bridge = Bridge(channel)
bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False,
              can_filters=[{"can_id": can_id(Fn.HEARTBEAT, node), "can_mask": 0x7FF}])
beats, stop = [], threading.Event()
def listen():
    while not stop.is_set():
        if bus.recv(0.05) is not None:
            beats.append(time.monotonic())
threading.Thread(target=listen, daemon=True).start()
print(bridge.url, flush=True)
sys.stdin.read()
stop.set()
print(json.dumps(beats), flush=True)
"""


class HeartbeatRecorder:
    """A device-side heartbeat listener behind a bridge, in a process of its own (:data:`_RECORDER`):
    ``url`` to open a ``remote`` bus on, ``beats()`` the arrival times (``time.monotonic``) at the end."""

    def __init__(self, device_node: int):
        self.process = subprocess.Popen([sys.executable, "-c", _RECORDER, str(device_node),
                                         f"heartbeat-recorder-{os.getpid()}-{next(_channels)}"],
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        self.url = self.process.stdout.readline().strip()
        if not self.url.startswith("ws://127.0.0.1:"):
            self.kill()
            raise RuntimeError(f"heartbeat recorder did not start: {self.url!r}")

    def beats(self) -> list[float]:
        out, _ = self.process.communicate("", timeout=30)
        return json.loads(out.strip().splitlines()[-1])

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait(10)


def hold_the_gil(seconds: float) -> None:
    """Sleep in C without releasing the GIL: no other Python thread of this process can run (as while
    rclpy publishes to a topic whose new reader Fast DDS is matching)."""
    import ctypes
    import ctypes.util

    libc = ctypes.PyDLL(ctypes.util.find_library("c"))   # PyDLL: the call keeps the GIL
    libc.usleep(int(seconds * 1e6))


#: The keeper's lease in the stalls section: shorter than the generator's default (1 s), so a stall
#: the keeper covers here it covers there.
STALL_LEASE_S = 0.5


def bench_stalls(args) -> list[dict]:
    """Heartbeat intervals at the device while the host's GIL is held (see the module docstring)."""
    from ppod_bench.solver_stalls import busy_core
    from ppod_ros.device import default_device_config

    stalls = 2 if args.quick else max(1, int(args.stalls))
    hold = float(args.stall_ms) / 1e3
    busy = int(getattr(args, "busy", 0))
    config = default_device_config()
    recorder = HeartbeatRecorder(config.can.device_node_id)
    windows: dict[str, tuple[float, float]] = {}
    summaries: dict[str, str] = {}
    with contextlib.ExitStack() as stack:
        if busy:
            stack.enter_context(busy_core(count=busy))
        try:
            _stall_arms(recorder, config, stalls, hold, windows, summaries)
            beats = np.asarray(recorder.beats())
        finally:
            recorder.kill()
    rows = []
    for arm, (t0, t1) in windows.items():
        iv = 1e3 * np.diff(beats[(beats >= t0) & (beats <= t1)])
        source = "the node's thread" if arm == "thread" else f"keeper process (lease {STALL_LEASE_S:g} s)"
        rows.append({"heartbeats_from": source,
                     "stalls": stalls, "stall_ms": 1e3 * hold, "busy_processes": busy, "n": int(iv.size),
                     "median_ms": float(np.median(iv)), "max_ms": float(iv.max()),
                     "over_150_ms": int(np.sum(iv > 150.0)), "keeper": summaries[arm]})
    return rows


def _stall_arms(recorder: HeartbeatRecorder, config, stalls: int, hold: float, windows: dict, summaries: dict) -> None:
    """Both arms of :func:`bench_stalls` against ``recorder``: each arm's window and keeper summary."""
    from ppod_ros.can import DeviceLink, open_bus

    config = config.with_can(interface="remote", channel=recorder.url)
    bus = open_bus(config.can)
    try:
        for arm, lease in (("thread", None), ("keeper", STALL_LEASE_S)):
            link = DeviceLink(bus, config)
            link.start_heartbeat(keeper_lease_s=lease)
            deadline = time.monotonic() + 30.0
            while lease is not None and not link._keeper.ready() and time.monotonic() < deadline:
                time.sleep(0.01)
            time.sleep(0.5)
            t0 = time.monotonic()
            # Beats before the first stall open the window, so its gap is measured whole: opened at the
            # stall itself, the beat before it could be received before the window and the gap missed
            # (its test counted 1 of 2 stalls over 150 ms once in about 14 runs beside a busy core).
            time.sleep(0.2)
            for _ in range(stalls):
                hold_the_gil(hold)
                time.sleep(1.0)
            windows[arm] = (t0, time.monotonic())
            link.stop_heartbeat()
            summaries[arm] = link.counters.keeper
            time.sleep(0.3)
    finally:
        bus.shutdown()


def _print_table(title: str, header: list[str], rows: list[list[str]]) -> None:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    print(f"\n{title}")
    print("  ".join(h.ljust(w) for h, w in zip(header, widths)))
    print("  ".join("-" * w for w in widths))
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths)))


def run(args: argparse.Namespace) -> int:
    out = Path(getattr(args, "out", "out/bench"))
    out.mkdir(parents=True, exist_ok=True)
    result: dict = {}
    with contextlib.suppress(OSError):
        result["machine"] = {"cpus": os.cpu_count(), "load_1min": os.getloadavg()[0]}
    if "load" in args.sections:
        rows = result["load"] = bench_load(args)
        _print_table(
            "Steady-state bus load (frames actually sent, both directions; classic CAN 1 Mbit/s, "
            "worst-case stuffing)",
            ["goal", "summary H", "frames/s", "kbit/s", "load", "limit"],
            [
                [
                    r["goal"],
                    str(r["summary_harmonics"]),
                    f"{r['frames_per_s']:.0f}",
                    f"{r['bits_per_s'] / 1e3:.1f}",
                    f"{100 * r['load']:.1f} %",
                    f"{100 * r['limit']:.0f} %",
                ]
                for r in rows
            ],
        )
    if "latency" in args.sections:
        lat = result["latency_in_process"] = bench_latency_in_process(args)
        rows = [
            [name, f"{1e3 * lat[key]['median']:.2f}", f"{1e3 * lat[key]['p99']:.2f}", str(lat[key]["n"])]
            for name, key in (
                ("plan (validate + feed-forward + quantise)", "plan"),
                ("goal -> first CAN frame sent", "first_frame"),
                ("goal -> commit frame sent", "commit_frame"),
            )
        ]
        _print_table(
            f"Two-harmonic goal, ROS-free path, in process ({lat['frames_per_goal']} frames per goal)",
            ["step", "median ms", "p99 ms", "n"],
            rows,
        )
        br = result["latency_bridge"] = bench_latency_bridge(args)
        _print_table(
            "Two-harmonic goal across processes (localhost bridge, simulator at real time, "
            "5 ms firmware period, 33 ms cycle)",
            ["goal -> ", "median ms", "p99 ms", "n"],
            [
                [name, f"{1e3 * br[key]['median']:.1f}", f"{1e3 * br[key]['p99']:.1f}", str(br[key]["n"])]
                for name, key in (
                    ("ACCEPTED ack received", "accepted"),
                    ("ACTIVE ack received (next cycle start)", "active"),
                )
            ],
        )
    if "node" in args.sections:
        node = result["latency_node"] = bench_latency_node(args)
        _print_table(
            "Two-harmonic goal through the waveform_generator node (ROS in process, DDS on loopback)",
            ["goal received by", "median ms", "p99 ms", "n"],
            [[f"{name} -> first CAN frame of its table", f"{1e3 * node[name]['median']:.2f}",
              f"{1e3 * node[name]['p99']:.2f}", str(node[name]["n"])] for name in ("topic", "service")],
        )
    if "bridge" in args.sections:
        rows = result["bridge"] = bench_bridge(args)
        _print_table(
            "Localhost bridge (python-can-remote), device -> client",
            ["offered frames/s", "sent frames/s", "received / sent", "delivered frames/s", "lag s"],
            [
                [
                    str(r["offered_fps"]),
                    f"{r['sent_fps']:.0f}",
                    f"{r['received']} / {r['sent']}",
                    f"{r['delivered_fps']:.0f}",
                    f"{r['lag_s']:.3f}",
                ]
                for r in rows
            ],
        )
    if "sim" in args.sections:
        rows = result["sim"] = bench_sim(args)
        _print_table(
            "Simulated device speed (LineSinkX, 30 Hz)",
            ["what", "exact geometry", "x real time"],
            [[r["what"], "yes" if r["exact_geometry"] else "no", f"{r['factor']:.1f}"] for r in rows],
        )
    if "heartbeat" in args.sections:
        rows = result["heartbeat"] = bench_heartbeat(args)
        _print_table(
            f"Heartbeat intervals (period 50 ms; watchdog 150 ms) with a Python-busy thread in the same "
            f"process and {args.busy} busy processes, {rows[0]['seconds_per_run']:g} s runs alternating",
            ["process scheduling", "sends", "median ms", "p99 ms", "max ms", "> 100 ms"],
            [[r["scheduling"], str(r["n"]), f"{r['median_ms']:.1f}", f"{r['p99_ms']:.1f}", f"{r['max_ms']:.1f}",
              str(r["over_100_ms"])] for r in rows],
        )
    if "stalls" in args.sections:
        rows = result["stalls"] = bench_stalls(args)
        _print_table(
            f"Heartbeats at the device while the host's GIL is held for {args.stall_ms:g} ms, {rows[0]['stalls']} "
            f"times 1 s apart, {rows[0]['busy_processes']} busy processes (period 50 ms; the watchdog trips "
            f"after 150 ms)",
            ["heartbeats from", "intervals", "median ms", "max ms", "> 150 ms (watchdog trips)"],
            [[r["heartbeats_from"], str(r["n"]), f"{r['median_ms']:.1f}", f"{r['max_ms']:.1f}", str(r["over_150_ms"])]
             for r in rows],
        )
    if "machine" in result:
        print(
            f"\n(machine: {result['machine']['cpus']} CPUs, 1-minute load average "
            f"{result['machine']['load_1min']:.2f} at the start)"
        )
    (out / "can.json").write_text(json.dumps(result, indent=2))
    print(f"results: {out / 'can.json'}")
    return 0

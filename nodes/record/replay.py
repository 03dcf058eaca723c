"""Replay a recorded session against the simulated device and compare the outcome with the recording.

A recording made with ``ppod record`` while ``ppod up --sim`` ran holds what a replay needs: the
simulated device's scenario (``ppod/sim/scenario``: device, mismatch, seed, camera, the placed scene),
the goals as the waveform generator accepted them (``ppod/plate_motion_active``, stamped in device
time) and the outcome (``ppod/sim/ground_truth/...``, ``ppod/plate_acceleration``, ``ppod/part_poses``).

:func:`plan_replay` reads that; :func:`compare` matches the two runs' messages by device time and
reports the differences against tolerances. ``ppod replay`` (nodes/cli/replay.py) starts the stack with
the recorded scenario, re-sends every goal at its recorded device time and calls :func:`compare`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ppod_nodes.common import topics
from ppod_nodes.common.convert import motion_from_msg, stamp_to_seconds
from ppod_nodes.record.mcap_io import read_mcap
from ppod_ros.config.fields import parse_yaml_text
from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion

SCENARIO = "/" + topics.SIM_SCENARIO
ACTIVE = "/" + topics.ACTIVE_MOTION
TRUE_POSES = "/" + topics.SIM_TRUE_POSES
TRUE_ACCEL = "/" + topics.SIM_TRUE_ACCELERATION
MEASURED_ACCEL = "/" + topics.ACCELERATION
TRACKED = "/" + topics.PART_POSES
COMPARED = (TRUE_POSES, TRUE_ACCEL, MEASURED_ACCEL, TRACKED)


@dataclass
class ReplayPlan:
    scenario: dict[str, Any]
    goals: list[tuple[float, PlateMotion]]  # (device time s, motion; zero motion = stop)
    duration_s: float
    outcome: dict[str, list[tuple[float, Any]]] = field(default_factory=dict)  # topic -> [(t, msg)]
    nodes: list[str] = field(default_factory=list)


def _decode(path, rec):
    """A recorded message, or a one-line ConfigError when its bytes do not decode as its type."""
    try:
        return rec.decode()
    except Exception as exc:  # noqa: BLE001 - rclpy's deserializer raises several types on corrupt bytes
        raise ConfigError(f"recording {path}: a {rec.type_name} message on {rec.topic} does not decode "
                          f"({type(exc).__name__}): the file is corrupt") from exc


def plan_replay(path: str | Path) -> ReplayPlan:
    """Read a recording; ConfigError if it lacks what a replay needs."""
    scenario = None
    goals: list[tuple[float, PlateMotion]] = []
    outcome: dict[str, list[tuple[float, Any]]] = {t: [] for t in COMPARED}
    seen_topics: set[str] = set()
    last_t = 0.0
    for rec in read_mcap(path):
        seen_topics.add(rec.topic)
        if rec.topic == SCENARIO:
            scenario = parse_yaml_text(_decode(path, rec).data, f"{path}: {SCENARIO}")
        elif rec.topic == ACTIVE:
            msg = _decode(path, rec)
            t = stamp_to_seconds(msg.header.stamp)
            motion = motion_from_msg(msg) if msg.harmonics else PlateMotion.zero(name="stop")
            if not goals and motion.is_zero():
                continue  # the idle state at start-up, not something anybody asked for
            if not goals or goals[-1][1] != motion or goals[-1][1].name != motion.name:
                goals.append((t, motion))
        elif rec.topic in outcome:
            msg = _decode(path, rec)
            t = stamp_to_seconds(msg.header.stamp)
            outcome[rec.topic].append((t, msg))
            last_t = max(last_t, t)
    if scenario is None:
        raise ConfigError(f"{path}: no {SCENARIO} message: record while `ppod up --sim` runs (the simulated "
                          f"device publishes its scenario, latched)")
    if not goals:
        raise ConfigError(f"{path}: no {ACTIVE} message: no goal was recorded")
    nodes = ["sim_device", "waveform_generator"]
    if any(t in seen_topics for t in (MEASURED_ACCEL, "/" + topics.CORRECTION)):
        nodes.append("accel_feedback")
    if TRACKED in seen_topics:
        nodes.append("part_tracker")
    return ReplayPlan(scenario, goals, last_t, outcome, nodes)


@dataclass
class Difference:
    what: str
    compared: int
    worst: float
    rms: float
    tolerance: float
    unit: str

    @property
    def ok(self) -> bool:
        return self.compared > 0 and self.worst <= self.tolerance


def _pairs(a: list[tuple[float, Any]], b: list[tuple[float, Any]], max_dt_s: float, after_s: float):
    """Pairs (msg_a, msg_b) whose device times differ by at most ``max_dt_s``, from ``after_s`` on."""
    if not a or not b:
        return []
    tb = np.array([t for t, _ in b])
    out = []
    for t, ma in a:
        if t < after_s:
            continue
        i = int(np.argmin(np.abs(tb - t)))
        if abs(tb[i] - t) <= max_dt_s:
            out.append((ma, b[i][1]))
    return out


def _accel(msg) -> np.ndarray:
    return np.array([np.asarray(h.amplitude) * np.exp(1j * np.asarray(h.phase)) for h in msg.measured])


def compare(recorded: dict[str, list], replayed: dict[str, list], *, position_tol_m: float = 0.002,
            accel_tol: float = 0.02, settle_s: float = 0.0,
            transients: list[tuple[float, float]] = ()) -> list[Difference]:
    """Differences between the recorded and replayed outcomes, matched by device time.

    ``transients``: device-time windows (goal changes and their ramps) where the plate's acceleration
    is not compared: a goal sent a cycle later shifts a ramp, which is no regression.
    """
    out: list[Difference] = []
    scale = np.array([1, 1, 1, 0.1, 0.1, 0.1])
    for topic, what in ((TRUE_ACCEL, "true plate acceleration"), (MEASURED_ACCEL, "measured plate acceleration")):
        if not recorded.get(topic):
            continue
        diffs = []
        if topic == MEASURED_ACCEL:
            # Estimates come when the feedback loop is ready, not on a clock: pair them by learning
            # iteration (the same goal, the same number of corrections applied).
            by_iteration = {m.iteration: m for _, m in replayed.get(topic, []) if m.iteration}
            pairs = [(m, by_iteration[m.iteration]) for _, m in recorded[topic] if m.iteration in by_iteration]
        else:
            steady = [(t, m) for t, m in recorded[topic] if not any(a <= t <= b for a, b in transients)]
            pairs = _pairs(steady, replayed.get(topic, []), 0.02, settle_s)
        for a, b in pairs:
            A, B = _accel(a), _accel(b)
            K = min(len(A), len(B))
            norm = max(np.linalg.norm(A[:K] * scale), 1.0)  # relative to the motion, or 1 m/s^2 at rest
            diffs.append(np.linalg.norm((A[:K] - B[:K]) * scale) / norm)
        out.append(_summary(what, diffs, accel_tol, "of the motion"))
    for topic, what in ((TRUE_POSES, "true part positions"), (TRACKED, "tracked part positions")):
        if not recorded.get(topic):
            continue
        diffs = []
        for a, b in _pairs(recorded[topic], replayed.get(topic, []), 0.06, settle_s):
            pb = {p.id: p for p in b.parts}
            for p in a.parts:
                q = pb.get(p.id)
                if q is not None and p.status == 0 and q.status == 0:
                    diffs.append(math.hypot(p.pose.x - q.pose.x, p.pose.y - q.pose.y))
        out.append(_summary(what, diffs, position_tol_m, "m"))
    return out


def _summary(what: str, diffs: list[float], tol: float, unit: str) -> Difference:
    d = np.asarray(diffs, dtype=float)
    if d.size == 0:
        return Difference(what, 0, math.nan, math.nan, tol, unit)
    return Difference(what, int(d.size), float(d.max()), float(np.sqrt(np.mean(d**2))), tol, unit)

"""``ppod demo`` with several goals at once (the default, or ``--goals GOALS.yaml``): the MoveParts
action, the ground-truth report and ``OUT/summary.json`` (format: docs/formats.md)."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from ppod_nodes.cli.demo import _Demo, _say, await_goal
from ppod_ros.errors import ConfigError, DeviceError
from ppod_ros.planning.goals import GoalEntry, load_goals_file, resolve_parts
from ppod_ros.planning.mpc import progress_bit

#: The default set: the bracket, oriented, and the two washers of the default scene, to the issue's
#: three-part tolerances (2 mm / 3 deg). The planner judges "done" by the tracker, whose error on the
#: stack's 640 x 512 camera is up to 0.1 mm at rest (docs/vision.md, "Calibration"; up to 0.4 mm
#: before the marker corner window was mended), within the 0.2 mm the plate's hold at rest keeps.
DEFAULT_TOL_MM, DEFAULT_TOL_DEG = 2.0, 3.0
DEFAULT_GOALS = (GoalEntry("bracket", 0.02, -0.02, 0.0, DEFAULT_TOL_MM, DEFAULT_TOL_DEG),
                 GoalEntry("washer", -0.03, 0.02, None, DEFAULT_TOL_MM, DEFAULT_TOL_DEG),
                 GoalEntry("washer", 0.03, 0.03, None, DEFAULT_TOL_MM, DEFAULT_TOL_DEG))
SETTLE_S = 0.5  # within tolerance for this long at the end: reached (as the planner's settle time)


def goals_for_scene(scene, path: Path | None) -> list[dict]:
    """Goals resolved to scene indices: [{index, label, x, y, theta_rad|None, tol_m, tol_rad}]."""
    entries = list(DEFAULT_GOALS) if path is None else load_goals_file(path)
    labels = [p.label for p in scene.parts]
    idx = resolve_parts(entries, labels)
    out = []
    for e, i in zip(entries, idx):
        if math.hypot(e.x_m, e.y_m) > 0.07:
            raise ConfigError(f"goals: part {e.part!r}: ({e.x_m:g}, {e.y_m:g}) m is outside the working disc "
                              f"(radius 0.07 m)")
        rigid = scene.parts[i].part.kind == "rigid"
        fp = scene.parts[i].part.footprint
        oriented = e.theta_deg is not None and (rigid or (fp is not None and fp.symmetry_rad > 0))
        out.append({"index": i, "label": labels[i], "x": e.x_m, "y": e.y_m,
                    "theta_rad": math.radians(e.theta_deg) if oriented else None,
                    "tol_m": 1e-3 * e.tol_mm, "tol_rad": math.radians(e.tol_deg)})
    return out


def _period(part) -> float:
    fp = part.footprint
    return fp.symmetry_rad if fp is not None and fp.symmetry_rad > 0 else 2 * math.pi


def summarize(goals: list[dict], parts, t: np.ndarray, poses: np.ndarray, t_start: float, device_s: float,
              real_time_factor: float) -> dict:
    """summary.json from the ground truth (times t (T,), poses (T, N, 3)) after ``t_start``."""
    keep = t >= t_start
    t, poses = t[keep], poses[keep]
    entries = []
    for g in goals:
        i = g["index"]
        if len(t) == 0:
            entries.append({"index": i, "label": g["label"], "goal": _goal_out(g), "final": None,
                            "position_error_m": None, "angle_error_deg": None, "reached": False,
                            "time_to_goal_s": None})
            continue
        p = poses[:, i, :]
        pos_err = np.hypot(p[:, 0] - g["x"], p[:, 1] - g["y"])
        within = pos_err <= g["tol_m"]
        ang_err = None
        if g["theta_rad"] is not None:
            per = _period(parts[i])
            a = np.abs((p[:, 2] - g["theta_rad"] + per / 2) % per - per / 2)
            within &= a <= g["tol_rad"]
            ang_err = float(np.degrees(a[-1]))
        entered = None
        if within[-1]:
            out_idx = np.flatnonzero(~within)
            k = out_idx[-1] + 1 if len(out_idx) else 0
            entered = float(t[k])
        reached = entered is not None and t[-1] - entered >= SETTLE_S - 1e-6
        entries.append({"index": i, "label": g["label"], "goal": _goal_out(g),
                        "final": [float(p[-1, 0]), float(p[-1, 1]), float(math.degrees(p[-1, 2]))],
                        "position_error_m": float(pos_err[-1]), "angle_error_deg": ang_err, "reached": bool(reached),
                        "time_to_goal_s": None if entered is None else entered - t_start})
    return {"all_reached": all(e["reached"] for e in entries), "device_time_s": float(device_s),
            "real_time_factor": float(real_time_factor), "parts": entries}


def progress_line(goals: list[dict], ids: list[int], fb) -> str:
    """One line of MoveParts feedback ``fb`` with each part named as the demo names it (scene index
    and label; ``ids``: the track id of each goal, in the goals' order)."""
    by_id = {int(tid): g for tid, g in zip(ids, goals)}
    bits = []
    for pid, d, a, ok in zip(fb.part_ids, fb.position_error_m, fb.orientation_error_rad, fb.within):
        g = by_id.get(int(pid))
        name = f"#{g['index']} ({g['label']})" if g is not None else f"track {pid}"
        oriented = g is not None and g["theta_rad"] is not None   # the feedback's angle is 0 otherwise
        bits.append(progress_bit(name, d, a if oriented else None, ok))
    return f"{fb.phase}: " + ", ".join(bits)


def _goal_out(g: dict) -> list:
    return [g["x"], g["y"], None if g["theta_rad"] is None else math.degrees(g["theta_rad"])]


class MultiDemo(_Demo):
    def __init__(self, args, scene, scene_path, goals: list[dict]):
        g0 = goals[0]
        super().__init__(args, scene, scene_path, g0["index"], (g0["x"], g0["y"], g0["theta_rad"]), None)
        self.goals = goals
        self.summary: dict | None = None
        self.t_start = None
        self.wall_goals = None

    def _intro(self) -> None:
        _say(f"scene {self.scene_path}: {len(self.scene.parts)} parts "
             f"({', '.join(p.label for p in self.scene.parts)}); moving at once: " + "; ".join(
                 f"#{g['index']} ({g['label']}) to ({g['x']:.3f}, {g['y']:.3f} m"
                 + (f", {math.degrees(g['theta_rad']):.0f} deg)" if g["theta_rad"] is not None else ")")
                 for g in self.goals))

    def run(self) -> int:
        try:
            return super().run()
        finally:
            self._write_summary()

    def _write_summary(self) -> None:
        path = self.args.out / "summary.json"
        if self.summary is None:  # failed before the end: what the ground truth says so far
            log = getattr(self, "log", None)
            t, poses = log.trajectories() if log is not None else (np.zeros(0), np.zeros((0, len(self.scene.parts), 3)))
            t0 = self.t_start if self.t_start is not None else (t[0] if len(t) else 0.0)
            device_s = float(t[-1] - t0) if len(t) else 0.0
            wall = time.monotonic() - self.wall_goals if self.wall_goals else 0.0
            self.summary = summarize(self.goals, [p.part for p in self.scene.parts], t, poses, t0, device_s,
                                     device_s / wall if wall > 0 else 0.0)
        path.write_text(json.dumps(self.summary, indent=1))
        _say(f"summary: {path} (all reached: {str(self.summary['all_reached']).lower()})")

    def _move(self, ros, _track_id: int, stack) -> int:
        from geometry_msgs.msg import Pose2D
        from ppod_msgs.action import MoveParts

        from ppod_nodes.common import topics
        from ppod_nodes.common.actions import ActionClient

        _, truth = self.log.latest_truth()
        _, tracked = self.log.latest_tracked()
        ids = []
        for g in self.goals:
            x, y = truth[g["index"], :2]
            free = {k: v for k, v in tracked.items() if k not in ids}
            tid = min(free, key=lambda k: math.hypot(free[k][0] - x, free[k][1] - y))
            ids.append(int(tid))
        client = ActionClient(ros.node, MoveParts, "/" + topics.MOVE_PARTS)
        if not client.wait_for_server(timeout_sec=30):
            raise DeviceError("the field_planner's MoveParts action is not available")
        goal = MoveParts.Goal(part_ids=ids, timeout_s=float(self.args.timeout),
                              keep_others_clear=bool(getattr(self.args, "keep_clear", False)))
        for g in self.goals:
            goal.targets.append(Pose2D(x=float(g["x"]), y=float(g["y"]), theta=float(g["theta_rad"] or 0.0)))
            goal.use_orientation.append(g["theta_rad"] is not None)
            goal.position_tolerance_m.append(float(g["tol_m"]))
            goal.orientation_tolerance_rad.append(float(g["tol_rad"]))
        last_print = [-math.inf]

        def on_feedback(msg) -> None:
            fb = msg.feedback
            t = (self.log.latest_truth() or (self.t_start, None))[0]
            err = max(fb.position_error_m) if len(fb.position_error_m) else math.nan
            self.log.add_feedback(t, fb.phase, fb.text, err)
            if t - last_print[0] >= 2.0:
                last_print[0] = t
                _say(f"t = {t - self.t_start:5.1f} s  {progress_line(self.goals, ids, fb)}  "
                     f"(replanned in {fb.plan_ms:.0f} ms)")

        self.wall_goals = time.monotonic()
        self.t_start = self.log.latest_truth()[0]
        res = await_goal(ros, stack, client, goal, on_feedback, "MoveParts", self.wall_goals,
                         3 * self.args.timeout + 60,
                         "the field_planner rejected the MoveParts goals (see the log for the reason)",
                         "MoveParts accepted: " + ", ".join(
                             f"#{g['index']} ({g['label']}) is track {tid}" for g, tid in zip(self.goals, ids)))
        wall = time.monotonic() - self.wall_goals
        device_s = float(self.log.latest_truth()[0] - self.t_start)  # at the same moment as the wall time
        ros.wait_until(lambda: False, 0.3)  # the last truth frames (for the final poses only)
        t, poses = self.log.trajectories()
        self.summary = summarize(self.goals, [p.part for p in self.scene.parts], t, poses, self.t_start, device_s,
                                 device_s / max(wall, 1e-9))
        _say(("planner: " if res.success else "not reached: ") + res.reason)
        for e in self.summary["parts"]:
            ang = "" if e["angle_error_deg"] is None else f", {e['angle_error_deg']:.2f} deg"
            ttg = "" if e["time_to_goal_s"] is None else f", in tolerance from {e['time_to_goal_s']:.1f} s"
            _say(f"#{e['index']} ({e['label']}): {1e3 * e['position_error_m']:.2f} mm{ang} from its goal "
                 f"(ground truth){ttg}: {'reached' if e['reached'] else 'NOT reached'}")
        _say(f"{device_s:.1f} s of device time in {wall:.1f} s wall: {self.summary['real_time_factor']:.2f}x real time")
        self.reached.update(device_s=device_s, wall_s=wall)
        return 0 if self.summary["all_reached"] else 1

    def _figures(self) -> None:
        from ppod_nodes.demo.figures import FieldCache, write_animation, write_multi_picture

        t, poses = self.log.trajectories() if hasattr(self, "log") else (np.zeros(0), None)
        if len(t) < 2:
            _say("no trajectories recorded: no figures")
            return
        t0 = self.t_start if self.t_start is not None else t[0]
        keep = t >= t0 - 1.0
        t, poses = t[keep], poses[keep]
        parts = [p.part for p in self.scene.parts]
        cache = FieldCache()
        final_motion = next((m for _, m in reversed(self.log.motions) if m is not None and not m.is_zero()), None)
        goals = [(g["index"], g["x"], g["y"], g["theta_rad"]) for g in self.goals]
        n_ok = sum(e["reached"] for e in (self.summary or {}).get("parts", []))
        title = (f"ppod demo: {len(goals)} parts to their goals at once ({n_ok} reached)"
                 + (f"\nfield of the last motion '{final_motion.name}'" if final_motion else ""))
        png = self.args.out / "demo.png"
        write_multi_picture(png, t, poses, parts, goals, final_motion, cache, title)
        _say(f"picture: {png}")
        if not self.args.no_animation:
            gif = self.args.out / "demo.gif"
            n = write_animation(gif, t, poses, parts, self.chosen, self.goal, None, self.log.motion_at, cache)
            _say(f"animation: {gif} ({n} frames)")


__all__ = ["DEFAULT_GOALS", "MultiDemo", "goals_for_scene", "summarize"]

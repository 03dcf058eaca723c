"""The full demo: the stack against the simulated device moves parts to goal poses.

By default (and with ``--goals GOALS.yaml``) several parts at once, each to its own goal: the
field_planner's MoveParts action (the model-predictive planner, docs/planner.md). The default set:
the bracket to (0.02, -0.02) at 0 deg, the two washers to (-0.03, 0.02) and (0.03, 0.03). It
prints the progress and then, from the simulator's ground truth, each commanded part's final pose
and error, and writes ``OUT/summary.json`` (always, on timeout or failure too; format in
docs/formats.md), the picture of each part's path to its goal (``OUT/demo.png``), the animation,
the session as MCAP and every node's log. ``--timeout S`` bounds the device time of the whole set.

With ``--part``/``--goal`` (not combined with ``--goals``), one part with MovePart, as before:
starts every node (`ppod up --sim`: simulated device with parts scattered on the plate, waveform
generator, accelerometer feedback, part tracker on the simulated camera, field planner), waits until
the tracker sees every part, then asks the field_planner (MovePart action) to bring the chosen part
to the goal pose from camera feedback; the other parts are gathered in the same sink around it (a
plate field moves every part at once, so the sink that positions the chosen part is where the others
end up; the chosen part, nearest to the goal, arrives first). It prints the
planner's progress, then what it reached, measured against the simulator's ground truth: position
and orientation error of the chosen part, the tracker's error, where the other parts ended, the
plate's acceleration-tracking error, and how the device clock kept up with real time. It writes
(under --out) a picture of the trajectories over the field, an animation, the session as MCAP
(`ppod replay OUT/session.mcap --against-sim` replays it) and every node's log.

examples:
  ppod demo                                    three parts of the default scene to three goals at once
  ppod demo --goals goals.yaml --out out/g1    any set of goals (GOALS.yaml: docs/formats.md)
  ppod demo --part bracket --goal 0.02 -0.02 0 one part with MovePart, the others gathered
  ppod demo --part washer --goal 0.03 0.03     a point part (position only)
  ppod demo --goal 0 -0.03 90 --out out/demo2
  ppod demo --part washer --goal 0.03 0.03 --no-collect   the model-predictive planner for one part
  ppod demo --no-collect --verbose             only the chosen part counts; every node's log shown
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
import threading
import time
from pathlib import Path

import numpy as np

from ppod_ros.errors import ConfigError, DeviceError

HELP = "the full demo: the stack against the simulated device brings a part to a goal pose"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scene", type=Path, help="scene YAML for the simulated device (default: the packaged one)")
    parser.add_argument("--goals", type=Path, metavar="GOALS.yaml",
                        help="several parts to their own goals at once (docs/formats.md); default without "
                             "--part/--goal: the bracket and the two washers of the default scene, to 2 mm / 3 deg")
    parser.add_argument("--keep-clear", action="store_true",
                        help="with several goals: also keep the predicted paths clear of the parts not commanded")
    parser.add_argument("--part", default=None,
                        help="one part with MovePart: a scene label (first match) or index (default: bracket)")
    parser.add_argument("--goal", nargs="+", type=float, default=None, metavar="V",
                        help="one part's goal X Y [THETA_DEG] in the plate frame (m, m, deg; default 0.02 -0.02 0); "
                             "no THETA: position only")
    parser.add_argument("--mismatch", choices=["zero", "default"], default="default",
                        help="plant mismatch of the simulated device: 'default', as configured (gain, phase, "
                             "cross-coupling and third-harmonic errors that the accelerometer feedback "
                             "learns), or 'zero' (the plate moves as the nominal model says)")
    parser.add_argument("--no-collect", action="store_true",
                        help="one part: only the chosen part counts, moved by the model-predictive planner, "
                             "done as soon as it is there (default: the template planner also gathers the "
                             "others, waiting up to half the timeout until they are within 40 mm of the goal)")
    parser.add_argument("--timeout", type=float, default=90.0,
                        help="device-clock s for the goal (or the whole set of goals) from its start (default 90)")
    parser.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder (default out/demo)")
    parser.add_argument("--no-animation", action="store_true", help="skip the GIF (saves a few seconds)")
    parser.add_argument("--no-record", action="store_true", help="do not record the session to MCAP")
    parser.add_argument("--verbose", action="store_true", help="forward every node's log lines")


def _say(text: str) -> None:
    print(f"[demo] {text}", flush=True)


def _choose(scene, which: str) -> int:
    if which.isdigit():
        i = int(which)
        if not 0 <= i < len(scene.parts):
            raise ConfigError(f"--part: index {i} outside 0..{len(scene.parts) - 1}")
        return i
    for i, p in enumerate(scene.parts):
        if p.label == which:
            return i
    raise ConfigError(f"--part: no part labelled {which!r} in the scene ({', '.join(p.label for p in scene.parts)})")


def _goal(values: list[float], rigid: bool) -> tuple[float, float, float | None]:
    if len(values) not in (2, 3):
        raise ConfigError(f"--goal: expected X Y [THETA_DEG], got {len(values)} values")
    if not all(math.isfinite(v) for v in values):
        raise ConfigError(f"--goal: values must be finite, got {values}")
    if math.hypot(values[0], values[1]) > 0.07:
        raise ConfigError(f"--goal: ({values[0]}, {values[1]}) is outside the working disc (radius 0.07 m)")
    theta = math.radians(values[2]) if len(values) == 3 and rigid else None
    return values[0], values[1], theta


def run(args: argparse.Namespace) -> int:
    from ppod_sim.ros_node import default_scene_path
    from ppod_sim.scene import load_scene

    if not (math.isfinite(args.timeout) and args.timeout > 0):
        raise ConfigError(f"--timeout: expected seconds > 0, got {args.timeout}")
    scene_path = args.scene or default_scene_path()
    scene = load_scene(scene_path)
    if args.goals is not None and (args.part is not None or args.goal is not None):
        raise ConfigError("--goals: not combined with --part/--goal (give every goal in the file)")
    if args.part is None and args.goal is None:
        from ppod_nodes.cli.demo_multi import MultiDemo, goals_for_scene

        goals = goals_for_scene(scene, args.goals)
        args.out.mkdir(parents=True, exist_ok=True)
        return MultiDemo(args, scene, scene_path, goals).run()
    args.part = args.part or "bracket"
    args.goal = args.goal if args.goal is not None else [0.02, -0.02, 0.0]
    chosen = _choose(scene, args.part)
    rigid = scene.parts[chosen].part.kind == "rigid"
    goal = _goal(args.goal, rigid)
    collect = None if args.no_collect else (goal[0], goal[1])
    args.out.mkdir(parents=True, exist_ok=True)
    return _Demo(args, scene, scene_path, chosen, goal, collect).run()


class _Demo:
    def __init__(self, args, scene, scene_path, chosen, goal, collect):
        self.args, self.scene, self.scene_path = args, scene, scene_path
        self.chosen, self.goal, self.collect = chosen, goal, collect
        self.result = None
        self.reached: dict[str, float] = {}

    def run(self) -> int:
        from ppod_nodes.launch.spec import load_launch_spec
        from ppod_nodes.launch.stack import Stack

        args = self.args
        log_path = args.out / "stack.log"
        self._intro()
        _say(f"node logs: {log_path}" + (" (also shown here)" if args.verbose else ""))
        wall0 = time.monotonic()
        with open(log_path, "w", encoding="utf-8") as log:
            out = _Tee(log, sys.stdout) if args.verbose else log
            # A fresh correction cache: corrections are learned per plant, and the simulated plant
            # changes with --mismatch while the device name stays the same.
            cache = args.out / "feedback_cache"
            shutil.rmtree(cache, ignore_errors=True)
            self._calibrate(cache)
            extra = {"sim_device": {"scene": str(self.scene_path), "mismatch": args.mismatch},
                     "accel_feedback": {"cache_dir": str(cache)}}
            with Stack(load_launch_spec(), sim=True, out=out, extra_params=extra) as stack:
                stack.start()
                _say(f"stack up in {time.monotonic() - wall0:.1f} s: "
                     + ", ".join(n.name for n in stack.nodes))
                code = self._drive(stack)
        _say(f"stack stopped; wall time {time.monotonic() - wall0:.1f} s")
        self._figures()
        return code

    def _calibrate(self, cache: Path) -> None:
        """Calibrate the simulated device's accelerometers (its sensor errors are on) into ``cache``,
        where accel_feedback loads it (use_calibration): as ``ppod calibrate accel`` on a real device."""
        from ppod_ros.device import Mismatch, load_device_config
        from ppod_sim.calibration import calibrate_simulated_device

        config = load_device_config(None)
        if self.args.mismatch == "zero":
            config = config.with_mismatch(Mismatch.zero())
        t0 = time.monotonic()
        _say("calibrating the simulated device's accelerometers (simulated sensor errors on)")
        cal = calibrate_simulated_device(config, seed=self.scene.seed, cache_dir=cache)
        gain_err = 100 * float(np.max(np.abs(cal.gain - 1.0)))
        _say(f"accelerometer calibration stored in {time.monotonic() - t0:.1f} s wall: "
             f"{len(cal.names)} channels, gains up to {gain_err:.1f} % off nominal; accel_feedback uses it")

    def _intro(self) -> None:
        _say(f"scene {self.scene_path}: {len(self.scene.parts)} parts "
             f"({', '.join(p.label for p in self.scene.parts)}); moving #{self.chosen} "
             f"({self.scene.parts[self.chosen].label}) to ({self.goal[0]:.3f}, {self.goal[1]:.3f} m"
             + (f", {math.degrees(self.goal[2]):.0f} deg)" if self.goal[2] is not None else ")")
             + (", the others gathered in the same sink" if self.collect else ""))

    # ------------------------------------------------------------------ the run
    def _drive(self, stack) -> int:
        from ppod_nodes.common.session import RosSession
        from ppod_nodes.demo.log import DemoLog

        self.log = DemoLog()
        with RosSession("ppod_demo") as ros:
            self.log.attach(ros.node)
            recorder = None
            if not self.args.no_record:
                from ppod_nodes.cli.record import default_include
                from ppod_nodes.record.mcap_io import McapRecorder

                meta = {"ppod": {"recorded_by": "ppod demo", "started_unix_s": f"{time.time():.3f}"}}
                recorder = McapRecorder(ros.node, self.args.out / "session.mcap", default_include(False), meta)
            try:
                track_id = self._wait_for_tracks(ros)
                code = self._move(ros, track_id, stack)
            finally:
                if recorder is not None:
                    recorder.close()
                    _say(f"recorded {sum(recorder.counts.values())} messages to {self.args.out / 'session.mcap'}")
        return code

    def _wait_for_tracks(self, ros) -> int:
        n = len(self.scene.parts)
        _say(f"waiting for the tracker to see all {n} parts")
        def all_seen() -> bool:
            tracked = self.log.latest_tracked()
            return tracked is not None and len(tracked[1]) >= n and self.log.latest_truth() is not None

        if not ros.wait_until(all_seen, 60):
            seen = len((self.log.latest_tracked() or (0, {}))[1])
            raise DeviceError(f"the tracker sees {seen} of {n} parts after 60 s (see {self.args.out / 'stack.log'})")
        t, truth = self.log.latest_truth()
        _, tracked = self.log.latest_tracked()
        target = truth[self.chosen, :2]
        track_id, (x, y, _) = min(tracked.items(),
                                  key=lambda kv: math.hypot(kv[1][0] - target[0], kv[1][1] - target[1]))
        _say(f"tracking {len(tracked)} parts; #{self.chosen} is track {track_id}, "
             f"{1e3 * math.hypot(x - target[0], y - target[1]):.2f} mm from its true position")
        self.t_start = t
        return track_id

    def _move(self, ros, track_id: int, stack) -> int:
        from ppod_msgs.action import MovePart

        from ppod_nodes.common import topics
        from ppod_nodes.common.actions import ActionClient

        client = ActionClient(ros.node, MovePart, "/" + topics.MOVE_PART)
        if not client.wait_for_server(timeout_sec=30):
            raise DeviceError("the field_planner's MovePart action is not available")
        goal = MovePart.Goal(part_id=track_id, use_orientation=self.goal[2] is not None,
                             timeout_s=float(self.args.timeout), collect_others=self.collect is not None)
        goal.target.x, goal.target.y = self.goal[0], self.goal[1]
        goal.target.theta = float(self.goal[2] or 0.0)
        if self.collect is not None:
            goal.collect_x_m, goal.collect_y_m = self.collect
        last_print = [-math.inf]

        def on_feedback(msg) -> None:
            fb = msg.feedback
            t = (self.log.latest_truth() or (self.t_start, None))[0]
            self.log.add_feedback(t, fb.phase, fb.text, fb.position_error_m)
            if t - last_print[0] >= 2.0:
                last_print[0] = t
                _say(f"t = {t - self.t_start:5.1f} s  {fb.phase:<11} {fb.text}")

        wall0 = time.monotonic()
        res = await_goal(ros, stack, client, goal, on_feedback, "MovePart", wall0, 3 * self.args.timeout + 60,
                         "the field_planner rejected the MovePart goal (see the log)",
                         "MovePart accepted by the field_planner")
        wall = time.monotonic() - wall0
        t_end, truth = self.log.latest_truth()
        self._report(res, truth, t_end, wall)
        return 0 if res.success else 1

    def _report(self, res, truth: np.ndarray, t_end: float, wall_s: float) -> None:
        device_s = t_end - self.t_start
        pose = truth[self.chosen]
        err_mm = 1e3 * math.hypot(pose[0] - self.goal[0], pose[1] - self.goal[1])
        r = self.reached
        r.update(device_s=device_s, wall_s=wall_s, real_time_factor=device_s / max(wall_s, 1e-9),
                 true_position_error_mm=err_mm, reported_position_error_mm=1e3 * res.position_error_m)
        _say(("done: " if res.success else "not reached: ") + res.reason)
        _say(f"part #{self.chosen} ({self.scene.parts[self.chosen].label}) at ({pose[0]:.4f}, {pose[1]:.4f}) m: "
             f"{err_mm:.2f} mm from the goal (ground truth), {1e3 * res.position_error_m:.2f} mm by the tracker")
        if self.goal[2] is not None:
            sym = self.scene.parts[self.chosen].part.footprint
            period = sym.symmetry_rad if sym is not None and sym.symmetry_rad > 0 else 2 * math.pi
            d = (pose[2] - self.goal[2] + period / 2) % period - period / 2
            r["true_angle_error_deg"] = abs(math.degrees(d))
            _say(f"orientation {math.degrees(pose[2]):.2f} deg: {abs(math.degrees(d)):.2f} deg from the goal "
                 f"(ground truth), {math.degrees(res.orientation_error_rad):.2f} deg by the tracker")
        if self.collect is not None and len(truth) > 1:
            others = [i for i in range(len(truth)) if i != self.chosen]
            dist = [1e3 * math.hypot(truth[i, 0] - self.collect[0], truth[i, 1] - self.collect[1]) for i in others]
            r["others_max_mm"] = max(dist)
            _say(f"other parts: {np.mean(dist):.1f} mm mean, {max(dist):.1f} mm max from the goal")
        acc = [e for t, e, _ in self.log.accel_errors if t > 0]
        if acc:
            r["accel_error_last"] = acc[-1]
            _say(f"plate acceleration tracking error (accel_feedback): last {100 * acc[-1]:.2f} %, "
                 f"median {100 * float(np.median(acc)):.2f} % over {len(acc)} estimates")
        _say(f"{device_s:.1f} s of device time in {wall_s:.1f} s wall: {r['real_time_factor']:.2f}x real time")

    # ------------------------------------------------------------------ pictures
    def _figures(self) -> None:
        from ppod_nodes.demo.figures import FieldCache, write_animation, write_picture

        t, poses = self.log.trajectories()
        if len(t) < 2:
            _say("no trajectories recorded: no figures")
            return
        keep = t >= self.t_start - 1.0
        t, poses = t[keep], poses[keep]
        parts = [p.part for p in self.scene.parts]
        cache = FieldCache()
        final_motion = next((m for _, m in reversed(self.log.motions) if m is not None), None)
        title = (f"ppod demo: {self.scene.parts[self.chosen].label} to goal"
                 + (f" ({self.reached['true_position_error_mm']:.2f} mm" if "true_position_error_mm" in self.reached
                    else " (")
                 + (f", {self.reached['true_angle_error_deg']:.2f} deg)" if "true_angle_error_deg" in self.reached
                    else ")")
                 + (f"\nfield of the last motion '{final_motion.name}'" if final_motion else ""))
        png = self.args.out / "demo.png"
        write_picture(png, t, poses, parts, self.chosen, self.goal, self.collect, final_motion, cache, title)
        _say(f"picture: {png}")
        if not self.args.no_animation:
            phases = self.log.feedback

            def phase_at(tf: float) -> str:
                before = [p for tt, p, _, _ in phases if tt <= tf]
                return before[-1] if before else ""

            gif = self.args.out / "demo.gif"
            n = write_animation(gif, t, poses, parts, self.chosen, self.goal, self.collect, self.log.motion_at,
                                cache, phase_at=phase_at)
            _say(f"animation: {gif} ({n} frames)")


def await_goal(ros, stack, client, goal, on_feedback, what: str, wall0: float, guard_s: float,
                     rejected: str, accepted: str):
    """Send an action goal, wait for its result while the stack lives (wall-clock guard from
    ``wall0``: cancel and fail after ``guard_s``), return the result."""
    handle = ros.wait_future(client.send_goal_async(goal, feedback_callback=on_feedback), 30, f"{what} goal")
    if not handle.accepted:
        raise DeviceError(rejected)
    _say(accepted)
    done = threading.Event()
    result_future = handle.get_result_async()
    result_future.add_done_callback(lambda _f: done.set())
    while not done.wait(0.5):
        if not stack.alive():
            raise DeviceError("a node of the stack died (see the log)")
        if time.monotonic() - wall0 > guard_s:
            handle.cancel_goal_async()
            raise DeviceError(f"{what} did not finish (wall-clock guard)")
    return result_future.result().result


class _Tee:
    """Write to a log file and a console stream."""

    def __init__(self, *streams):
        self.streams = streams

    def write(self, text: str) -> int:
        for s in self.streams:
            s.write(text)
        return len(text)

    def flush(self) -> None:
        for s in self.streams:
            s.flush()

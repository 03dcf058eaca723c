"""field_planner: designs plate motions for requested velocity fields and moves parts with them.

Lifecycle node (STYLE.md rule 9); the logic is ppod_ros.planning (docs/planner.md):
  configure  load the device description (the limits every design must respect) and the part
             models by label (the tracker file: a ``part`` mapping, or a point part with the
             default friction and the listed footprint)
  activate   accept PlanField requests and MovePart goals; follow the tracked part poses
  deactivate abort a running MovePart goal and ask the generator to ramp the plate down
  cleanup    drop the models

Interfaces (names in ppod_nodes.common.topics):
  ppod/plan_field  (ppod_msgs/PlanField)   design a motion for a field; ``apply`` publishes it
  ppod/move_part   (ppod_msgs/MovePart)    closed loop: bring part ``part_id`` to a pose, choosing
                                           and updating fields from the tracked poses (a Task); with
                                           ``sensorless``, a plan of fields played open loop on the
                                           node's clock (a SensorlessTask), poses only reported
  ppod/move_parts  (ppod_msgs/MoveParts)   several parts, each to its own pose, at once: the
                                           model-predictive planner (a MultiTask) chooses the plate
                                           motion itself; per-part tolerances and feedback; goals
                                           that collide or leave the working region are rejected
                                           with the reason
  ppod/part_poses  (in)                    the tracker's poses; the Task steps on each array
  ppod/plate_motion_goal (out)             the motions it designs, for the waveform generator
  ppod/stop        (client)                ramp the plate down when a task ends or is cancelled

One MovePart or MoveParts goal runs at a time (a field moves every part on the plate); a new goal is rejected
while one runs. A closed-loop task (Task, MultiTask) steps on one planning thread, started from the
pose subscription's callback (a frame arriving while a step is computed is skipped: the next step
takes the newest poses); the executor thread applies each finished step (publishes its motion and
feedback), so it keeps serving poses, cancels and services while the planner thinks. A
SensorlessTask steps in a 10 Hz timer (device time under ``ppod up --sim``: use_sim_time). The
action's execute coroutine only waits for the outcome.
Plan lease: a MoveParts motion was planned on the poses of one frame. While the next plan is
computed, every frame checks how old those poses are; past ``plan_lease_s`` (device time, from the
pose stamps) the plate is stopped (a zero motion: at rest it holds every part), the late plan is
dropped when it comes, and the task replans from rest. A busy or stalled host then costs time,
never a part carried off by a stale motion.
A step that does not come back: a frame that finds the step finished but not yet applied applies it
(a lost wake-up costs a frame, not the goal); past ``plan_stuck_s`` of device time the goal ends as
failed with the reason, the plate is stopped, the planning thread's stack is logged and the thread
is abandoned (a new one plans the next goal), so the node and its action server live on.
Diagnostics: the last design (kind, R^2, seconds) and the running task (phase, errors).
"""

from __future__ import annotations

import contextlib
import math
import sys
import threading
import time
import traceback
from concurrent.futures import ThreadPoolExecutor
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from ppod_msgs.action import MovePart, MoveParts
from ppod_msgs.msg import PartPose, PartPoseArray, PlannerProgress
from ppod_msgs.msg import PlateMotion as PlateMotionMsg
from ppod_msgs.srv import PlanField
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.task import Future
from std_srvs.srv import Trigger

from ppod_nodes.common import diagnostics as diag
from ppod_nodes.common import qos, topics
from ppod_nodes.common.convert import motion_to_msg, stamp_to_seconds
from ppod_nodes.common.lifecycle import PpodLifecycleNode
from ppod_nodes.common.params import Param
from ppod_nodes.common.runner import make_main
from ppod_ros.config.fields import Fields, load_yaml_file
from ppod_ros.device import load_device_config
from ppod_ros.errors import ConfigError, PpodError
from ppod_ros.motion import PlateMotion
from ppod_ros.parts import Footprint, PointPart, part_from_dict, part_from_yaml_text
from ppod_ros.planning import FieldSpec, SensorlessTask, Task, design_field, plan_sensorless
from ppod_ros.planning.mpc import MultiTask, PartGoal, base_design, base_kinds


def part_models_from_tracker_file(path: str | Path, default_mu: float) -> dict[str, Any]:
    """Label -> part model from a tracker file (docs/vision.md): its ``part`` mapping when given,
    otherwise a point part with ``default_mu`` and the listed footprint."""
    data = load_yaml_file(path, "tracker")
    if not isinstance(data, dict) or not isinstance(data.get("parts"), list):
        raise ConfigError(f"{path}: parts: expected a list of part types")
    models: dict[str, Any] = {}
    for i, item in enumerate(data["parts"]):
        f = Fields(item, f"{path}: parts[{i}]")
        label = f.string("label")
        if item.get("part") is not None:
            models[label] = part_from_dict(item["part"], f.key_path("part"))
        else:
            models[label] = PointPart(mu=default_mu,
                                      footprint=Footprint.from_value(item.get("footprint"), f.key_path("footprint")))
    return models


def part_goals_from_request(goal, ids: list[int], default_tol_m: float, default_tol_rad: float) -> list[PartGoal]:
    """MoveParts goal fields -> PartGoals in the rows of ``ids`` (the tracked parts' order);
    ConfigError naming the field for lists of the wrong length or parts not tracked."""
    n = len(goal.part_ids)
    if n == 0:
        raise ConfigError("part_ids: expected at least one part")
    if len(goal.targets) != n:
        raise ConfigError(f"targets: expected {n} poses (one per part_ids entry), got {len(goal.targets)}")
    for name in ("use_orientation", "position_tolerance_m", "orientation_tolerance_rad"):
        got = len(getattr(goal, name))
        if got not in (0, n):
            raise ConfigError(f"{name}: expected 0 or {n} entries, got {got}")
    out = []
    for i, pid in enumerate(goal.part_ids):
        if int(pid) not in ids:
            raise ConfigError(f"part_ids[{i}]: part {pid} is not tracked")
        t = goal.targets[i]
        oriented = bool(goal.use_orientation[i]) if len(goal.use_orientation) else False
        tol = float(goal.position_tolerance_m[i]) if len(goal.position_tolerance_m) else 0.0
        atol = float(goal.orientation_tolerance_rad[i]) if len(goal.orientation_tolerance_rad) else 0.0
        out.append(PartGoal(ids.index(int(pid)), float(t.x), float(t.y), float(t.theta) if oriented else None,
                            tol or default_tol_m, atol or default_tol_rad))
    return out


#: A lost track is taken over by a new one of the same label within this distance (m): touching
#: parts are lost by the tracker and come back under new ids.
REASSOCIATE_M = 0.02


def reassociate(ids: list[int], labels: list, last_xy: list, by_id: dict) -> None:
    """Rows whose track is gone take over the nearest new track (an id in no row) of the same
    label within REASSOCIATE_M of where the row was last seen (in place)."""
    taken = set(ids)
    for row, pid in enumerate(ids):
        if pid in by_id or last_xy[row] is None:
            continue
        x, y = last_xy[row]
        near = [(math.hypot(p.pose.x - x, p.pose.y - y), nid) for nid, p in by_id.items()
                if nid not in taken and p.label == labels[row]]
        near = [c for c in near if c[0] <= REASSOCIATE_M]
        if near:
            ids[row] = min(near)[1]
            taken.add(ids[row])


def _track_names(ids: list[int]) -> list[str]:
    """What the planner's texts call each row: its track id (``ppod move`` and MoveParts name parts
    by it), not the row of the planner's pose table."""
    return [f"track {i}" for i in ids]


def _progress(fb, multi: bool, stamp) -> PlannerProgress:
    """The action feedback ``fb`` as a PlannerProgress message (the plain, recordable copy)."""
    msg = PlannerProgress(action="move_parts" if multi else "move_part", phase=fb.phase, text=fb.text)
    msg.header.stamp = stamp
    if multi:
        msg.part_ids, msg.within, msg.velocity_scale = list(fb.part_ids), list(fb.within), list(fb.velocity_scale)
        msg.position_error_m, msg.orientation_error_rad = list(fb.position_error_m), list(fb.orientation_error_rad)
        msg.plan_ms = float(fb.plan_ms)
    else:
        msg.position_error_m, msg.orientation_error_rad = [fb.position_error_m], [fb.orientation_error_rad]
    return msg


class _RunningTask:
    """The MovePart goal being executed: its handle, the Task, the track ids in Task order."""

    def __init__(self, handle, task: Task | SensorlessTask | MultiTask, ids: list[int], goal, started_s: float,
                 multi: bool = False):
        self.handle = handle
        self.task = task
        self.ids = ids
        self.goal = goal
        self.started_s = started_s
        self.done: Future = Future()
        self.last_motion_key = None
        self.last_step = None
        self.multi = multi      # a MoveParts goal (a MovePart goal may run a MultiTask of one part too)
        self.labels: list[str | None] = [None] * len(ids)   # per row, as last seen
        self.last_xy: list[tuple[float, float] | None] = [None] * len(ids)
        self.stopped_at: float | None = None       # the lease stopped the plate at this device time
        self.stopped_poses: np.ndarray | None = None
        self.lease_stops = 0
        self.step_called_at: float | None = None   # device time the step being planned was submitted
        self.last_plan_ms = 0.0    # wall time of the goal's last replanning step (steps between report 0)


class FieldPlannerNode(PpodLifecycleNode):
    # Read per request from self.params, so a change applies to the next request (nodes/common/lifecycle.py).
    RUNTIME_PARAMS = ("frequency_hz", "num_frequencies", "position_tolerance_m", "orientation_tolerance_deg",
                      "timeout_s", "stop_when_done", "plan_lease_s", "plan_stuck_s")
    PARAMS = (
        Param("device_config", "", "device description YAML; empty: the packaged default (docs/device.md)"),
        Param("tracker_config", "", "tracker file naming the part types (label -> part model); "
                                    "empty: the packaged default"),
        Param("default_mu", 0.3, "friction of parts whose model is not given", min_value=0.01, max_value=2.0),
        Param("frequency_hz", 0.0, "design frequency (Hz); 0: the planner's default", min_value=0.0),
        Param("num_frequencies", 1, "1 (11 inputs) or 2 (23 inputs)", min_value=1, max_value=2),
        Param("position_tolerance_m", 1e-3, "default MovePart position tolerance (m)", min_value=1e-5),
        Param("orientation_tolerance_deg", 2.0, "default MovePart orientation tolerance (deg)", min_value=0.01),
        Param("timeout_s", 60.0, "default MovePart timeout (device-clock s)", min_value=1.0),
        Param("stop_when_done", True, "ramp the plate down when a MovePart goal ends (parts stay put)"),
        Param("plan_lease_s", 1.0, "device time a MoveParts motion may play past the poses it was planned on "
                                   "while the next plan is computed; then the plate stops until it comes",
              min_value=0.1, max_value=10.0),
        Param("plan_stuck_s", 10.0, "device time a planning step may take before its goal ends as failed "
                                    "(the plate stopped, the planning thread abandoned)", min_value=1.0,
              max_value=600.0),
    )

    def __init__(self, **kwargs):
        super().__init__("field_planner", **kwargs)
        self.device = None
        self.models: dict[str, Any] = {}
        self.running: _RunningTask | None = None
        self._poses: PartPoseArray | None = None
        # Closed-loop steps run on one planning thread; the executor applies their results.
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="planner")
        self._abandoned = 0   # planning threads given up on (plan_stuck_s)
        self._pending: tuple[_RunningTask, float, Any] | None = None
        self._step_done = self.create_guard_condition(self._on_step_done)
        self.goal_pub = self.create_lifecycle_publisher(PlateMotionMsg, topics.GOAL, qos.COMMANDS)
        self.target_pub = self.create_publisher(PartPoseArray, topics.MOVE_PART_TARGET, qos.LATCHED)  # drawn by viz
        self.progress_pub = self.create_publisher(PlannerProgress, topics.PLANNER_PROGRESS, qos.STREAM)
        self.create_service(PlanField, topics.PLAN_FIELD, self._on_plan_field)
        self.create_subscription(PartPoseArray, topics.PART_POSES, self._on_poses, qos.LATEST)
        self._stop_client = self.create_client(Trigger, topics.STOP)
        self._action = ActionServer(self, MovePart, topics.MOVE_PART, execute_callback=self._execute,
                                    goal_callback=self._on_goal_request, cancel_callback=self._on_cancel)
        self._multi_action = ActionServer(self, MoveParts, topics.MOVE_PARTS, execute_callback=self._execute_multi,
                                          goal_callback=self._on_multi_request, cancel_callback=self._on_cancel)
        self.create_timer(0.1, self._on_sensorless_tick)

    # ------------------------------------------------------------------ lifecycle
    def on_configure_node(self, params):
        self.device = load_device_config(params["device_config"] or None)
        tracker = params["tracker_config"] or str(resources.files("ppod_ros") / "data" / "tracker.yaml")
        self.models = part_models_from_tracker_file(tracker, params["default_mu"])
        self.get_logger().info(f"part models: {', '.join(f'{k} ({v.kind})' for k, v in self.models.items())}")
        for kind in base_kinds():  # the MoveParts planner's templates, designed once here
            base_design(kind, self.device)

    def on_deactivate_node(self):
        if self.running is not None:
            self._finish(False, "the planner was deactivated")

    def on_cleanup_node(self):
        self.device, self.models = None, {}

    def on_shutdown_node(self):
        if self.running is not None:
            self._finish(False, "the planner shut down")
        self._worker.shutdown(wait=False, cancel_futures=True)

    # ------------------------------------------------------------------ PlanField
    def _frequency(self, requested: float) -> float | None:
        f = requested or self.params.get("frequency_hz", 0.0)
        return float(f) if f > 0 else None

    def _on_plan_field(self, req: PlanField.Request, resp: PlanField.Response) -> PlanField.Response:
        if self.lifecycle_state != "active":
            resp.success, resp.reason = False, f"field_planner is {self.lifecycle_state}, not active"
            return resp
        try:
            spec = FieldSpec.from_request(req.field_type, list(req.params))
            part = part_from_yaml_text(req.part_yaml, "part_yaml") if req.part_yaml.strip() else None
            harmonics = int(req.num_frequencies) or self.params["num_frequencies"]
            result = design_field(spec, part, frequency_hz=self._frequency(req.frequency_hz),
                                  harmonics=harmonics, device=self.device)
        except PpodError as exc:
            resp.success, resp.reason = False, str(exc)
            self.get_logger().warning(f"PlanField {req.field_type} {list(req.params)} rejected: {exc}")
            return resp
        resp.success, resp.reason = True, "; ".join(result.messages)
        resp.motion = motion_to_msg(result.motion, self.get_clock().now().to_msg())
        resp.r_squared, resp.rms_error_mps = float(result.r2), float(result.rms_error_mps)
        resp.valid_fraction, resp.seconds = float(result.valid_fraction), float(result.seconds)
        self.get_logger().info(f"designed '{result.motion.name}': R^2 {result.r2:.4f}, rms "
                               f"{1e3 * result.rms_error_mps:.2f} mm/s, {result.seconds:.2f} s"
                               + (" (cached)" if result.cached else ""))
        self.diagnostics.set("design", diag.OK if result.r2 >= 0.98 else diag.WARN,
                             f"{req.field_type}: R^2 {result.r2:.4f}", r_squared=result.r2, seconds=result.seconds)
        if req.apply:
            if self.running is not None:
                resp.reason += "; not applied: a MovePart goal is running"
            else:
                self.goal_pub.publish(resp.motion)
        return resp

    # ------------------------------------------------------------------ MovePart
    def _on_goal_request(self, goal: MovePart.Goal) -> GoalResponse:
        if self.lifecycle_state != "active":
            self.get_logger().warning("MovePart rejected: the planner is not active")
            return GoalResponse.REJECT
        if self.running is not None:
            self.get_logger().warning("MovePart rejected: another goal is running (a field moves every part)")
            return GoalResponse.REJECT
        tracked = self._poses is not None and any(p.id == goal.part_id for p in self._poses.parts)
        if not tracked and not goal.sensorless:
            self.get_logger().warning(f"MovePart rejected: part {goal.part_id} is not tracked")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _on_multi_request(self, goal: MoveParts.Goal) -> GoalResponse:
        if self.lifecycle_state != "active":
            self.get_logger().warning("MoveParts rejected: the planner is not active")
            return GoalResponse.REJECT
        if self.running is not None:
            self.get_logger().warning("MoveParts rejected: another goal is running (a field moves every part)")
            return GoalResponse.REJECT
        try:
            self._build_multi(goal)
        except PpodError as exc:
            self.get_logger().warning(f"MoveParts rejected: {exc}")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _build_multi(self, goal: MoveParts.Goal) -> tuple[MultiTask, list[int]]:
        parts, ids = [], []
        for p in (self._poses.parts if self._poses is not None else []):
            model = self.models.get(p.label)
            if model is None:
                model = PointPart(mu=self.params["default_mu"])
            parts.append(model)
            ids.append(int(p.id))
        p = self.params
        goals = part_goals_from_request(goal, ids, p["position_tolerance_m"],
                                        math.radians(p["orientation_tolerance_deg"]))
        task = MultiTask(parts, goals, device=self.device, timeout_s=goal.timeout_s or p["timeout_s"],
                         keep_clear=bool(goal.keep_others_clear), names=_track_names(ids))
        return task, ids

    async def _execute_multi(self, handle) -> MoveParts.Result:
        goal: MoveParts.Goal = handle.request
        result = MoveParts.Result()
        task = self._start(handle, self._build_multi, result, "MoveParts")
        if task is None:
            return result
        self.get_logger().info("MoveParts: " + ", ".join(
            f"part {g_id} to ({t.x:.4f}, {t.y:.4f}" + (f", {math.degrees(t.theta):.1f} deg)" if g.theta_rad is not None
                                                       else ")")
            for g_id, t, g in zip(goal.part_ids, goal.targets, task.goals)))
        running = self.running
        success, reason = await running.done
        step = running.last_step
        result.success, result.reason = bool(success), reason
        result.elapsed_s = self._now() - running.started_s
        result.part_ids = [int(v) for v in goal.part_ids]
        statuses = {st.index: st for st in (step.parts if step is not None else ())}
        for g, pid in zip(task.goals, goal.part_ids):
            st = statuses.get(g.index)
            result.reached.append(bool(st is not None and st.reached))
            result.position_error_m.append(float(st.position_error_m) if st is not None else math.nan)
            result.orientation_error_rad.append(float(st.angle_error_rad or 0.0) if st is not None else 0.0)
            result.time_to_goal_s.append(float(st.time_to_goal_s) if st is not None and st.reached else -1.0)
            pose = self._pose_of(int(pid))
            result.final_poses.append(pose.pose if pose is not None else type(goal.targets[0])())
        self._end(handle, success, reason, "MoveParts")
        return result

    def _start(self, handle, build, result, name: str):
        """Build the task for ``handle``'s goal and make it the running one; on a PpodError abort the
        goal with the reason in ``result`` and return None."""
        try:
            task, ids = build(handle.request)
        except PpodError as exc:
            handle.abort()
            result.success, result.reason = False, str(exc)
            self.get_logger().error(f"{name}: {exc}")
            return None
        self.running = _RunningTask(handle, task, ids, handle.request, self._now(), multi=name == "MoveParts")
        return task

    def _end(self, handle, success: bool, reason: str, name: str) -> None:
        """Close the action goal the way it ended (canceled, succeeded or aborted) and log it."""
        if handle.is_cancel_requested:
            handle.canceled()
        elif success:
            handle.succeed()
        else:
            handle.abort()
        self.get_logger().info(f"{name} {'succeeded' if success else 'ended'}: {reason}")

    def _on_cancel(self, _handle) -> CancelResponse:
        return CancelResponse.ACCEPT

    def _build_task(self, goal: MovePart.Goal) -> tuple[Task | SensorlessTask | MultiTask, list[int]]:
        parts, ids = [], []
        for p in (self._poses.parts if self._poses is not None else []):
            model = self.models.get(p.label)
            if model is None:
                model = PointPart(mu=self.params["default_mu"])
                self.get_logger().warning(f"no model for label {p.label!r}: treated as a point part")
            parts.append(model)
            ids.append(int(p.id))
        p = self.params
        theta = float(goal.target.theta) if goal.use_orientation else None
        target = (float(goal.target.x), float(goal.target.y), theta)
        position_tol = goal.position_tolerance_m or p["position_tolerance_m"]
        angle_tol = goal.orientation_tolerance_rad or math.radians(p["orientation_tolerance_deg"])
        if goal.sensorless:
            if int(goal.part_id) not in ids:  # never seen: the default model, reported in the poses as unseen
                self.get_logger().warning(f"sensorless: part {goal.part_id} is not tracked: planned as a point part "
                                          f"with mu {p['default_mu']:g}")
                parts.append(PointPart(mu=p["default_mu"]))
                ids.append(int(goal.part_id))
            chosen = ids.index(int(goal.part_id))
            plan = plan_sensorless(parts[chosen], target, device=self.device, position_tol_m=position_tol,
                                   angle_tol_rad=angle_tol)
            for line in plan.describe().splitlines():
                self.get_logger().info(line)
            return SensorlessTask(plan, chosen), ids
        timeout = goal.timeout_s or p["timeout_s"]
        if goal.collect_others:  # the template planner: the chosen part's sink, then the others gathered
            collect = (float(goal.collect_x_m), float(goal.collect_y_m))
            return Task(parts, ids.index(int(goal.part_id)), target, collect, device=self.device,
                        position_tol_m=position_tol, angle_tol_rad=angle_tol, timeout_s=timeout), ids
        # One part, nothing to gather: the model-predictive planner with one goal (one bracket in the
        # benchmark: 10 of 10 reached against 7 of 10 for the template planner; docs/planner.md).
        one = PartGoal(ids.index(int(goal.part_id)), target[0], target[1], theta, position_tol, angle_tol)
        return MultiTask(parts, [one], device=self.device, timeout_s=timeout, names=_track_names(ids)), ids

    async def _execute(self, handle) -> MovePart.Result:
        goal: MovePart.Goal = handle.request
        result = MovePart.Result()
        task = self._start(handle, self._build_task, result, "MovePart")
        if task is None:
            return result
        self.target_pub.publish(PartPoseArray(parts=[PartPose(id=goal.part_id, label="target", pose=goal.target)]))
        self.get_logger().info(f"MovePart: part {goal.part_id} to ({goal.target.x:.4f}, {goal.target.y:.4f}"
                               + (f", {math.degrees(goal.target.theta):.1f} deg)" if goal.use_orientation else ")")
                               + (f", others to ({goal.collect_x_m:.3f}, {goal.collect_y_m:.3f})"
                                  if goal.collect_others else "")
                               + (f", sensorless: {task.plan.total_s:.1f} s open loop"
                                  if isinstance(task, SensorlessTask) else ""))
        running = self.running
        success, reason = await running.done
        step = running.last_step
        result.success, result.reason = bool(success), reason
        result.elapsed_s = self._now() - running.started_s
        pose = self._pose_of(goal.part_id)
        if pose is not None:
            result.final_pose = pose.pose
        if step is not None:
            result.position_error_m = float(step.position_error_m)
            result.orientation_error_rad = float(step.angle_error_rad or 0.0)
        self._end(handle, success, reason, "MovePart")
        return result

    def _pose_of(self, part_id: int) -> PartPose | None:
        if self._poses is None:
            return None
        return next((p for p in self._poses.parts if p.id == part_id), None)

    def _on_poses(self, msg: PartPoseArray) -> None:
        self._poses = msg
        run = self.running
        if run is None or isinstance(run.task, SensorlessTask):
            return
        self._step(run, stamp_to_seconds(msg.header.stamp))

    def _on_sensorless_tick(self) -> None:
        run = self.running
        if run is not None and isinstance(run.task, SensorlessTask):
            self._step(run, self._now())

    def _step(self, run: _RunningTask, t_s: float) -> None:
        """Step the running task at time ``t_s`` on the latest poses (rows in the task's part order).

        A closed-loop task steps on the planning thread, so the executor keeps serving poses,
        cancels and services while it plans; a frame that arrives while a step is computed is
        skipped (the next step takes the newest poses) and checks the plan's lease."""
        if run.handle.is_cancel_requested:
            self._finish(False, "cancelled")
            return
        poses = self._rows(run)
        if isinstance(run.task, SensorlessTask):  # open loop on the clock: a lookup, never slow
            self._apply(run, t_s, self._timed_step(run, t_s, poses))
            return
        if self._pending is not None:
            if self._pending[2].done():   # finished, its wake-up not applied yet (or lost): apply it now
                self._on_step_done()
                return
            self._check_lease(run, t_s, poses)
            self._check_stuck(run, t_s)
            return
        run.step_called_at = self._now()
        self._pending = (run, t_s, self._worker.submit(self._timed_step, run, t_s, poses))
        self._pending[2].add_done_callback(self._signal_step_done)

    def _signal_step_done(self, _future) -> None:
        """On the planning thread: wake the executor to apply the step."""
        # The node may have been destroyed while the step ran (rclpy's InvalidHandle): nothing to apply.
        with contextlib.suppress(Exception):
            self._step_done.trigger()

    def _rows(self, run: _RunningTask) -> np.ndarray:
        """The latest poses in the task's row order (NaN rows unseen); re-associates MoveParts tracks."""
        parts = self._poses.parts if self._poses is not None else []
        by_id = {int(p.id): p for p in parts if p.status != PartPose.STATUS_LOST}
        if run.multi:
            reassociate(run.ids, run.labels, run.last_xy, by_id)
        poses = np.full((len(run.ids), 3), np.nan)
        for row, pid in enumerate(run.ids):
            p = by_id.get(pid)
            if p is not None:
                poses[row] = (p.pose.x, p.pose.y, p.pose.theta)
                run.last_xy[row] = (p.pose.x, p.pose.y)
                run.labels[row] = p.label
        return poses

    @staticmethod
    def _timed_step(run: _RunningTask, t_s: float, poses: np.ndarray):
        """The task's step (on the planning thread for closed-loop tasks): (step or the PpodError, ms)."""
        t0 = time.perf_counter()
        try:
            out = run.task.step(t_s, poses)
        except PpodError as exc:
            out = exc
        return out, 1e3 * (time.perf_counter() - t0)

    def _on_step_done(self) -> None:
        """The planning thread finished a step: apply it on the executor thread (unless its task
        ended meanwhile, or the lease stopped the plate while it was planned: then the plan, made on
        poses from before the stop, is dropped and the task continues from rest)."""
        if self._pending is None or not self._pending[2].done():
            return
        (run, t_s, future), self._pending = self._pending, None
        if run is not self.running:
            return
        try:
            outcome = future.result()
        except Exception as exc:  # a planner bug must not kill the node that commands the plate
            self.get_logger().error(f"planning step raised {type(exc).__name__}: {exc}")
            self._finish(False, f"planning failed (internal error, {type(exc).__name__}: {exc}); plate stopped")
            return
        if run.stopped_at is not None:
            stopped_at, stopped_poses = run.stopped_at, run.stopped_poses
            run.stopped_at = run.stopped_poses = None
            if t_s < stopped_at and not isinstance(outcome[0], PpodError):
                run.task.plate_stopped(stopped_at, stopped_poses)
                self._apply(run, t_s, outcome, publish_motion=False)
                return
        self._apply(run, t_s, outcome)

    def _check_lease(self, run: _RunningTask, t_s: float, poses: np.ndarray) -> None:
        """While a MultiTask plans, the motion playing was planned at ``task.t_plan``: past
        ``plan_lease_s`` of device time it is no longer a plan but a guess (the parts have moved on
        under it), so the plate stops (at rest it holds every part) until the next plan."""
        task = run.task
        if not isinstance(task, MultiTask) or run.stopped_at is not None or task.current.is_zero():
            return
        age = t_s - task.t_plan
        lease = float(self.params.get("plan_lease_s", 1.0))
        if age <= lease:
            return
        rest = PlateMotion.zero(task.current.frequency_hz, name="rest")
        self.goal_pub.publish(motion_to_msg(rest, self.get_clock().now().to_msg()))
        run.last_motion_key = rest.key
        run.stopped_at, run.stopped_poses = t_s, poses.copy()
        run.lease_stops += 1
        self.get_logger().warning(
            f"replanning is late: the motion playing was planned on poses {age:.2f} s old (plan_lease_s "
            f"{lease:g} s): plate stopped until the next plan ({run.lease_stops} such stops in this goal)")

    def _check_stuck(self, run: _RunningTask, t_s: float) -> None:
        """A planning step pending for more than ``plan_stuck_s`` of device time (from the frame it
        was planned on) will not be waited for: the planning thread's stack goes to the log and the
        thread is abandoned (Python cannot stop it), so the next step plans on a new one. When the
        step is the running goal's, that goal ends as failed and the plate stops; a step of a goal
        that has ended (cancelled while it hung) no longer holds up the goal now running."""
        pending_run, planned_t, future = self._pending
        limit = float(self.params.get("plan_stuck_s", 10.0))
        age = t_s - planned_t
        if age <= limit or future.done():
            return
        self._pending = None
        stuck, self._worker = self._worker, ThreadPoolExecutor(max_workers=1, thread_name_prefix="planner")
        stuck.shutdown(wait=False, cancel_futures=True)
        self._abandoned += 1
        whose = "" if pending_run is run else " (of a goal that has ended)"
        self.get_logger().error(f"planning step{whose} has not returned after {age:.1f} s of device time "
                                f"(plan_stuck_s {limit:g} s); abandoned, where it is: {_stacks_of(stuck)}")
        if pending_run is run:
            self._finish(False, f"planning step did not return within plan_stuck_s {limit:g} s of device "
                                "time (abandoned; see the node's log); plate stopped")

    def _apply(self, run: _RunningTask, t_s: float, outcome, publish_motion: bool = True) -> None:
        """Publish a finished step: its motion (when new), the action feedback and the progress. A
        failure doing so (a bug) ends the goal with the reason and stops the plate, as a planning
        step's does: the goal must not wait for steps that are never applied, nor the node die."""
        try:
            self._publish_step(run, t_s, outcome, publish_motion)
        except Exception as exc:
            self.get_logger().error(f"applying a planning step raised {type(exc).__name__}: {exc}")
            self._finish(False, f"planning failed (internal error applying a step, {type(exc).__name__}: "
                                f"{exc}); plate stopped")

    def _publish_step(self, run: _RunningTask, t_s: float, outcome, publish_motion: bool) -> None:
        step, step_ms = outcome
        if isinstance(step, PpodError):
            self._finish(False, f"planning failed: {step}")
            return
        plan_ms = getattr(step, "plan_ms", 0.0)   # MultiStep's (a Task's or SensorlessTask's step has none)
        if plan_ms > 0:
            run.last_plan_ms = float(plan_ms)
        if publish_motion and step.motion is not None and step.motion.key != run.last_motion_key:
            run.last_motion_key = step.motion.key
            self.goal_pub.publish(motion_to_msg(step.motion, self.get_clock().now().to_msg()))
            if isinstance(run.task, MultiTask) and run.step_called_at is not None:
                # The planning time and the executor's, in device time: the planner lowers its
                # approach gain for it (MpcSettings.latency_ref_s).
                run.task.command_latency(self._now() - run.step_called_at)
        if run.multi:
            fb = MoveParts.Feedback(phase=step.phase, text=step.text, plan_ms=run.last_plan_ms)
            for st in step.parts:
                fb.part_ids.append(int(run.ids[st.index]))
                fb.position_error_m.append(float(st.position_error_m))
                fb.orientation_error_rad.append(float(st.angle_error_rad or 0.0))
                fb.within.append(bool(st.within))
                fb.velocity_scale.append(float(st.velocity_scale))
        else:
            fb = MovePart.Feedback(phase=step.phase, text=step.text, position_error_m=float(step.position_error_m),
                                   orientation_error_rad=float(step.angle_error_rad or 0.0))
            pose = self._pose_of(int(run.goal.part_id))
            if pose is not None:
                fb.current_pose = pose.pose
        run.handle.publish_feedback(fb)
        self.progress_pub.publish(_progress(fb, run.multi, self.get_clock().now().to_msg()))
        # The running mean of the reported command latency (a MultiTask's).
        extra = {"command_latency_s": run.task.latency_s} if isinstance(run.task, MultiTask) else {}
        self.diagnostics.set("task", diag.OK, step.text, phase=step.phase, position_error_m=step.position_error_m,
                             step_ms=step_ms, lease_stops=run.lease_stops, **extra)
        run.last_step = step   # published: the goal's result reads it
        if step.done or step.failed_reason:
            self._finish(step.done and not step.failed_reason, step.failed_reason or step.text)

    def _finish(self, success: bool, reason: str) -> None:
        run, self.running = self.running, None
        if run is None:
            return
        if self.params.get("stop_when_done", True) or not success:
            # Static friction holds the parts where they are once the plate is at rest.
            if self._stop_client.service_is_ready():
                self._stop_client.call_async(Trigger.Request())
            else:
                self.get_logger().warning("ppod/stop is not available: the last motion keeps playing")
        self.diagnostics.set("task", diag.OK if success else diag.WARN, reason)
        if not run.done.done():
            run.done.set_result((success, reason))

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9


def _stacks_of(pool: ThreadPoolExecutor) -> str:
    """The innermost frames of ``pool``'s threads, on one line (for the log)."""
    frames = sys._current_frames()
    out = []
    for thread in list(getattr(pool, "_threads", ())):
        frame = frames.get(thread.ident) if isinstance(thread, threading.Thread) else None
        if frame is not None:
            calls = traceback.extract_stack(frame)[-6:]
            out.append(f"{thread.name}: " + " <- ".join(f"{Path(c.filename).name}:{c.lineno} {c.name}"
                                                        for c in reversed(calls)))
    return "; ".join(out) or "no live planning thread"


main = make_main(FieldPlannerNode)

if __name__ == "__main__":
    raise SystemExit(main())

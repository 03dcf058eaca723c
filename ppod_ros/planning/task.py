"""Closed-loop manipulation: bring a tracked part to a goal pose by choosing and updating fields.

A plate field moves every part at once, so the sequence is built on one sink, centred on the goal:

  positioning  the sink designed for the goal (design_field, cached). Integral action moves the
               sink's centre (shift_centre: an exact change of a_z, no redesign) to cancel the
               steady offset that the real plate (plant mismatch, friction differences) produces.
  turning      rigid parts more than 15 degrees from the goal orientation (until within 8): a
               rotation field about the part spins it in place, first of all, before the others
               come near (0.3 rad/s asked; the orienting field below converges more slowly and has
               two stable orientations, theta and theta + pi, so it must start on the right side).
  orienting    rigid parts: the rotated u1 motion whose line sink passes through the goal
               (design kind "orient"): the part turns to theta while it stays on that line.
  holding      the part is within tolerance; with ``collect``, the sink stays on while the other
               parts gather around the goal (they share the sink: the chosen part, nearest, arrives
               first), with the same integral action keeping the chosen part in place.
  done/failed  within tolerance for ``settle_s`` (and the others gathered, or the collecting time
               spent); failed on timeout or when the part is no longer seen.

Poses come from the tracker in the plate frame, one array per camera frame (10 Hz), NaN rows for
parts not seen. ``step`` raises ConfigError for malformed poses and LimitError when a field cannot
be designed within the device's limits. It is cheap except when a new field must be designed (at most once per
goal and field kind, about a second; cached across tasks).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion
from ppod_ros.parts import PointPart, RigidPart
from ppod_ros.planning.design import design_field, shift_centre
from ppod_ros.planning.specs import CENTRE_RADIUS_M, FieldSpec


@dataclass(frozen=True)
class TaskStep:
    motion: PlateMotion | None          # None: keep the current motion
    phase: str
    done: bool
    failed_reason: str | None
    position_error_m: float
    angle_error_rad: float | None
    text: str


def _wrap(a: float, period: float = 2 * math.pi) -> float:
    return (a + period / 2) % period - period / 2


def orient_motion(x_m: float, y_m: float, theta_rad: float, device=None) -> PlateMotion:
    """The orienting motion through (x, y) for orientation theta (see design kind "orient")."""
    return design_field(FieldSpec.from_request("orient", [x_m, y_m, theta_rad]), device=device).motion


class Task:
    """Move ``parts[chosen]`` to ``goal`` = (x, y, theta or None); see the module docstring."""

    def __init__(self, parts: Sequence[PointPart | RigidPart], chosen: int, goal, collect=None, *, device=None,
                 position_tol_m: float = 1e-3, angle_tol_rad: float = math.radians(2.0), timeout_s: float = 60.0,
                 gain_per_s: float = 0.3, integral_per_s: float = 0.5, settle_s: float = 0.5,
                 collect_radius_m: float = 0.04, lost_after_s: float = 2.0, integral_zone_m: float = 0.01):
        if not parts:
            raise ConfigError("parts: expected at least one part")
        if not 0 <= int(chosen) < len(parts):
            raise ConfigError(f"chosen: index {chosen} outside 0..{len(parts) - 1}")
        goal = tuple(goal)
        if len(goal) != 3:
            raise ConfigError(f"goal: expected (x_m, y_m, theta_rad or None), got {goal!r}")
        gx, gy, gt = goal
        if not (math.isfinite(gx) and math.isfinite(gy)) or (gt is not None and not math.isfinite(gt)):
            raise ConfigError(f"goal: must be finite, got {goal!r}")
        if math.hypot(gx, gy) > CENTRE_RADIUS_M:
            raise ConfigError(f"goal: ({gx:g}, {gy:g}) m is outside the working disc (radius {CENTRE_RADIUS_M} m)")
        if collect is not None:
            cx, cy = (float(v) for v in collect)
            if math.hypot(cx - gx, cy - gy) > 0.01:
                raise ConfigError(
                    f"collect: ({cx:g}, {cy:g}) m is not at the goal: a plate field moves every part, so the "
                    f"others can only be gathered in the sink that positions the chosen part (give the goal)")
        for name, v in (("position_tol_m", position_tol_m), ("angle_tol_rad", angle_tol_rad),
                        ("timeout_s", timeout_s)):
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"{name}: must be > 0, got {v!r}")
        self.parts = list(parts)
        self.chosen = int(chosen)
        self.rigid = isinstance(self.parts[self.chosen], RigidPart)
        self.goal = np.array([gx, gy], dtype=float)
        self.goal_theta = None if (gt is None or not self.rigid) else float(gt)
        self.collect = collect is not None
        self.device = device
        self.tol, self.angle_tol, self.timeout = float(position_tol_m), float(angle_tol_rad), float(timeout_s)
        self.gain, self.ki, self.settle = gain_per_s, integral_per_s, settle_s
        self.collect_radius, self.lost_after = collect_radius_m, lost_after_s
        self.integral_zone_m = float(integral_zone_m)
        fp = getattr(self.parts[self.chosen], "footprint", None)
        sym = fp.symmetry_rad if fp is not None else 2 * math.pi
        self.symmetry = sym if sym > 0 else 2 * math.pi
        self.t0: float | None = None
        self.t_last: float | None = None
        self.last_seen: float | None = None
        self.in_tol_since: float | None = None
        self.held_since: float | None = None
        self.offset = np.zeros(2)  # integral action: where the sink's centre is moved
        self._applied_offset = np.zeros(2)
        self._track: list[tuple[float, float, float]] = []  # (t, x, y) over the last second
        self._offset_changed_s = -math.inf
        self.phase = "positioning"
        self.current_key: tuple | None = None
        self.finished: TaskStep | None = None
        self._sink = design_field(FieldSpec.from_request("sink", [gx, gy, gain_per_s]), self._point(),
                                  device=device).motion

    def _point(self) -> PointPart:
        part = self.parts[self.chosen]
        return part if isinstance(part, PointPart) else PointPart(mu=float(np.mean(part.mu)))

    # ------------------------------------------------------------------ stepping
    def step(self, t_s: float, poses) -> TaskStep:
        """One camera frame: ``poses`` (N, 3) [x, y, theta] in the plate frame, NaN rows unseen."""
        if self.finished is not None:
            return self.finished
        poses = np.asarray(poses, dtype=float).reshape(-1, 3)
        if poses.shape[0] != len(self.parts):
            raise ConfigError(f"poses: expected {len(self.parts)} rows, got {poses.shape[0]}")
        if self.t0 is None:
            self.t0 = self.last_seen = t_s
        dt = 0.0 if self.t_last is None else max(0.0, t_s - self.t_last)
        self.t_last = t_s
        elapsed = t_s - self.t0
        me = poses[self.chosen]
        if not np.all(np.isfinite(me[:2])):
            if t_s - self.last_seen > self.lost_after:
                return self._end(None, f"part not seen for {t_s - self.last_seen:.1f} s", math.nan, None)
            return TaskStep(None, self.phase, False, None, math.nan, None, f"{self.phase}: part not seen")
        self.last_seen = t_s
        err = self.goal - me[:2]
        dist = float(np.hypot(*err))
        ang = None if self.goal_theta is None else _wrap(me[2] - self.goal_theta, self.symmetry)
        if elapsed > self.timeout:
            return self._end(dist, f"timeout after {elapsed:.1f} s: {1e3 * dist:.2f} mm"
                             + ("" if ang is None else f", {math.degrees(abs(ang)):.1f} deg") + " from the goal",
                             dist, ang)
        pos_ok = dist <= self.tol
        ang_ok = ang is None or abs(ang) <= self.angle_tol
        others = [i for i in range(len(self.parts)) if i != self.chosen and np.all(np.isfinite(poses[i, :2]))]
        spread = max((float(np.hypot(*(poses[i, :2] - self.goal))) for i in others), default=0.0)
        # Touching parts are not tracked (never guessed): say how many of the others the spread covers.
        n_others = len(self.parts) - 1
        seen = (f"others within {1e3 * spread:.0f} mm ({len(others)} of {n_others} seen)" if others
                else f"none of the {n_others} others seen")
        if pos_ok and ang_ok:
            self.in_tol_since = t_s if self.in_tol_since is None else self.in_tol_since
            self.held_since = t_s if self.held_since is None else self.held_since
            gathered = not self.collect or spread <= self.collect_radius
            collect_spent = t_s - self.held_since > 0.5 * self.timeout
            if t_s - self.in_tol_since >= self.settle and (gathered or collect_spent):
                text = (f"done in {elapsed:.1f} s: {1e3 * dist:.2f} mm"
                        + ("" if ang is None else f", {math.degrees(abs(ang)):.2f} deg") + " from the goal"
                        + (f"; {seen}" if self.collect else ""))
                return self._end(dist, None, dist, ang, text=text)
        else:
            self.in_tol_since = None
        # Integral action on the sink centre while positioning or holding: within 3 mm of the goal,
        # or within integral_zone_m (10 mm) once the part has stalled (moved under 0.3 mm in the
        # last second: parts crowding round the goal hold it off, which only the integral
        # corrects). Integrating while the part is still approaching would wind up and overshoot.
        self._track.append((t_s, me[0], me[1]))
        while len(self._track) > 2 and t_s - self._track[1][0] >= 1.0:
            self._track.pop(0)
        moved = math.hypot(me[0] - self._track[0][1], me[1] - self._track[0][2])
        stalled = t_s - self._track[0][0] >= 1.0 and moved < 3e-4
        if self.phase in ("positioning", "holding") and (dist < 0.003 or (dist < self.integral_zone_m and stalled)):
            self.offset = np.clip(self.offset + self.ki * dt * err, -0.01, 0.01)
        phase = self._choose_phase(dist, ang, pos_ok, ang_ok, me)
        motion = self._motion_for(phase, me)
        self.phase = phase
        text = (f"{phase}: {1e3 * dist:.2f} mm" + ("" if ang is None else f", {math.degrees(ang):+.1f} deg")
                + " from the goal" + (f"; {seen}" if self.collect and others else ""))
        return TaskStep(motion, phase, False, None, dist, ang, text)

    def _choose_phase(self, dist: float, ang: float | None, pos_ok: bool, ang_ok: bool, me: np.ndarray) -> str:
        near = dist <= max(3 * self.tol, 0.003)
        turnable = ang is not None and math.hypot(*me[:2]) <= CENTRE_RADIUS_M - 0.005
        if turnable and (abs(ang) > math.radians(15) or (self.phase == "turning" and abs(ang) > math.radians(8))):
            return "turning"
        # Orient when out of tolerance; once orienting, finish (hysteresis: down to half the
        # tolerance), the orienting line keeps the part near the goal.
        if ang is not None and near and (not ang_ok or (self.phase == "orienting" and abs(ang) > self.angle_tol / 2)):
            return "orienting"
        return "holding" if pos_ok else "positioning"

    def _motion_for(self, phase: str, me: np.ndarray) -> PlateMotion | None:
        if phase in ("positioning", "holding"):
            # Each new motion is a new goal for the accelerometer feedback (it re-learns for about a
            # second): move the sink's centre only in steps of 0.2 mm or more, at most every second.
            applied = self._applied_offset
            due = self.t_last - self._offset_changed_s >= 1.0 and np.hypot(*(self.offset - applied)) >= 2e-4
            if due:
                self._applied_offset, self._offset_changed_s = self.offset.copy(), self.t_last
            key = ("sink", tuple(np.round(self._applied_offset, 6)))
            motion = shift_centre(self._sink, *self._applied_offset) if key != self.current_key else None
        elif phase == "orienting":
            key = ("orient",)
            motion = orient_motion(self.goal[0], self.goal[1], self.goal_theta, self.device) \
                if key != self.current_key else None
        else:  # turning: spin in place about the part, towards the goal orientation
            ang = _wrap(me[2] - self.goal_theta, self.symmetry)
            omega = -0.3 if ang > 0 else 0.3
            key = ("turn", omega)
            if key != self.current_key:
                spec = FieldSpec.from_request("rotation", [float(me[0]), float(me[1]), omega])
                motion = design_field(spec, self._point(), device=self.device).motion
            else:
                motion = None
        if motion is not None:
            self.current_key = key
        return motion

    def _end(self, dist, failed: str | None, d: float, ang, text: str | None = None) -> TaskStep:
        self.finished = TaskStep(None, "failed" if failed else "done", failed is None, failed,
                                 d if d is not None else math.nan, ang, text or f"failed: {failed}")
        return self.finished


__all__ = ["Task", "TaskStep", "orient_motion"]

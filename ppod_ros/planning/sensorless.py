"""Sensorless manipulation: position and orient parts with the stable fixed points of plate fields,
no camera. A plan is a list of fields, each played for a computed time.

  positioning    the sink designed for the goal (design_field). Its actual fixed point (where the
                 asymptotic field of the part's model vanishes, found by Newton's method) is moved
                 onto the goal (shift_centre) and checked stable (both eigenvalues of the field's
                 Jacobian with negative real part). The stage lasts until the asymptotic field,
                 integrated from the worst starts (rings at the edge of the working disc and half
                 way in, rigid parts at several orientations), has brought every start within half
                 the position tolerance, times ``margin``.
  turning away   rigid parts with a goal orientation, when it shortens the plan: the orienting
                 field for theta + pi/4 (stable orientations theta + pi/4 and theta + 5 pi/4),
                 which moves orientations away from theta +- pi/2, where the final field is unstable.
  orienting      the orienting field for theta through the goal: stable orientations theta and
                 theta + pi. Both durations come from integrating the part's rotation rate at the
                 goal (a table over theta from the rigid asymptotic solver) from 720 starting
                 orientations, with the split of the shortest total that brings ``coverage``
                 (default 99 %) of them within half the angle tolerance. Not all: a flow on the
                 circle is continuous, so some start always ends on an unstable orientation, and
                 departing from one is slow. For the published bracket the away stage does not
                 pay (its own unstable orientations are left just as slowly) and is left out.

What a sensorless plan cannot do: tell theta from theta + pi. The orienting fields are symmetric
under a half turn, so a part without half-turn symmetry ends at theta or theta + pi depending on
where it started (``SensorlessPlan.orientation_period_rad``). The durations hold for the part's
model on the nominal plate; ``margin`` (default 1.25) covers modest plant differences. Like the
closed loop, a plan moves every part on the plate: several parts are positioned together only in the
sense that they all gather at the goal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ppod_ros.errors import ConfigError, LimitError
from ppod_ros.motion import PlateMotion
from ppod_ros.parts import PointPart, RigidPart
from ppod_ros.planning.design import design_field, shift_centre
from ppod_ros.planning.specs import CENTRE_RADIUS_M, FieldSpec
from ppod_ros.planning.task import TaskStep, orient_motion

_THETAS = np.linspace(0.0, 2 * math.pi, 12, endpoint=False)  # orientations a rigid part's field is averaged over


@dataclass(frozen=True)
class Stage:
    name: str
    motion: PlateMotion
    duration_s: float
    text: str


@dataclass
class FixedPoint:
    position_m: np.ndarray      # (2,)
    jacobian_per_s: np.ndarray  # (2, 2) d v / d r at the fixed point
    residual_mps: float         # |v| there
    iterations: int

    @property
    def eigenvalues(self) -> np.ndarray:
        return np.linalg.eigvals(self.jacobian_per_s)

    @property
    def stable(self) -> bool:
        return bool(np.all(self.eigenvalues.real < 0))


@dataclass
class SensorlessPlan:
    goal: tuple[float, float, float | None]
    stages: list[Stage]
    fixed_point: FixedPoint
    orientation_period_rad: float | None   # the final orientation is known modulo this (None: not oriented)
    messages: list[str] = field(default_factory=list)

    @property
    def total_s(self) -> float:
        return float(sum(s.duration_s for s in self.stages))

    def stage_at(self, elapsed_s: float) -> int | None:
        """Index of the stage playing ``elapsed_s`` after the start; None once the plan is over."""
        t = 0.0
        for i, s in enumerate(self.stages):
            t += s.duration_s
            if elapsed_s < t:
                return i
        return None

    def describe(self) -> str:
        lines = [f"sensorless plan: {len(self.stages)} fields, {self.total_s:.1f} s"]
        lines += [f"  {s.name:13s} {s.duration_s:5.1f} s  {s.text}" for s in self.stages]
        lines += [f"  {m}" for m in self.messages]
        return "\n".join(lines)


def _model(part: PointPart | RigidPart) -> PointPart | RigidPart:
    if not isinstance(part, (PointPart, RigidPart)):
        raise ConfigError(f"part: expected a PointPart or RigidPart, got {type(part).__name__}")
    return part


def _velocity(motion: PlateMotion, part, xy: np.ndarray, settings) -> tuple[np.ndarray, np.ndarray]:
    """Translational asymptotic velocity (N, 2) at points ``xy`` (N, 2); a rigid part's is averaged
    over its orientations (it turns slowly under a sink). Also the valid flags (N,)."""
    from ppod_ros.physics import solve_field

    if isinstance(part, PointPart):
        r = solve_field(motion, part, xy, settings)
        return np.nan_to_num(r.velocity), r.valid
    n, m = xy.shape[0], _THETAS.size
    cfg = np.column_stack([np.repeat(xy, m, axis=0), np.tile(_THETAS, n)])
    r = solve_field(motion, part, cfg, settings)
    v = np.nan_to_num(r.velocity[:, :2]).reshape(n, m, 2).mean(axis=1)
    return v, r.valid.reshape(n, m).all(axis=1)


def field_fixed_point(motion: PlateMotion, part: PointPart | RigidPart, guess, *, step_m: float = 5e-4,
                      tol_m: float = 1e-6, max_iterations: int = 10, settings=None) -> FixedPoint:
    """Where ``motion``'s asymptotic field for ``part`` vanishes near ``guess`` (x, y): Newton's
    method with a central-difference Jacobian. LimitError if it does not converge or contact is lost."""
    from ppod_ros.physics import PRESETS

    part = _model(part)
    settings = settings or PRESETS["accurate"].replace(cache=False)
    r = np.asarray(guess, dtype=float).reshape(2)
    offsets = np.array([[0, 0], [step_m, 0], [-step_m, 0], [0, step_m], [0, -step_m]])
    for it in range(1, max_iterations + 1):
        v, ok = _velocity(motion, part, r + offsets, settings)
        if not ok.all():
            raise LimitError(f"fixed point: contact lost near ({r[0]:.4f}, {r[1]:.4f}) m")
        J = np.column_stack([(v[1] - v[2]) / (2 * step_m), (v[3] - v[4]) / (2 * step_m)])
        try:
            dr = -np.linalg.solve(J, v[0])
        except np.linalg.LinAlgError as exc:
            raise LimitError(f"fixed point: the field's Jacobian is singular at ({r[0]:.4f}, {r[1]:.4f}) m") from exc
        dr = np.clip(dr, -0.01, 0.01)
        r = r + dr
        if np.hypot(*dr) < tol_m:
            v_end, _ = _velocity(motion, part, r[None], settings)
            return FixedPoint(r, J, float(np.hypot(*v_end[0])), it)
    raise LimitError(f"fixed point: Newton did not converge in {max_iterations} iterations (last step "
                     f"{1e3 * np.hypot(*dr):.3f} mm)")


def _starts(radius_m: float, goal: np.ndarray) -> np.ndarray:
    angles = np.linspace(0, 2 * math.pi, 12, endpoint=False)
    ring = np.column_stack([np.cos(angles), np.sin(angles)])
    pts = np.vstack([radius_m * ring, 0.5 * radius_m * ring + 0.5 * goal])
    return pts[np.hypot(pts[:, 0] - goal[0], pts[:, 1] - goal[1]) > 1e-3]


def _positioning_time(motion, part, target: np.ndarray, starts: np.ndarray, reach_m: float, settings,
                      dt_s: float = 0.5, max_s: float = 120.0) -> tuple[float, int]:
    """Integrate the asymptotic field (Heun) from ``starts`` until all are within ``reach_m`` of
    ``target``; the time and the number of starts where contact was lost."""
    r = starts.copy()
    arrived = np.full(len(r), math.nan)
    lost = np.zeros(len(r), bool)
    t = 0.0
    while t < max_s:
        d = np.hypot(*(r - target).T)
        arrived[np.isnan(arrived) & (d <= reach_m)] = t
        live = np.isnan(arrived) & ~lost
        if not live.any():
            break
        v1, ok1 = _velocity(motion, part, r[live], settings)
        v2, ok2 = _velocity(motion, part, r[live] + dt_s * v1, settings)
        idx = np.flatnonzero(live)
        lost[idx[~(ok1 & ok2)]] = True
        r[idx] += 0.5 * dt_s * (v1 + v2)
        t += dt_s
    if np.isnan(arrived[~lost]).any():
        worst = float(np.max(np.hypot(*(r[~lost] - target).T)))
        raise LimitError(f"sensorless positioning: the field has not brought every start within "
                         f"{1e3 * reach_m:.2f} mm of the goal in {max_s:g} s (worst {1e3 * worst:.1f} mm)")
    return float(np.nanmax(arrived)) if (~lost).any() else 0.0, int(lost.sum())


def _rate_table(motion: PlateMotion, part: RigidPart, xy: np.ndarray, settings, n: int = 72
                ) -> tuple[np.ndarray, np.ndarray]:
    from ppod_ros.physics import solve_field

    th = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    r = solve_field(motion, part, np.column_stack([np.full(n, xy[0]), np.full(n, xy[1]), th]), settings)
    if not r.valid.all():
        raise LimitError(f"sensorless orienting: contact lost at the goal for {int((~r.valid).sum())} of {n} "
                         f"orientations")
    return th, r.velocity[:, 2]


def _rotate(theta: np.ndarray, table: tuple[np.ndarray, np.ndarray], duration_s: float, dt_s: float = 0.05
            ) -> np.ndarray:
    th, w = table
    period = 2 * math.pi
    grid = np.append(th, period)
    rate = np.append(w, w[0])
    out = theta.copy()
    for _ in range(int(round(duration_s / dt_s))):
        k1 = np.interp(out % period, grid, rate)
        k2 = np.interp((out + dt_s * k1) % period, grid, rate)
        out = out + 0.5 * dt_s * (k1 + k2)
    return out


def _wrap(a, period):
    return (np.asarray(a) + period / 2) % period - period / 2


def _orienting_times(away, final, goal_theta: float, tol_rad: float, coverage: float, step_s: float = 0.5,
                     max_s: float = 150.0) -> tuple[float, float]:
    """Durations (turning away, orienting) with the shortest total that bring the fraction
    ``coverage`` of 720 evenly spread starting orientations within ``tol_rad`` of goal_theta
    modulo pi. All of them cannot be promised: a flow on the circle is continuous, so some start
    always ends on an unstable orientation."""
    starts = goal_theta + np.linspace(-math.pi, math.pi, 720, endpoint=False)
    best = None
    for t_away in np.arange(0.0, 30.0 + 1e-9, 1.0):
        th = _rotate(starts, away, t_away) if t_away else starts.copy()
        t = 0.0
        while t <= max_s and np.mean(np.abs(_wrap(th - goal_theta, math.pi)) <= tol_rad) < coverage:
            th = _rotate(th, final, step_s)
            t += step_s
        if t <= max_s and (best is None or t_away + t < sum(best)):
            best = (float(t_away), t)
    if best is None:
        raise LimitError(f"sensorless orienting: no split of the two orienting fields brings {100 * coverage:g} % "
                         f"of the starting orientations within {math.degrees(tol_rad):.1f} deg in {max_s:g} s")
    return best


def plan_sensorless(part: PointPart | RigidPart, goal, *, device=None, gain_per_s: float = 0.3,
                    position_tol_m: float = 1e-3, angle_tol_rad: float = math.radians(2.0),
                    start_radius_m: float = CENTRE_RADIUS_M, margin: float = 1.25,
                    coverage: float = 0.99) -> SensorlessPlan:
    """The sensorless plan that brings ``part`` from anywhere within ``start_radius_m`` of the plate
    centre to ``goal`` = (x, y, theta or None) (see the module docstring)."""
    from ppod_ros.physics import PRESETS

    part = _model(part)
    goal = tuple(goal)
    if len(goal) != 3:
        raise ConfigError(f"goal: expected (x_m, y_m, theta_rad or None), got {goal!r}")
    gx, gy, gt = goal
    if not (math.isfinite(gx) and math.isfinite(gy)) or (gt is not None and not math.isfinite(gt)):
        raise ConfigError(f"goal: must be finite, got {goal!r}")
    if math.hypot(gx, gy) > CENTRE_RADIUS_M:
        raise ConfigError(f"goal: ({gx:g}, {gy:g}) m is outside the working disc (radius {CENTRE_RADIUS_M} m)")
    for name, v in (("position_tol_m", position_tol_m), ("angle_tol_rad", angle_tol_rad), ("margin", margin),
                    ("start_radius_m", start_radius_m)):
        if not (math.isfinite(v) and v > 0):
            raise ConfigError(f"{name}: must be > 0, got {v!r}")
    if margin < 1.0:
        raise ConfigError(f"margin: must be >= 1, got {margin:g}")
    if not 0.5 <= coverage < 1.0:
        raise ConfigError(f"coverage: expected 0.5 <= coverage < 1, got {coverage!r}")
    oriented = gt is not None and isinstance(part, RigidPart)
    target = np.array([gx, gy])
    settings = PRESETS["fast"].replace(cache=False)
    messages: list[str] = []
    point = part if isinstance(part, PointPart) else PointPart(mu=float(np.mean(part.mu)))
    sink = design_field(FieldSpec.from_request("sink", [gx, gy, gain_per_s]), point, device=device).motion

    # Put the field's actual fixed point on the goal (two corrections of the sink's centre).
    fp = field_fixed_point(sink, part, target)
    first_offset = float(np.hypot(*(fp.position_m - target)))
    for _ in range(2):
        if np.hypot(*(fp.position_m - target)) < 0.02 * position_tol_m:
            break
        shift = target - fp.position_m
        sink = shift_centre(sink, *shift)
        fp = field_fixed_point(sink, part, target)
    if not fp.stable:
        raise LimitError(f"sensorless positioning: the sink's fixed point is not stable (eigenvalues "
                         f"{np.round(fp.eigenvalues, 3)} 1/s)")
    messages.append(f"fixed point {1e3 * first_offset:.3f} mm from the goal as designed, "
                    f"{1e3 * np.hypot(*(fp.position_m - target)):.4f} mm after correction; eigenvalues "
                    + ", ".join(f"{e.real:.3f}" + (f"{e.imag:+.3f}i" if abs(e.imag) > 1e-6 else "")
                                for e in fp.eigenvalues) + " 1/s")
    t_pos, lost = _positioning_time(sink, part, fp.position_m, _starts(start_radius_m, target),
                                    0.5 * position_tol_m, settings)
    if lost:
        messages.append(f"contact lost from {lost} of the sampled starts (the part hops, then lands and follows "
                        f"the field)")
    stages = [Stage("positioning", sink, margin * t_pos,
                    f"sink at ({1e3 * gx:.1f}, {1e3 * gy:.1f}) mm: every start within "
                    f"{0.5e3 * position_tol_m:.2f} mm after {t_pos:.1f} s (x {margin:g})")]
    period = None
    if oriented:
        rigid: RigidPart = part  # type: ignore[assignment]
        away_motion = orient_motion(gx, gy, gt + math.pi / 4, device)
        final_motion = orient_motion(gx, gy, gt, device)
        away = _rate_table(away_motion, rigid, target, settings)
        final = _rate_table(final_motion, rigid, target, settings)
        t_away, t_final = _orienting_times(away, final, gt, 0.5 * angle_tol_rad, coverage)
        if t_away > 0:
            stages.append(Stage("turning away", away_motion, margin * t_away,
                                f"orienting field for {math.degrees(gt + math.pi / 4):.1f} deg: away from the "
                                f"unstable {math.degrees(gt + math.pi / 2):.1f} +- 180 deg"))
        stages.append(Stage("orienting", final_motion, margin * t_final,
                            f"orienting field for {math.degrees(gt):.1f} deg: {100 * coverage:g} % of starting "
                            f"orientations within {0.5 * math.degrees(angle_tol_rad):.1f} deg of it (mod 180) after "
                            f"{t_away + t_final:.1f} s (x {margin:g})"))
        sym = rigid.footprint.symmetry_rad if getattr(rigid, "footprint", None) is not None else 0.0
        half_turn_symmetric = sym > 0 and min(math.pi % sym, sym - math.pi % sym) < 1e-9
        period = sym if half_turn_symmetric else math.pi
        if not half_turn_symmetric:
            messages.append("the part ends at the goal orientation or half a turn from it (the orienting fields "
                            "cannot tell them apart)")
    return SensorlessPlan((gx, gy, gt if oriented else None), stages, fp, period, messages)


class SensorlessTask:
    """Play a :class:`SensorlessPlan` against a clock, with the same ``step`` shape as :class:`Task`.

    ``poses`` are optional and only reported (the plan never reads them): pass the tracker's array
    when a camera happens to watch, or None.
    """

    def __init__(self, plan: SensorlessPlan, chosen: int = 0):
        if not isinstance(plan, SensorlessPlan):
            raise ConfigError(f"plan: expected a SensorlessPlan, got {type(plan).__name__}")
        self.plan, self.chosen = plan, int(chosen)
        self.t0: float | None = None
        self.current: int | None = None
        self.finished: TaskStep | None = None

    def step(self, t_s: float, poses=None) -> TaskStep:
        if self.finished is not None:
            return self.finished
        if self.t0 is None:
            self.t0 = float(t_s)
        elapsed = t_s - self.t0
        dist, ang = math.nan, None
        if poses is not None:
            p = np.asarray(poses, dtype=float).reshape(-1, 3)
            if 0 <= self.chosen < p.shape[0] and np.all(np.isfinite(p[self.chosen, :2])):
                gx, gy, gt = self.plan.goal
                dist = float(math.hypot(p[self.chosen, 0] - gx, p[self.chosen, 1] - gy))
                if gt is not None and math.isfinite(p[self.chosen, 2]):
                    ang = float(_wrap(p[self.chosen, 2] - gt, self.plan.orientation_period_rad or 2 * math.pi))
        seen = "" if math.isnan(dist) else f" (seen {1e3 * dist:.2f} mm" + \
            ("" if ang is None else f", {math.degrees(ang):+.1f} deg") + " from the goal)"
        index = self.plan.stage_at(elapsed)
        if index is None:
            self.finished = TaskStep(None, "done", True, None, dist, ang,
                                     f"done: sensorless plan played in {elapsed:.1f} s{seen}")
            return self.finished
        stage = self.plan.stages[index]
        motion = stage.motion if index != self.current else None
        self.current = index
        left = self.plan.total_s - elapsed
        return TaskStep(motion, stage.name, False, None, dist, ang,
                        f"{stage.name} (sensorless): {left:.1f} s of {self.plan.total_s:.1f} s left{seen}")


__all__ = ["FixedPoint", "SensorlessPlan", "SensorlessTask", "Stage", "field_fixed_point", "plan_sensorless"]

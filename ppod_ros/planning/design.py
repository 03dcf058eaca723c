"""Design of a plate motion whose asymptotic field matches a requested field (FieldSpec).

Unknowns: the phasors of the six plate axes at one frequency (harmonic 1: 12 real numbers less the
time-shift gauge, so 11 inputs) or at two (harmonics 1 and 2: 23 inputs). The objective is the
difference between the asymptotic velocity of the part (ppod_ros.physics.solve_field, point-part
model) and the target over a sample grid on the working disc, plus penalties that keep the motion
inside the device's limits (peak plate acceleration, peak angular acceleration, contact margin
min(g + a_n) over the working disc). scipy.optimize.least_squares (trust region reflective, finite
differences) starts from the linear superposition of basis fields below; the result is checked by
the waveform generator's own GoalPlanner.plan and scaled down until it passes, and until the
feedback's corrections for actuator errors within the plant tolerance pass too (planning/envelope.py).

Basis fields at 30 Hz, mu 0.3 (found with the solver; tests/planning check the signs):
  translation   a_x = A, a_z = Z i             v = (-c A Z, 0)       (c about 3.1e-4 s^3/m)
  line sink     a_x = A, alpha_y = -10 A i     v = (-g x, 0)         (g about 0.31 1/s at A = 10)
  sink          line sinks along x and y, 90 degrees apart (Sink.yaml)
  rotation      alpha_z = W, a_z = Z i          v = w z x r, w < 0 for W, Z > 0
  centre shift  a_z += alpha_y x0 - alpha_x y0 moves the zero of a_n, hence a sink's centre, to r0;
                a_xy += alpha_z (y0, -x0) moves a rotation's centre to r0.
Sources, saddles, shear, centrifuges and whirlpools are the same motions with signs and axes
permuted (docs/planner.md).

R^2 is measured on a 13 x 13 grid over the disc of radius 0.07 m: 1 - SS_res / SS_tot over the
points where the part keeps contact, SS_tot about the mean target; for uniform targets (transport)
SS_tot is taken about zero, i.e. relative to the target's own magnitude.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ppod_ros.errors import ConfigError, LimitError
from ppod_ros.motion import PlateMotion
from ppod_ros.parts import PointPart, RigidPart
from ppod_ros.planning.specs import CENTRE_RADIUS_M, FieldSpec

DEFAULT_FREQUENCY_HZ = 30.0
_SCALE = np.array([10.0, 10.0, 10.0, 100.0, 100.0, 100.0])  # typical m/s^2 and rad/s^2
_FIT_N = 7          # optimisation grid per axis (masked to the disc)
_EVAL_N = 13        # R^2 grid per axis
_GOOD_ENOUGH_R2 = 0.999  # a second harmonic is searched for only below this one-frequency fit


@dataclass
class DesignResult:
    motion: PlateMotion
    spec: FieldSpec
    r2: float
    rms_error_mps: float
    valid_fraction: float
    seconds: float
    messages: list[str] = field(default_factory=list)
    cached: bool = False
    points: np.ndarray | None = field(default=None, repr=False)     # (N, 2) evaluation grid
    target: np.ndarray | None = field(default=None, repr=False)     # (N, 2)
    achieved: np.ndarray | None = field(default=None, repr=False)   # (N, 2), NaN where invalid

    def plot(self, path: str | Path) -> None:
        """Target and achieved fields (quiver) and the residual, as a PNG."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        p, t, a = self.points, self.target, self.achieved
        fig, axes = plt.subplots(1, 2, figsize=(11, 5.2))
        ax = axes[0]
        ax.quiver(p[:, 0], p[:, 1], t[:, 0], t[:, 1], color="0.6", angles="xy", label="target")
        ok = np.isfinite(a[:, 0])
        ax.quiver(p[ok, 0], p[ok, 1], a[ok, 0], a[ok, 1], color="tab:blue", angles="xy", label="achieved")
        ax.plot(p[~ok, 0], p[~ok, 1], "rx", label="contact lost")
        ax.set_title(f"{self.spec.describe()}: R^2 = {self.r2:.4f}", fontsize=9)
        ax.legend(fontsize=7, loc="lower right")
        res = np.linalg.norm(a - t, axis=1)
        sc = axes[1].scatter(p[:, 0], p[:, 1], c=1e3 * res, cmap="magma")
        fig.colorbar(sc, ax=axes[1], label="|achieved - target| (mm/s)")
        axes[1].set_title(f"residual: rms {1e3 * self.rms_error_mps:.2f} mm/s; {self.motion.name}", fontsize=9)
        for ax in axes:
            ax.set_aspect("equal")
            ax.set_xlabel("x (m)")
            ax.set_ylabel("y (m)")
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)


# ---------------------------------------------------------------------------------- basis
def _rot(vx: complex, vy: complex, psi: float) -> tuple[complex, complex]:
    c, s = math.cos(psi), math.sin(psi)
    return c * vx - s * vy, s * vx + c * vy


def initial_phasors(spec: FieldSpec, frequency_hz: float) -> np.ndarray:
    """The linear superposition of basis fields for ``spec``: a (6,) complex phasor row."""
    X = np.zeros(6, dtype=complex)
    p = spec.params
    f_scale = frequency_hz / DEFAULT_FREQUENCY_HZ  # gains fall as 1/f at fixed accelerations
    if spec.kind == "transport":
        speed = math.hypot(p[0], p[1])
        if speed > 0:
            A = min(25.0, 10.0 * math.sqrt(speed * f_scale / 0.0153))
            X[0], X[1] = -A * p[0] / speed, -A * p[1] / speed
            X[2] = 5.0j
        return X
    x0, y0 = spec.centre
    if spec.kind == "orient":
        return orient_phasors(x0, y0, p[2])
    if spec.kind in ("sink", "line_sink"):
        gain = p[2] if spec.kind == "sink" else p[3]
        A = 10.0 * math.sqrt(gain * f_scale / 0.31)
        A = min(A, 8.0 / (10.0 * (0.08 + math.hypot(x0, y0))), 20.0)  # contact margin budget
        if spec.kind == "sink":
            X[0], X[4] = A, -10j * A           # line sink towards x = x0
            X[1], X[3] = 1j * A, -10 * A       # line sink towards y = y0, 90 degrees later
        else:
            # A line sink with its normal n at psi: gathers on the line through r0 along psi + pi/2.
            psi = p[2] - math.pi / 2
            X[0], X[1] = _rot(A, 0.0, psi)
            X[3], X[4] = _rot(0.0, -10j * A, psi)
    else:  # rotation
        W = -150.0 * p[2] / 0.1665 * f_scale
        W = max(-300.0, min(300.0, W))
        X[5], X[2] = W, 5.0j
        X[0], X[1] = W * y0, -W * x0
    X[2] += X[4] * x0 - X[3] * y0
    return X


def orient_phasors(x0: float, y0: float, theta: float) -> np.ndarray:
    """The orienting motion at ORIENT_FREQUENCY_HZ: PHYSICS.md's u1 (a_x 20, alpha_y 100 at -90
    degrees, under which the rigid part has stable orientations 0 and pi) rotated by ``theta`` about
    z and shifted so that its line sink passes through (x0, y0); scaled to keep the contact margin."""
    s = min(1.0, 8.0 / (100.0 * (0.08 + math.hypot(x0, y0))))
    X = np.zeros(6, dtype=complex)
    X[0], X[1] = _rot(20.0 * s, 0.0, theta)
    X[3], X[4] = _rot(0.0, -100j * s, theta)
    X[2] = X[4] * x0 - X[3] * y0
    return X


def shift_centre(motion: PlateMotion, dx_m: float, dy_m: float) -> PlateMotion:
    """Move the zero of a_n (a sink's or line sink's centre) by (dx, dy): a_z += alpha_y dx - alpha_x dy
    per harmonic (exact for the normal acceleration; the in-plane terms are unchanged)."""
    X = motion.phasors().copy()
    X[:, 2] += X[:, 4] * dx_m - X[:, 3] * dy_m
    return PlateMotion.from_phasors(motion.frequency_hz, motion.k, X, name=motion.name,
                                    ramp_time_s=motion.ramp_time_s)


ORIENT_FREQUENCY_HZ = 20.0


# ---------------------------------------------------------------------------------- parametrisation
def _pack(table: np.ndarray) -> np.ndarray:
    """(H, 6) phasors -> (real vector, gauge axis): harmonic 1's largest axis is made real."""
    ref = int(np.argmax(np.abs(table[0]) / _SCALE))
    table = table * np.exp(-1j * np.angle(table[0, ref])) ** np.arange(1, table.shape[0] + 1)[:, None]
    z = (table / _SCALE).reshape(-1)
    v = np.concatenate([z.real, z.imag])
    return np.delete(v, z.size + ref), ref


def _unpack(v: np.ndarray, harmonics: int, ref: int) -> np.ndarray:
    n = 6 * harmonics
    full = np.insert(v, n + ref, 0.0)
    return ((full[:n] + 1j * full[n:]).reshape(harmonics, 6)) * _SCALE


def _motion(table: np.ndarray, frequency_hz: float, name: str) -> PlateMotion:
    k = np.arange(1, table.shape[0] + 1)
    return PlateMotion.from_phasors(frequency_hz, k, table, name=name)


def _disc_points(n: int, radius: float = CENTRE_RADIUS_M) -> np.ndarray:
    xs = np.linspace(-radius, radius, n)
    X, Y = np.meshgrid(xs, xs)
    keep = np.hypot(X, Y) <= radius + 1e-12
    return np.column_stack([X[keep], Y[keep]])


# ---------------------------------------------------------------------------------- design
_CACHE: dict[tuple, DesignResult] = {}


def design_field(spec: FieldSpec, part: PointPart | RigidPart | None = None, *, frequency_hz: float | None = None,
                 harmonics: int = 1, device=None, settings=None, max_evaluations: int = 120) -> DesignResult:
    """Design the plate motion for ``spec`` (see the module docstring). Cached; LimitError when no
    motion within the device's limits can be found."""
    from scipy.optimize import least_squares

    from ppod_ros.actuation.planning import contact_margin, plate_peaks
    from ppod_ros.device import default_device_config
    from ppod_ros.physics import PRESETS, solve_fields

    if not isinstance(spec, FieldSpec):
        raise ConfigError(f"spec: expected a FieldSpec, got {type(spec).__name__}")
    if harmonics not in (1, 2):
        raise ConfigError(f"harmonics: expected 1 or 2, got {harmonics!r}")
    freq = DEFAULT_FREQUENCY_HZ if frequency_hz is None else float(frequency_hz)
    if not (math.isfinite(freq) and 5.0 <= freq <= 200.0):
        raise ConfigError(f"frequency_hz: expected 5..200 Hz, got {frequency_hz!r}")
    messages: list[str] = []
    if part is None:
        part = PointPart(mu=0.3)
    if isinstance(part, RigidPart):
        point = PointPart(mu=float(np.mean(part.mu)))
        messages.append(f"rigid part: fitted with the point-part model at mu {point.mu:g}")
    else:
        point = PointPart(mu=part.mu, mu_static=part.mu_static)
    device = device or default_device_config()
    lim = device.limits
    key = (spec.key(), point.key, round(freq, 6), harmonics, repr(lim))
    if key in _CACHE:
        hit = _CACHE[key]
        return DesignResult(hit.motion, hit.spec, hit.r2, hit.rms_error_mps, hit.valid_fraction, hit.seconds,
                            list(hit.messages), True, hit.points, hit.target, hit.achieved)

    t0 = time.perf_counter()
    name = f"{spec.kind}({', '.join(f'{v:.3g}' for v in spec.params)})"
    if spec.kind == "orient":
        freq = ORIENT_FREQUENCY_HZ
        messages.append(f"orient: the rotated u1 motion at {freq:g} Hz (stable orientations theta and theta + pi)")
        result = _within_limits(_motion(orient_phasors(*spec.params)[None], freq, name), spec, point, device,
                                messages)
        result.seconds = time.perf_counter() - t0
        _CACHE[key] = result
        return result
    settings = settings or PRESETS["fast"].replace(cache=False)
    fit_pts = _disc_points(_FIT_N)
    target = spec.target_velocity(fit_pts[:, 0], fit_pts[:, 1])
    v_scale = max(float(np.sqrt(np.mean(np.sum(target ** 2, axis=1)))), 1e-4)
    table0 = np.zeros((harmonics, 6), dtype=complex)
    base = None
    if harmonics == 1:
        table0[0] = initial_phasors(spec, freq)
    else:
        # Continuation: the second harmonic refines the one-frequency optimum (cached), so the
        # 23-input search starts where the 11-input one ended, not from the basis superposition.
        base = design_field(spec, part, frequency_hz=freq, harmonics=1, device=device, settings=settings,
                            max_evaluations=max_evaluations)
        if base.r2 >= _GOOD_ENOUGH_R2:
            table0[0] = base.motion.phasor_table(1)[0]
            result = evaluate(_motion(table0, freq, name), spec, point)
            result.messages = messages + base.messages + [
                f"second harmonic: not needed (one frequency reaches R^2 {base.r2:.4f}); harmonic 2 at zero"]
            result.seconds = time.perf_counter() - t0
            _CACHE[key] = result
            return result
        table0[0] = base.motion.phasor_table(1)[0]
        # From a good start a few steps do it; least_squares counts steps, not the 23 evaluations
        # of each finite-difference Jacobian (the cost: about 0.15 s per step here).
        max_evaluations = min(max_evaluations, 5)
    x0, ref = _pack(table0)

    coil_map = _coil_map(device, freq, harmonics)
    rms_limit = 0.9 * _RMS_PER_TEMPERATURE * lim.coil_temperature_c

    def residuals(vs: list[np.ndarray]) -> list[np.ndarray]:
        """The residual vector of each parameter vector in ``vs``: one solve_fields call for all."""
        tables = [_unpack(v, harmonics, ref) for v in vs]
        motions = [_motion(table, freq, name) for table in tables]
        # Cold starts, as solve_field: a warm start from the evaluation point changes the number of
        # periods (so each value within the tolerance) unevenly between neighbours and was seen to
        # spoil the finite differences (rotation R^2 0.993 -> 0.956).
        fields = solve_fields(motions, point, fit_pts, settings, warm=False)
        out = []
        for i, (v, table, m) in enumerate(zip(vs, tables, motions)):
            valid = fields.valid[i]
            currents = np.einsum("hcj,hj->hc", coil_map, table)  # (H, 6 coils) complex amperes
            rms = np.sqrt(np.sum(np.abs(currents) ** 2, axis=0) / 2.0)
            vel = np.where(valid[:, None], np.nan_to_num(fields.velocity[i, :, :2]), 0.0)
            res = (vel - target) / v_scale
            res[~valid] *= 2.0  # contact lost: worse than standing still
            acc, ang = plate_peaks(m)
            margin = contact_margin(m, lim.working_radius_m)
            pen = [max(0.0, acc - 0.95 * lim.plate_accel_mps2),
                   max(0.0, (ang - 0.95 * lim.plate_angular_accel_radps2) / 10.0),
                   max(0.0, 1.5 * lim.contact_margin_mps2 - margin),
                   max(0.0, float(rms.max()) - rms_limit),
                   max(0.0, float(np.abs(currents).sum(axis=0).max()) - 0.9 * lim.coil_current_a)]
            # A light pull towards the basis superposition keeps the design in the regime the basis
            # came from (moderate in-plane amplitudes), where plant errors distort the field least.
            out.append(np.concatenate([res.reshape(-1), 10.0 * np.array(pen), 0.02 * (v - x0)]))
        return out

    def residual(v: np.ndarray) -> np.ndarray:
        return residuals([v])[0]

    def batched(_fun, points) -> list[np.ndarray]:
        # least_squares' ``workers``: every point of a finite-difference Jacobian (the same points
        # and differences as scipy's own '2-point' scheme) evaluated in one solve_fields call.
        return residuals([np.asarray(x, dtype=float) for x in points])

    sol = least_squares(residual, x0, method="trf", x_scale=1.0, diff_step=1e-3, max_nfev=max_evaluations,
                        xtol=1e-6, ftol=1e-6, workers=batched)
    result = _within_limits(_motion(_unpack(sol.x, harmonics, ref), freq, name), spec, point, device, messages)
    if base is not None:
        h2 = float(np.max(np.abs(result.motion.phasor_table(2)[1]) / _SCALE))
        result.messages.append(f"second harmonic: R^2 {base.r2:.4f} -> {result.r2:.4f} "
                               f"(largest harmonic-2 axis {h2:.2f} of its typical scale)")
        if result.r2 < base.r2:  # the refinement never makes the design worse
            table = np.zeros((2, 6), dtype=complex)
            table[0] = base.motion.phasor_table(1)[0]
            result = evaluate(_motion(table, freq, name), spec, point)
            result.messages = messages + [f"second harmonic: no improvement on R^2 {base.r2:.4f}; the "
                                          f"one-frequency design is returned (harmonic 2 at zero)"]
    result.seconds = time.perf_counter() - t0
    _CACHE[key] = result
    return result


#: The thermal limit as an rms current: device.yaml's 110 degC is "about 3 A rms" (docs/device.md);
#: a proxy for the optimiser only: GoalPlanner.plan has the last word.
_RMS_PER_TEMPERATURE = 3.0 / 110.0


def _coil_map(device, frequency_hz: float, harmonics: int) -> np.ndarray:
    """(H, 6 coils, 6 axes) complex: the nominal plant's feed-forward currents per unit axis phasor
    (linear in the motion), so the optimiser can keep currents in bounds without planning."""
    from ppod_ros.actuation.planning import GoalPlanner

    planner = GoalPlanner(device)
    out = np.zeros((harmonics, 6, 6), dtype=complex)
    for h in range(1, harmonics + 1):
        for j in range(6):
            X = np.zeros((h, 6), dtype=complex)
            X[h - 1, j] = _SCALE[j] * 0.01
            m = PlateMotion.from_phasors(frequency_hz, np.arange(1, h + 1), X)
            kt = max(h, 1)
            out[h - 1, :, j] = planner.plant.feedforward(m, max(kt, device.limits.max_harmonic))[h - 1] \
                / (_SCALE[j] * 0.01)
    return out


def _within_limits(motion: PlateMotion, spec: FieldSpec, point: PointPart, device, messages: list[str]
                   ) -> DesignResult:
    """Scale ``motion`` down (3 % steps) until the generator's GoalPlanner accepts it; evaluate it."""
    from ppod_ros.actuation.planning import GoalPlanner

    planner = GoalPlanner(device)
    scale, first = 1.0, None
    for _attempt in range(40):
        try:
            planner.plan(motion.scaled(scale) if scale != 1.0 else motion)
            break
        except LimitError as exc:
            first = first or str(exc)
            scale *= 0.97
    else:
        planner.plan(motion.scaled(scale))  # raises the LimitError that names the limit
    if scale != 1.0:
        messages.append(f"scaled by {scale:.3f} to stay within the limits ({first})")
        motion = motion.scaled(scale)
    # Room for the feedback: the corrected tables of plants within the actuator tolerance must pass
    # the checker too, or the generator scales the corrections back and the plate keeps its error
    # (planning/envelope.py). Ratios are linear in amplitude: one scale fits.
    from ppod_ros.planning.envelope import PlantTolerance, corrected_motion_ratios

    ratios = corrected_motion_ratios(motion, device, PlantTolerance())
    name, worst = max(ratios.items(), key=lambda kv: kv[1])
    if worst > 1.0:
        motion = motion.scaled(1.0 / worst)
        messages.append(f"scaled by {1.0 / worst:.3f} so that its corrections for actuator errors within the "
                        f"plant tolerance stay within {name}")
    result = evaluate(motion, spec, point)
    result.messages = messages + result.messages
    return result


def evaluate(motion: PlateMotion, spec: FieldSpec, part: PointPart, n: int = _EVAL_N) -> DesignResult:
    """R^2, RMS error and valid fraction of ``motion``'s field against ``spec`` on the disc grid."""
    from ppod_ros.physics import PRESETS, solve_field

    pts = _disc_points(n)
    target = spec.target_velocity(pts[:, 0], pts[:, 1])
    r = solve_field(motion, part, pts, PRESETS["default"].replace(cache=False))
    ach = np.where(r.valid[:, None], r.velocity[:, :2], np.nan)
    ok = r.valid
    messages = []
    if not ok.any():
        return DesignResult(motion, spec, -math.inf, math.inf, 0.0, 0.0, ["contact lost everywhere"], False,
                            pts, target, ach)
    err = ach[ok] - target[ok]
    ss_res = float(np.sum(err ** 2))
    centre = target[ok].mean(axis=0) if spec.kind != "transport" else np.zeros(2)
    ss_tot = float(np.sum((target[ok] - centre) ** 2))
    r2 = 1.0 - ss_res / ss_tot if ss_tot > 0 else (1.0 if ss_res == 0 else -math.inf)
    if not ok.all():
        messages.append(f"contact lost at {int((~ok).sum())} of {ok.size} sample points")
    return DesignResult(motion, spec, r2, float(np.sqrt(ss_res / ok.sum())), float(ok.mean()), 0.0, messages,
                        False, pts, target, ach)


__all__ = ["DEFAULT_FREQUENCY_HZ", "ORIENT_FREQUENCY_HZ", "DesignResult", "design_field", "evaluate",
           "initial_phasors", "orient_phasors", "shift_centre"]

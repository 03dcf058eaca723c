"""The solver on the motions a planner actually produces (``ppod bench solver --planner-motions``).

The suite (``--suite``) times hand-made motions on a grid. The model-predictive planner asks
something else: a few configurations (its parts' poses) under many motions (templates moved to
the goals, their envelope fits, the Gauss-Newton probes), for point and rigid parts. This section
runs the planner closed loop on the multipart benchmark's scenes (``benchmarks/planner.py``), records
every solver call it makes, samples motions per part kind and motion class, and for each sample
measures, on the same configurations:

- this solver with the planner's settings (``PLANNER_SOLVER``) and the ``fast``, ``default`` and
  ``accurate`` presets: time per configuration (best of ``--repeat``, no warm starts, no cache) and the rows the
  planner's caps give up on;
- the error against a reference: point parts the independent fixed-step reference
  (``fixed_step_reference``, 25,600 steps per period); rigid parts the ``reference`` preset
  (DOP853 at 1e-11: no independent rigid reference exists);
- a lean ``scipy.integrate.solve_ivp`` baseline written from PHYSICS.md alone: point parts the
  suite's (``solver.baseline_average``), rigid parts :func:`rigid_baseline_average` (RK45, the 6 x 6
  contact system solved per evaluation, the regularised Coulomb law at the solver's velocity scale);
  the ratio is the baseline's time over the cheapest of this solver's settings with an error no
  larger than the baseline's, over the same configurations.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

#: The classes a planner motion falls in (``motion.name`` up to "@"); "mpc": the Gauss-Newton
#: probes and their results; "design": the template designs the planner makes once (named by their
#: field spec, e.g. "sink(0, 0, 0.3)").
PLANNER_CLASSES = ("sink", "carry", "turn", "spin", "orient", "line", "mpc", "design")


def motion_class(name: str) -> str:
    """The class of a planner motion by its name: "sink@0" -> "sink", "turn-@1" -> "turn"."""
    base = (name or "mpc").split("@")[0].rstrip("+-")
    return base if base in PLANNER_CLASSES else "design"


def rigid_baseline_average(motion, part, config, budget_s: float = float("inf"), rtol: float = 1e-8,
                           atol: float = 1e-11, tol: float = 1e-8, max_periods: int = 200, eps: float = 1e-6):
    """The lean solve_ivp baseline for a rigid part at one configuration (PHYSICS.md, "Rigid part
    with three point contacts"), sharing no code with ``ppod_ros.physics``.

    Returns (period-average twist (3,), periods, finished); NaN when a contact lifts off.
    The state is the twist (Vx, Vy, theta'); per evaluation the 6 x 6 system in (Ax, Ay, theta'',
    N1, N2, N3) is solved with f_i = -mu_i N_i u_i / max(|u_i|, eps).
    """
    from scipy.integrate import solve_ivp

    from ppod_bench.solver import _OutOfTimeError

    sx, sy, th = (float(c) for c in config)
    T = motion.period_s
    w = motion.omega * np.asarray(motion.k, float)                         # (K,)
    amp, ph = np.asarray(motion.amplitude, float), np.asarray(motion.phase, float)  # (K, 6)
    c, s = math.cos(th), math.sin(th)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    rho = (R @ np.asarray(part.contacts, float).T).T                      # (3, 3): [rho_x, rho_y, -h]
    h = -float(rho[0, 2])
    px, py = sx + rho[:, 0], sy + rho[:, 1]
    Iw = R @ np.asarray(part.inertia, float) @ R.T
    mu = np.broadcast_to(np.asarray(part.mu, float), (3,))
    m = float(part.mass)
    deadline = time.perf_counter() + budget_s
    lifted = [False]

    def plate(t):
        arg = np.outer(np.ones(6), w).T * t + ph                         # (K, 6)
        u = (amp * np.sin(arg)).sum(axis=0)                              # accelerations
        v = (-(amp / w[:, None]) * np.cos(arg)).sum(axis=0)              # zero-mean velocities
        return u, v

    def rhs(t, y):
        if time.perf_counter() > deadline:
            raise _OutOfTimeError
        u, v = plate(t)
        vx, vy, wz = y
        # Sliding velocity of each contact relative to the plate (PHYSICS.md).
        ux = vx - h * v[4] - wz * rho[:, 1] - (v[0] - v[5] * py)
        uy = vy + h * v[3] + wz * rho[:, 0] - (v[1] + v[5] * px)
        nrm = np.maximum(np.hypot(ux, uy), eps)
        ex, ey = ux / nrm, uy / nrm
        A = np.zeros((6, 6))
        b = np.zeros(6)
        A[0, 0] = A[1, 1] = m
        A[0, 3:] = mu * ex
        A[1, 3:] = mu * ey
        A[2, 3:] = 1.0
        b[2] = m * (9.81 + u[2] + u[3] * sy - u[4] * sx)
        # I_w (ax, ay, theta'') = sum rho_i x F_i, F_i = N_i (-mu ex, -mu ey, 1).
        A[3:, 2] = Iw[:, 2]
        A[3, 3:] = -(rho[:, 1] - h * mu * ey)
        A[4, 3:] = -(h * mu * ex - rho[:, 0])
        A[5, 3:] = -mu * (rho[:, 1] * ex - rho[:, 0] * ey)
        b[3:] = -(Iw[:, 0] * u[3] + Iw[:, 1] * u[4])
        z = np.linalg.solve(A, b)
        if np.any(z[3:] <= 0.0):
            lifted[0] = True
        return z[:3]

    y = np.zeros(3)
    last = np.full(3, np.nan)
    for p in range(max_periods):
        try:
            sol = solve_ivp(rhs, (p * T, (p + 1) * T), y, method="RK45", rtol=rtol, atol=atol, dense_output=True)
        except _OutOfTimeError:
            return last, p, False
        if lifted[0]:
            return np.full(3, np.nan), p + 1, True
        y = sol.y[:, -1]
        tt = np.linspace(p * T, (p + 1) * T, 401)
        avg = np.trapezoid(sol.sol(tt), tt, axis=1) / T
        if np.isfinite(last).all() and np.abs(avg - last).max() < tol:
            return avg, p + 1, True
        last = avg
    return last, max_periods, True


def collect_planner_calls(counts, scenes: int, seconds: float, seed: int = 0) -> list[tuple]:
    """Run the model-predictive planner closed loop on the multipart benchmark's first ``scenes``
    scenes per count for ``seconds`` of device time; return every solver call it made as
    (motions, part, configs)."""
    import ppod_ros.physics as physics
    from ppod_bench import planner as bp
    from ppod_ros.planning.mpc import MultiTask, PartGoal
    from ppod_ros.planning.simulate import ActuatorPlantError, run_on_dynamics
    from ppod_sim.scene import ScenePart

    templates, models = bp.multipart_models()
    calls = []
    real = physics.solve_fields

    def recording(motions, part, configs, *a, **kw):
        calls.append((list(motions), part, np.array(configs, float)))
        return real(motions, part, configs, *a, **kw)

    physics.solve_fields = recording
    try:
        for count in counts:
            rng = np.random.default_rng(1000 * seed + count)
            for n in range(scenes):
                sc = bp._multi_scene(count, rng, templates)
                labels = sc["labels"]
                true_parts = [bp._true_part(templates[lb].part, mu) for lb, mu in zip(labels, sc["mu"])]
                goals = [PartGoal(i, g[0], g[1], sc["goal_theta"] if lb == "bracket" else None, 2e-3,
                                  math.radians(3)) for i, (lb, g) in enumerate(zip(labels, sc["goals"]))]
                task = MultiTask([models[lb] for lb in labels], goals, timeout_s=seconds)
                before = len(calls)
                run_on_dynamics(task, true_parts, sc["starts"], horizon_s=seconds, ramp_s=0.5, latency_s=0.1,
                                plant=ActuatorPlantError.random(np.random.default_rng(sc["plant_seed"])),
                                separate=bp._separation([ScenePart(lb, tp, templates[lb].height_m, np.array(st))
                                                         for lb, tp, st in zip(labels, true_parts, sc["starts"])]),
                                seed=sc["plant_seed"] % 1000)
                print(f"  {count} part(s), scene {n}: {len(calls) - before} solver calls recorded", flush=True)
    finally:
        physics.solve_fields = real
    return calls


def sample_calls(calls, per_kind: int, seed: int) -> list[tuple]:
    """Up to ``per_kind`` (motion, part, configs) samples per part kind (point, rigid), spread over
    the motion classes (round robin over the classes, random within one), unique by motion and part."""
    from ppod_ros.parts import RigidPart

    pools: dict = defaultdict(lambda: defaultdict(dict))
    for motions, part, cfg in calls:
        kind = "rigid" if isinstance(part, RigidPart) else "point"
        for mo in motions:
            if not mo.is_zero():
                pools[kind][motion_class(mo.name)].setdefault((mo.key, repr(part.key)), (mo, part, cfg))
    rng = np.random.default_rng(seed)
    out = []
    for kind in ("point", "rigid"):
        classes = {k: [v[i] for i in rng.permutation(len(v))] for k, v in
                   ((k, list(d.values())) for k, d in sorted(pools[kind].items()))}
        picked = 0
        while picked < per_kind and any(classes.values()):
            for k in list(classes):
                if classes[k] and picked < per_kind:
                    out.append((kind, k, *classes[k].pop()))
                    picked += 1
    return out


def _ours(motion, part, cfg, settings, repeat: int):
    from ppod_ros.physics import solve_fields

    best, r = math.inf, None
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        r = solve_fields([motion], part, cfg, settings=settings.replace(cache=False), warm=False)
        best = min(best, time.perf_counter() - t0)
    return best, np.asarray(r.velocity, float)[0], np.asarray(r.valid, bool)[0], r


def evaluate(samples, repeat: int, budget_s: float, out: Path) -> list[dict]:
    """Per sample: our settings' times and errors, the reference, the baseline (see the module)."""
    from ppod_bench.fixed_step_reference import reference_average
    from ppod_bench.solver import baseline_average
    from ppod_ros.physics import PRESETS
    from ppod_ros.planning.predict import PLANNER_SOLVER

    ours = {"planner": PLANNER_SOLVER, "fast": PRESETS["fast"].replace(threads=1),
            "default": PRESETS["default"].replace(threads=1), "accurate": PRESETS["accurate"].replace(threads=1)}
    rows = []
    for i, (kind, cls, motion, part, cfg) in enumerate(samples):
        row = {"kind": kind, "class": cls, "name": motion.name, "configs": int(len(cfg)), "ours": {}}
        res = {lb: _ours(motion, part, cfg, st, repeat) for lb, st in ours.items()}
        if kind == "point":
            ref = np.full((len(cfg), 2), np.nan)
            for j, (x, y) in enumerate(cfg[:, :2]):
                if res["default"][2][j]:
                    ref[j], _ = reference_average(motion, float(part.mu), x, y)
        else:
            _, ref, ok, _ = _ours(motion, part, cfg, PRESETS["reference"], 1)
            ref = np.where(ok[:, None], ref, np.nan)
        valid = np.all(np.isfinite(ref), axis=1)
        for lb, (t, v, ok, r) in res.items():
            d = np.abs(v - ref)[valid & ok]
            reasons = [str(x) for x in np.asarray(r.reason, object)[0]] if hasattr(r, "reason") else []
            row["ours"][lb] = {"seconds": t, "ms_per_config": 1e3 * t / max(1, len(cfg)),
                               "err_mps": float(d[:, :2].max()) if d.size else 0.0,
                               "err_radps": float(d[:, 2].max()) if d.size and d.shape[1] == 3 else None,
                               "invalid_where_reference_valid": int((valid & ~ok).sum()),
                               "given_up": sum("not converged" in x for x in reasons)}
        tb = time.perf_counter()
        if kind == "point":
            runs = [baseline_average(motion, float(part.mu), x, y, budget_s) for x, y in cfg[valid, :2]]
        else:
            runs = [rigid_baseline_average(motion, part, q, budget_s) for q in cfg[valid]]
        t_base = time.perf_counter() - tb
        bv = np.array([r_[0] for r_ in runs]).reshape(-1, ref.shape[1])
        d = np.abs(bv - ref[valid])
        e_base = float(np.nanmax(d[:, :2])) if np.isfinite(d).any() else math.inf
        capped = sum(not r_[2] for r_ in runs)
        row["baseline"] = {"seconds": t_base, "configs": int(valid.sum()), "capped": capped, "err_mps": e_base}
        cheapest = [(res[lb][0], lb) for lb in ours if row["ours"][lb]["err_mps"] <= e_base
                    and row["ours"][lb]["invalid_where_reference_valid"] == 0]
        row["ratio"] = (t_base / min(cheapest)[0], min(cheapest)[1]) if cheapest and valid.any() else None
        rows.append(row)
        o = row["ours"]
        ratio = "-" if row["ratio"] is None else f"{'>=' if capped else ''}{row['ratio'][0]:.0f}x ({row['ratio'][1]})"
        print(f"  [{i + 1}/{len(samples)}] {kind:5s} {cls:6s} {motion.name:10s} {len(cfg)} configs: planner "
              f"{o['planner']['ms_per_config']:.2f} ms/config err {o['planner']['err_mps']:.1e}, default "
              f"{o['default']['ms_per_config']:.2f} ms err {o['default']['err_mps']:.1e}; baseline "
              f"{t_base / max(1, valid.sum()):.2f} s/config err {e_base:.1e}{f' ({capped} capped)' if capped else ''};"
              f" ratio {ratio}", flush=True)
    return rows


def summary_rows(rows: list[dict]) -> list[list]:
    """One table row per (part kind, motion class) and per part kind in all."""
    groups = defaultdict(list)
    for r in rows:
        groups[(r["kind"], r["class"])].append(r)
        groups[(r["kind"], "all")].append(r)
    table = []
    for (kind, cls), rs in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1] == "all", kv[0][1])):
        n_cfg = sum(r["configs"] for r in rs)
        line = [kind, cls, len(rs), n_cfg]
        for lb in ("planner", "default", "accurate"):
            t = sum(r["ours"][lb]["seconds"] for r in rs)
            e = max(r["ours"][lb]["err_mps"] for r in rs)
            line += [f"{1e3 * t / n_cfg:.2f}", f"{e:.1e}"]
        line.append(sum(r["ours"]["planner"]["given_up"] for r in rs))
        b_cfg = sum(r["baseline"]["configs"] for r in rs)
        capped = sum(r["baseline"]["capped"] for r in rs)
        t_b = sum(r["baseline"]["seconds"] for r in rs)
        line += [f"{t_b / max(1, b_cfg):.2f}" + (f" ({capped} capped)" if capped else ""),
                 f"{max(r['baseline']['err_mps'] for r in rs):.1e}"]
        ratios = [r["ratio"][0] for r in rs if r["ratio"] is not None]
        line.append(f"{'>=' if capped else ''}{min(ratios):.0f} / {np.median(ratios):.0f}" if ratios else "-")
        line.append(len(rs) - len(ratios))
        table.append(line)
    return table


def run_planner_motions(args, out: Path) -> int:
    from ppod_bench.solver import _table
    from ppod_ros.physics._params import ensure_compiled

    ensure_compiled()
    load = os.getloadavg()
    print(f"load average before: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}", flush=True)
    print(f"recording the planner's solver calls ({args.planner_scenes} scene(s) per count, counts 1 and 3, "
          f"{args.planner_seconds:g} s of device time each):", flush=True)
    calls = collect_planner_calls((1, 3), args.planner_scenes, args.planner_seconds, seed=0)
    n_motions = sum(len(m) for m, _, _ in calls)
    print(f"{len(calls)} calls, {n_motions} motion evaluations; sampling {args.planner_samples} per part kind",
          flush=True)
    samples = sample_calls(calls, args.planner_samples, args.seed)
    rows = evaluate(samples, args.repeat, args.baseline_budget, out)
    text = _table("the solver on the planner's own motions (no warm starts, no cache; error against the "
                  "fixed-step reference for point parts, the reference preset for rigid ones)",
                  ["part", "class", "motions", "configs", "planner ms/config", "planner max err m/s",
                   "default ms/config", "default max err m/s", "accurate ms/config", "accurate max err m/s",
                   "planner gave up", "baseline s/config",
                   "baseline max err", "ratio min / median (same configs, equal error)",
                   "no setting at <= baseline err"], summary_rows(rows))
    (out / "solver_planner_motions.txt").write_text(text + "\n", encoding="utf-8")
    if args.json:
        payload = {"load_average": list(load), "calls": len(calls), "motion_evaluations": n_motions, "samples": rows}
        Path(args.json).write_text(json.dumps(payload, indent=1, default=str) + "\n", encoding="utf-8")
    return 0


__all__ = ["PLANNER_CLASSES", "collect_planner_calls", "evaluate", "motion_class", "rigid_baseline_average",
           "run_planner_motions", "sample_calls", "summary_rows"]

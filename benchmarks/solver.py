"""Accuracy versus time of the asymptotic solver, against a converged reference and a plain
scipy.integrate.solve_ivp baseline; what the skipping saves; full-dynamics speed.

Point parts (mu 0.3) on a 51 x 51 grid over [-0.1, 0.1]^2 m for every suite motion of
config/motions; the PHYSICS.md rigid part on 7 x 7 x 7 configurations under RigidU1. The reference
is the solver's "reference" preset (8th-order Dormand-Prince, step tolerance 1e-12, the closed form
where a_h is collinear), cached under --out keyed by its settings, motion, part and grid; --suite
judges the extended suite against an independent fixed-step reference instead
(fixed_step_reference.py, 25,600 steps per period). The baseline is a lean solve_ivp user code
(RK45, rtol 1e-9, atol 1e-12; the plate's coefficients precomputed, numpy only in the right-hand
side) on s' = -mu n w/|w|, period after period until the period average changes by less than
1e-8 m/s or 200 periods, on a fixed random subset of valid configurations; ratios compare the same
configurations at equal or better error. --stalls measures the per-call latency of small calls
with a bounded busy loop on the other core. --design times one-frequency field designs (line sink
and rotation) at the given sample grids: wall and CPU seconds, solver calls, configurations solved
and mean periods per configuration. --separation times the simulator's part separation per cycle
(cell list against the all-pairs reference, which must agree bit for bit). --startup times
`ppod field config/motions/Sink.yaml --json OUT --quiet` in fresh processes, interleaved with the
JIT kernel (PPOD_AOT=0), and checks that both write the same field. --planner-motions records the
motions the model-predictive planner evaluates in closed loop (the multipart scenes) and measures
the solver on samples of them (the planner's settings, fast, default) against the reference and
the solve_ivp baseline, point and rigid parts (benchmarks/solver_planner.py).

examples:
  ppod bench solver --quick
  ppod bench solver --stalls
  ppod bench solver --suite --json out/bench/suite.json
  ppod bench solver --design 7 15
  ppod bench solver --separation
  ppod bench solver --startup --startup-runs 9
  ppod bench solver --planner-motions --planner-scenes 1 --planner-samples 4 --baseline-budget 2
  ppod bench solver --out out/bench
  ppod bench solver --baseline-configs 10 --motions Sink LineSinkX
"""

from __future__ import annotations

import argparse
import hashlib
import math
import time
from pathlib import Path

import numpy as np

HELP = "asymptotic solver: Pareto table vs a converged reference, solve_ivp baseline, skipping, dynamics"

CONFIG = Path(__file__).resolve().parents[1] / "config"
POINT_MOTIONS = ["TranslateX", "RotateZ", "LineSinkX", "TwoHarmonicX", "Sink", "Whirlpool", "Swirl3H",
                 "NearContactLoss", "StickingHeavy"]
#: The extended suite: the motions above plus nearly-collinear, 2-D sticking and plant-corrected ones.
SUITE_MOTIONS = POINT_MOTIONS + ["LineSinkXNear", "Stick2D", "LineSinkXPlant", "SinkPlant"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quick", action="store_true",
                        help="short run: 21 x 21 and 5 x 5 x 5 grids, 3 motions, 5 baseline configurations")
    parser.add_argument("--grid", type=int, default=51, help="point grid size per axis (default 51)")
    parser.add_argument("--rigid-grid", type=int, default=7, help="rigid grid size per axis (default 7)")
    parser.add_argument("--baseline-configs", type=int, default=25, help="configurations per motion for solve_ivp")
    parser.add_argument("--motions", nargs="+", metavar="NAME", help=f"point motions (default: {POINT_MOTIONS})")
    parser.add_argument("--baseline-budget", type=float, default=10.0, metavar="S",
                        help="wall-time budget per baseline configuration (s; default 10): sticking makes "
                             "RK45 chatter, and a capped run gives a lower bound on the ratio")
    parser.add_argument("--repeat", type=int, default=3, help="timed repetitions, best kept (default 3)")
    parser.add_argument("--seed", type=int, default=2024, help="seed of the baseline subset")
    parser.add_argument("--stalls", action="store_true",
                        help="only the per-call latency section (busy loop on the other core, p50/p90)")
    parser.add_argument("--stall-calls", type=int, default=200, metavar="N",
                        help="timed calls per case in the latency section (default 200)")
    parser.add_argument("--suite", action="store_true",
                        help="only the extended suite: time per motion on the grid, periods per configuration, "
                             "error against the independent fixed-step reference")
    parser.add_argument("--reference-configs", type=int, default=12, metavar="N",
                        help="configurations per motion checked against the fixed-step reference (default 12)")
    parser.add_argument("--json", metavar="OUT", help="with --suite or --planner-motions: also write the figures "
                                                      "as JSON")
    parser.add_argument("--design", type=int, nargs="+", metavar="N",
                        help="only the design section: line sink and rotation designs on N x N sample grids "
                             "(the design's default is 7)")
    parser.add_argument("--separation", action="store_true",
                        help="only the part-separation section: time per cycle of the simulator's cell list "
                             "and of the all-pairs reference, 2 mm disks within r = 0.09 m")
    parser.add_argument("--separation-parts", type=int, default=1000, metavar="N",
                        help="disks in the separation section (default 1000)")
    parser.add_argument("--separation-cycles", type=int, default=200, metavar="N",
                        help="timed cycles of the cell list in the separation section (default 200)")
    parser.add_argument("--startup", action="store_true",
                        help="only the start-up section: `ppod field` on Sink 21 x 21 in fresh processes, "
                             "ahead-of-time against JIT kernel")
    parser.add_argument("--startup-runs", type=int, default=9, metavar="N",
                        help="processes per variant in the start-up section (default 9)")
    parser.add_argument("--planner-motions", action="store_true",
                        help="only the planner-motions section: the solver on the motions the model-predictive "
                             "planner produces in closed loop, against the reference and a solve_ivp baseline")
    parser.add_argument("--planner-scenes", type=int, default=2, metavar="N",
                        help="planner-motions: multipart scenes per count (1 and 3) to record (default 2)")
    parser.add_argument("--planner-seconds", type=float, default=15.0, metavar="S",
                        help="planner-motions: device time per recorded scene (default 15)")
    parser.add_argument("--planner-samples", type=int, default=16, metavar="N",
                        help="planner-motions: sampled motions per part kind, point and rigid (default 16)")
    parser.add_argument("--no-busy", dest="busy", action="store_false",
                        help="latency section without the busy loop on the other core")


# ------------------------------------------------------------------ settings compared


def _point_settings():
    from ppod_ros.physics import PRESETS, SolverSettings

    return {
        "fast": PRESETS["fast"],
        "default": PRESETS["default"],
        "rtol 1e-7": SolverSettings(rtol=1e-7, fixed_point_rtol=1e-6),
        "bs3 rtol 1e-6": SolverSettings(integrator="bs3", fixed_point_rtol=1e-5),
        "dop853 rtol 1e-8": SolverSettings(integrator="dop853", rtol=1e-8, fixed_point_rtol=1e-7),
        "accurate": PRESETS["accurate"],
        "default, picard": SolverSettings(fixed_point="picard"),
        "default, no closed form": SolverSettings(closed_form=False),
    }


def _rigid_settings():
    from ppod_ros.physics import PRESETS, SolverSettings

    return {
        "fast": PRESETS["fast"],
        "default": PRESETS["default"],
        "rigid_rtol 1e-7": SolverSettings(rigid_rtol=1e-7),
        "rigid_rtol 1e-9": SolverSettings(rigid_rtol=1e-9, fixed_point_rtol=1e-7),
        "dop853 1e-9": SolverSettings(integrator="dop853", rigid_rtol=1e-9, fixed_point_rtol=1e-7),
        "accurate": PRESETS["accurate"],
    }


# ------------------------------------------------------------------ helpers


def _timed(motion, part, cfg, settings, repeat, **kw):
    from ppod_ros.physics import solve_field

    best = None
    for _ in range(max(1, repeat)):
        r = solve_field(motion, part, cfg, settings.replace(cache=False), **kw)
        if best is None or r.seconds < best.seconds:
            best = r
    return best


def _errors(r, ref):
    both = r.valid & ref.valid
    d = np.abs(r.velocity[both] - ref.velocity[both])
    ev = float(d[:, :2].max()) if both.any() else 0.0
    ew = float(d[:, 2].max()) if both.any() and d.shape[1] == 3 else float("nan")
    return ev, ew, int((r.valid != ref.valid).sum())


def _reference(motion, part, cfg, out: Path):
    """The reference preset's field, cached under out/reference keyed by everything it depends on."""
    from ppod_ros.physics import PRESETS, solve_field

    ref = PRESETS["reference"]
    h = hashlib.sha1()
    for item in (motion.key, repr(part.key).encode(), cfg.tobytes(), repr(ref.cache_key()).encode()):
        h.update(item)
    path = out / "reference" / f"{motion.name or 'motion'}-{h.hexdigest()[:16]}.npz"
    if path.exists():
        z = np.load(path)
        return _Stored(z["velocity"], z["valid"], float(z["seconds"])), True
    r = solve_field(motion, part, cfg, ref)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, velocity=r.velocity, valid=r.valid, seconds=r.seconds)
    return _Stored(r.velocity, r.valid, r.seconds), False


class _Stored:
    def __init__(self, velocity, valid, seconds):
        self.velocity = velocity
        self.valid = valid
        self.seconds = seconds


class _OutOfTimeError(Exception):
    pass


def baseline_average(motion, mu, x, y, budget_s=float("inf")):
    """The plain solve_ivp baseline at one point: (period-average velocity (2,), periods, finished).

    Where the part sticks, s' = -mu n w/|w| chatters around w = 0 and RK45 at rtol 1e-9 crawls
    (minutes per configuration): after ``budget_s`` of wall time the run stops and reports its
    last period average with ``finished`` False, so the benchmark's ratio is then a lower bound.
    """
    from scipy.integrate import solve_ivp

    T = motion.period_s
    deadline = time.perf_counter() + budget_s
    # The plate at (x, y), precomputed once: a_n = sum An_k sin(w_k t + pn_k), v_h likewise.
    amp = np.asarray(motion.amplitude, float)
    ph = np.asarray(motion.phase, float)
    w = motion.omega * np.asarray(motion.k, float)
    def combine(c, cx, cy):  # amplitude/phase of c u_j + cx u_5 (or alpha terms) as one sinusoid
        z = (amp[:, c[0]] * np.exp(1j * ph[:, c[0]]) * c[1] + amp[:, cx[0]] * np.exp(1j * ph[:, cx[0]]) * cx[1]
             + amp[:, cy[0]] * np.exp(1j * ph[:, cy[0]]) * cy[1])
        return z
    zn = combine((2, 1.0), (3, y), (4, -x))            # a_n = u2 + u3 y - u4 x
    zvx = combine((0, 1.0), (5, -y), (5, 0.0)) / w     # v_h = integral of a_h (zero mean)
    zvy = combine((1, 1.0), (5, x), (5, 0.0)) / w
    mu_g = mu * 9.81

    def rhs(t, s):
        if time.perf_counter() > deadline:
            raise _OutOfTimeError
        e = np.exp(1j * w * t)
        n_acc = float((zn * e).imag.sum())
        vx = float(-(zvx * e).real.sum())
        vy = float(-(zvy * e).real.sum())
        wx, wy = s[0] - vx, s[1] - vy
        nw = math.hypot(wx, wy)
        if nw == 0.0:
            return np.zeros(2)
        f = -(mu_g + mu * n_acc) / nw
        return np.array([f * wx, f * wy])

    s = np.zeros(2)
    last = np.full(2, np.nan)
    for p in range(200):
        try:
            sol = solve_ivp(rhs, (p * T, (p + 1) * T), s, method="RK45", rtol=1e-9, atol=1e-12, dense_output=True)
        except _OutOfTimeError:
            return last, p, False
        s = sol.y[:, -1]
        tt = np.linspace(p * T, (p + 1) * T, 401)
        avg = np.trapezoid(sol.sol(tt), tt, axis=1) / T
        if np.isfinite(last).all() and np.abs(avg - last).max() < 1e-8:
            return avg, p + 1, True
        last = avg
    return last, 200, True


def _table(title, header, rows):
    widths = [max(len(str(h)), *(len(str(r[i])) for r in rows)) for i, h in enumerate(header)]
    line = "  ".join(f"{h:>{w}}" for h, w in zip(header, widths))
    out = [f"\n== {title}", line, "-" * len(line)]
    out += ["  ".join(f"{str(c):>{w}}" for c, w in zip(r, widths)) for r in rows]
    text = "\n".join(out)
    print(text, flush=True)
    return text


# ------------------------------------------------------------------ the run


def run(args: argparse.Namespace) -> int:
    from ppod_ros.motion import PlateMotion
    from ppod_ros.parts import PointPart, load_part
    from ppod_ros.physics import PRESETS, PartDynamics, grid_configs, solve_field
    from ppod_ros.physics._params import ensure_compiled

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.stalls:
        return _run_stalls(args, out)
    if args.suite:
        return _run_suite(args, out)
    if args.design:
        return _run_design(args, out)
    if args.separation:
        return _run_separation(args, out)
    if args.startup:
        return _run_startup(args, out)
    if args.planner_motions:
        from ppod_bench.solver_planner import run_planner_motions

        return run_planner_motions(args, out)
    quick = args.quick
    n = 21 if quick else args.grid
    nr = 5 if quick else args.rigid_grid
    nb = 5 if quick else args.baseline_configs
    names = args.motions or (["LineSinkX", "Sink", "StickingHeavy"] if quick else POINT_MOTIONS)
    repeat = 1 if quick else args.repeat
    texts = []

    t0 = time.perf_counter()
    setup = ensure_compiled()
    print(f"set-up (numba compile or cache load): {setup:.2f} s ({time.perf_counter() - t0:.2f} s wall)")

    part = PointPart(0.3)
    xs = np.linspace(-0.1, 0.1, n)
    cfg = grid_configs(xs, xs)
    motions = {name: PlateMotion.from_yaml(CONFIG / "motions" / f"{name}.yaml") for name in names}

    # --- references ------------------------------------------------------------------------------
    refs = {}
    for name, m in motions.items():
        refs[name], cached = _reference(m, part, cfg, out)
        print(f"reference {name}: {'cached' if cached else f'computed in {refs[name].seconds:.1f} s'}", flush=True)

    # --- Pareto, point parts -----------------------------------------------------------------------
    settings = _point_settings()
    results = {}
    rows = []
    for label, st in settings.items():
        worst_t, worst_e, total, mism = 0.0, 0.0, 0.0, 0
        for name, m in motions.items():
            r = _timed(m, part, cfg, st, repeat)
            ev, _, mm = _errors(r, refs[name])
            results[(label, name)] = (r.seconds, ev, r)
            worst_t, worst_e, total, mism = max(worst_t, r.seconds), max(worst_e, ev), total + r.seconds, mism + mm
        rows.append([label, f"{worst_t:.3f}", f"{total:.3f}", f"{worst_e:.1e}", mism])
    texts.append(_table(f"point part, {n} x {n} grid, all {len(motions)} motions: settings vs max error vs time",
                        ["settings", "worst s/motion", "total s", "max err m/s", "validity mismatches"], rows))
    rows = []
    for name in motions:
        s, ev, r = results[("default", name)]
        rows.append([name, f"{s:.3f}", f"{ev:.1e}", int((~r.valid).sum()), f"{r.periods[r.valid].mean():.1f}",
                     f"{np.nanmean(r.stick_fraction):.3f}", f"{results[('fast', name)][0]:.3f}",
                     f"{results[('fast', name)][1]:.1e}"])
    texts.append(_table(f"point part, default settings, per motion ({n} x {n})",
                        ["motion", "seconds", "max err m/s", "invalid", "periods", "stick frac",
                         "fast s", "fast err"], rows))

    # --- rigid ---------------------------------------------------------------------------------------
    rigid = load_part(CONFIG / "parts" / "published_rigid.yaml")
    u1 = PlateMotion.from_yaml(CONFIG / "motions" / "RigidU1.yaml")
    rcfg = grid_configs(np.linspace(-0.06, 0.06, nr), np.linspace(-0.06, 0.06, nr),
                        np.linspace(0, 2 * np.pi, nr, endpoint=False))
    rref, cached = _reference(u1, rigid, rcfg, out)
    print(f"reference rigid: {'cached' if cached else f'computed in {rref.seconds:.1f} s'}", flush=True)
    rows = []
    rigid_results = {}
    for label, st in _rigid_settings().items():
        r = _timed(u1, rigid, rcfg, st, repeat)
        ev, ew, mm = _errors(r, rref)
        rigid_results[label] = (r.seconds, ev, ew)
        rows.append([label, f"{r.seconds:.3f}", f"{ev:.1e}", f"{ew:.1e}", mm, f"{r.periods[r.valid].mean():.1f}"])
    texts.append(_table(f"rigid part (PHYSICS.md), RigidU1, {len(rcfg)} configurations",
                        ["settings", "seconds", "max err m/s", "max err rad/s", "mismatches", "periods"], rows))

    # --- baseline --------------------------------------------------------------------------------------
    rng = np.random.default_rng(args.seed)
    rows = []
    base_points = []
    for name, m in motions.items():
        ok = np.flatnonzero(refs[name].valid)
        pick = np.sort(rng.choice(ok, size=min(nb, ok.size), replace=False))
        sub = cfg[pick]
        tb = time.perf_counter()
        runs = [baseline_average(m, 0.3, x, y, args.baseline_budget) for x, y in sub]
        t_base = (time.perf_counter() - tb) / len(sub)
        bv = np.array([r[0] for r in runs])
        capped = sum(not r[2] for r in runs)
        e_base = float(np.nanmax(np.abs(bv - refs[name].velocity[pick]))) if np.isfinite(bv).any() else np.inf
        print(f"baseline {name}: {t_base:.2f} s/config, max err {e_base:.1e}"
              + (f", {capped} of {len(sub)} stopped at the {args.baseline_budget:g} s budget" if capped else ""),
              flush=True)
        # Ours on the same configurations: the cheapest settings at equal or better error.
        best = None
        for label, st in settings.items():
            r = _timed(m, part, sub, st, repeat)
            e = float(np.abs(r.velocity - refs[name].velocity[pick]).max()) if r.valid.all() else np.inf
            if e <= e_base and (best is None or r.seconds < best[1]):
                best = (label, r.seconds, e)
        if best is None:
            rows.append([name, len(sub), f"{t_base:.3f}", f"{e_base:.1e}", "-", "-", "-", "-", "-"])
            continue
        t_ours = best[1] / len(sub)
        r_grid = results[("default", name)][2]
        t_grid = r_grid.seconds / max(1, int((r_grid.periods > 0).sum()))  # contact-lost ones excluded
        base_points.append((t_base, e_base))
        bound = ">=" if capped else ""
        rows.append([name, f"{len(sub)}" + (f" ({capped} capped)" if capped else ""), f"{bound}{t_base:.3f}",
                     f"{e_base:.1e}", best[0], f"{t_ours * 1e3:.3f}", f"{best[2]:.1e}",
                     f"{bound}{t_base / t_ours:.0f}", f"{bound}{t_base / t_grid:.0f}"])
    texts.append(_table("solve_ivp baseline (RK45 1e-9/1e-12, period averages to 1e-8 m/s) vs this solver",
                        ["motion", "configs", "baseline s/config", "baseline max err", "ours: cheapest at <= err",
                         "ours ms/config", "ours max err", "ratio (same configs)",
                         "ratio (default, grid, integrated configs only)"], rows))

    # --- skipping ------------------------------------------------------------------------------------
    rows = []
    sink = PlateMotion.from_yaml(CONFIG / "motions" / "Sink.yaml")
    padded = PlateMotion(sink.frequency_hz, np.arange(1, 11), np.vstack([sink.amplitude, np.zeros((9, 6))]),
                         np.vstack([sink.phase, np.zeros((9, 6))]))
    d = PRESETS["default"]
    for label, (m, a, b) in {
        "zero harmonics 2..10 (Sink): pruned vs kept": (padded, d, d.replace(prune_harmonics=False)),
        "collinear a_h (RotateZ): closed form vs integrated": (
            PlateMotion.from_yaml(CONFIG / "motions" / "RotateZ.yaml"), d, d.replace(closed_form=False)),
        "collinear a_h (LineSinkX): closed form vs integrated": (
            PlateMotion.from_yaml(CONFIG / "motions" / "LineSinkX.yaml"), d, d.replace(closed_form=False)),
        "sticking provably impossible (Sink): skipped vs checked": (sink, d, d.replace(skip_sticking=False)),
    }.items():
        ra = _timed(m, part, cfg, a, repeat)
        rb = _timed(m, part, cfg, b, repeat)
        rows.append([label, f"{ra.seconds:.3f}", f"{rb.seconds:.3f}", f"{rb.seconds / max(ra.seconds, 1e-9):.1f}x"])
    ra = _timed(u1, rigid, rcfg, d, repeat)
    rb = _timed(u1, rigid, rcfg, d.replace(skip_sticking=False), repeat)
    rows.append(["sticking provably impossible (rigid, RigidU1): skipped vs checked", f"{ra.seconds:.3f}",
                 f"{rb.seconds:.3f}", f"{rb.seconds / max(ra.seconds, 1e-9):.1f}x"])
    from ppod_ros.physics import FieldCache

    cache = FieldCache()
    first = solve_field(sink, part, cfg, d, cache=cache)
    second = solve_field(sink, part, cfg, d, cache=cache)
    rows.append(["result cache (Sink): second call vs first", f"{second.seconds:.3f}", f"{first.seconds:.3f}",
                 f"{first.seconds / max(second.seconds, 1e-9):.0f}x"])
    ncl = PlateMotion.from_yaml(CONFIG / "motions" / "NearContactLoss.yaml")
    full = _timed(ncl, part, cfg, d, repeat)
    valid_only = _timed(ncl, part, cfg[full.valid], d, repeat)
    rows.append([f"contact lost, not integrated (NearContactLoss, {int((~full.valid).sum())} invalid): "
                 "valid only vs all", f"{valid_only.seconds:.3f}", f"{full.seconds:.3f}",
                 f"{full.seconds / max(valid_only.seconds, 1e-9):.2f}x"])
    pt = _timed(sink, part, cfg, d, repeat).seconds / len(cfg)
    rt = ra.seconds / len(rcfg)
    rows.append(["point part (2 states, no rotation) vs rigid part, per configuration", f"{pt * 1e3:.3f} ms",
                 f"{rt * 1e3:.3f} ms", f"{rt / pt:.0f}x"])
    texts.append(_table("what skipping saves", ["case", "with skip", "without", "saving"], rows))

    # --- full dynamics ---------------------------------------------------------------------------------
    rows = []
    sim_s = 2.0 if quick else 10.0
    for label, parts, cfgs in (
        ("10 point parts", [part] * 10, np.column_stack([np.linspace(-0.05, 0.05, 10), np.linspace(-0.03, 0.03, 10),
                                                          np.zeros(10)])),
        ("10 rigid parts", [rigid] * 10, np.column_stack([np.linspace(-0.05, 0.05, 10), np.linspace(-0.03, 0.03, 10),
                                                           np.linspace(0, 3, 10)])),
        ("5 point + 5 rigid", [part] * 5 + [rigid] * 5, np.column_stack([np.linspace(-0.05, 0.05, 10),
                                                                         np.linspace(-0.03, 0.03, 10),
                                                                         np.linspace(0, 3, 10)])),
    ):
        for mname in ("Sink", "RigidU1"):
            m = PlateMotion.from_yaml(CONFIG / "motions" / f"{mname}.yaml")
            sim = PartDynamics(parts, cfgs)
            tb = time.perf_counter()
            for k in range(int(round(sim_s / 0.1))):
                sim.advance(m, k * 0.1, 0.1)
            el = time.perf_counter() - tb
            rows.append([label, mname, f"{sim_s:.0f} s", f"{el:.2f} s", f"{sim_s / el:.0f}x",
                         int(sim.state.contact_lost.sum())])
    texts.append(_table("full dynamics, advanced in 0.1 s chunks",
                        ["parts", "motion", "simulated", "wall", "x real time", "contact lost"], rows))

    (out / "solver_tables.txt").write_text("\n".join(texts) + "\n", encoding="utf-8")
    _plot(out / "solver_pareto.png", results, settings, motions, rigid_results, base_points)
    print(f"\ntables: {out / 'solver_tables.txt'}; plot: {out / 'solver_pareto.png'}")
    return 0


def _run_suite(args, out: Path) -> int:
    """Per motion of the extended suite: grid time (best of --repeat), mean periods per integrated
    configuration (contact-lost ones excluded), and the max error on a random subset against the
    independent fixed-step reference (``fixed_step_reference``, 25,600 steps per period)."""
    import json
    import os

    from ppod_bench.fixed_step_reference import reference_average
    from ppod_ros.motion import PlateMotion
    from ppod_ros.parts import PointPart
    from ppod_ros.physics import SolverSettings, grid_configs
    from ppod_ros.physics._params import ensure_compiled

    ensure_compiled()
    n = args.grid
    names = args.motions or SUITE_MOTIONS
    part = PointPart(0.3)
    xs = np.linspace(-0.1, 0.1, n)
    cfg = grid_configs(xs, xs)
    st = SolverSettings(cache=False)
    rng = np.random.default_rng(args.seed)
    rows, figures = [], {}
    load = os.getloadavg()
    print(f"load average before: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}", flush=True)
    for name in names:
        m = PlateMotion.from_yaml(CONFIG / "motions" / f"{name}.yaml")
        r = _timed(m, part, cfg, st, args.repeat)
        integrated = r.periods > 0
        ok = np.flatnonzero(r.valid)
        pick = np.sort(rng.choice(ok, size=min(args.reference_configs, ok.size), replace=False))
        err = 0.0
        tr = time.perf_counter()
        for i in pick:
            ref, _ = reference_average(m, part.mu, cfg[i, 0], cfg[i, 1], start=r.cycle_start[i])
            err = max(err, float(np.abs(ref - r.velocity[i]).max()))
        tr = time.perf_counter() - tr
        periods = float(r.periods[integrated].mean()) if integrated.any() else 0.0
        figures[name] = {"seconds": r.seconds, "periods_per_config": periods, "max_error_mps": err,
                         "checked_configs": int(pick.size), "invalid": int((~r.valid).sum()),
                         "stick_fraction_mean": float(np.nanmean(r.stick_fraction)) if ok.size else None}
        rows.append([name, f"{r.seconds:.3f}", f"{periods:.2f}", f"{err:.1e}", int(pick.size),
                     int((~r.valid).sum()), f"{np.nanmean(r.stick_fraction):.3f}" if ok.size else "-"])
        print(f"{name}: {r.seconds:.3f} s, {periods:.2f} periods/config, max err {err:.1e} "
              f"({pick.size} configs, reference {tr:.1f} s)", flush=True)
    text = _table(f"extended suite, point part mu 0.3, {n} x {n} grid, default settings; error vs the fixed-step "
                  f"reference (25,600 steps per period)",
                  ["motion", "seconds", "periods/config", "max err m/s", "checked", "invalid", "stick frac"], rows)
    (out / "solver_suite.txt").write_text(text + "\n", encoding="utf-8")
    if args.json:
        payload = {"grid": n, "load_average": list(load), "motions": figures}
        Path(args.json).write_text(json.dumps(payload, indent=1) + "\n", encoding="utf-8")
    return 0


DESIGN_SPECS = [("line_sink", [0.01, 0.0, 0.5, 0.3]), ("rotation", [0.02, 0.01, 0.2])]


def _run_design(args, out: Path) -> int:
    """One-frequency designs from an empty design cache on N x N sample grids (design._FIT_N)."""
    import os

    import ppod_ros.physics as physics
    from ppod_ros.planning import FieldSpec
    from ppod_ros.planning import design as design_module

    real = physics.solve_fields
    calls: list = []

    def counting(*a, **kw):
        r = real(*a, **kw)
        calls.append(r)
        return r

    default_n = design_module._FIT_N
    design_module.design_field(FieldSpec.from_request("transport", [0.003, 0.0]))  # solver loading
    rows = []
    physics.solve_fields = counting
    try:
        for n in args.design:
            design_module._FIT_N = n
            for kind, params in DESIGN_SPECS:
                design_module._CACHE.clear()
                calls.clear()
                load = os.getloadavg()[0]
                t0, c0 = time.perf_counter(), time.process_time()
                r = design_module.design_field(FieldSpec.from_request(kind, params))
                wall, cpu = time.perf_counter() - t0, time.process_time() - c0
                configs = sum(int(c.periods.size) for c in calls)
                integrated = sum(int((c.periods > 0).sum()) for c in calls)
                periods = sum(float(c.periods.sum()) for c in calls) / max(1, integrated)
                rows.append([kind, f"{n} x {n} ({len(design_module._disc_points(n))})", f"{r.r2:.4f}",
                             f"{wall:.2f}", f"{cpu:.2f}", str(len(calls)), str(configs), f"{periods:.2f}",
                             f"{load:.1f}"])
                print("  " + "  ".join(rows[-1]), flush=True)
    finally:
        physics.solve_fields = real
        design_module._FIT_N = default_n
    text = _table("one-frequency designs (30 Hz, point part mu 0.3), from an empty design cache",
                  ["design", "samples (points)", "R^2", "wall s", "CPU s", "solver calls", "configs",
                   "periods/config", "load"], rows)
    (out / "solver_design.txt").write_text(text + "\n", encoding="utf-8")
    return 0


def _run_separation(args, out: Path) -> int:
    import os

    from ppod_bench.solver_separation import measure

    load = os.getloadavg()
    print(f"part separation per cycle; load average before: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}", flush=True)
    rows = measure(args.separation_parts, args.separation_cycles)
    text = _table("part separation per plate cycle (2 mm disks within r = 0.09 m, 0.2 mm rms step per cycle)",
                  ["method", "parts", "cycles", "moved / cycle", "p50 ms", "p90 ms", "max ms"], rows)
    (out / "solver_separation.txt").write_text(text + "\n", encoding="utf-8")
    return 0


def _run_startup(args, out: Path) -> int:
    from ppod_bench.solver_startup import measure
    from ppod_ros.errors import ConfigError

    if args.startup_runs < 1:
        raise ConfigError(f"--startup-runs: expected an integer >= 1, got {args.startup_runs}")
    rows = measure(args.startup_runs)
    text = _table("start-up: ppod field config/motions/Sink.yaml --json OUT --quiet (21 x 21), fresh processes",
                  ["kernel", "runs", "wall min s", "wall median s", "CPU median s", "load"], rows)
    (out / "solver_startup.txt").write_text(text + "\n", encoding="utf-8")
    return 0


def _run_stalls(args, out: Path) -> int:
    import os

    from ppod_bench.solver_stalls import measure

    load = os.getloadavg()
    print(f"per-call latency, {'busy loop on the other core' if args.busy else 'no busy loop'}; "
          f"load average before: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}", flush=True)
    rows = measure(args.stall_calls, args.busy)
    text = _table("per-call latency of small calls" + (" with the other core busy" if args.busy else ""),
                  ["case", "threads", "calls", "p50 ms", "p90 ms", "max ms", "thread CPU p50 ms", "periods/config"],
                  rows)
    (out / "solver_stalls.txt").write_text(text + "\n", encoding="utf-8")
    return 0


def _plot(path, results, settings, motions, rigid_results, base_points) -> None:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.5))
    for label in settings:
        t = [results[(label, n)][0] for n in motions]
        e = [max(results[(label, n)][1], 1e-12) for n in motions]
        ax.scatter(t, e, s=18, label=label)
    for label, (t, ev, _ew) in rigid_results.items():
        ax.scatter([t], [max(ev, 1e-12)], marker="s", s=30, edgecolor="k", facecolor="none")
        ax.annotate(f"rigid: {label}", (t, max(ev, 1e-12)), fontsize=6)
    for t, e in base_points:
        ax.scatter([t], [max(e, 1e-12)], marker="x", color="red", s=30)
    ax.scatter([], [], marker="x", color="red", label="solve_ivp baseline (s per configuration)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.axhline(1e-5, color="grey", lw=0.6, ls="--")
    ax.axvline(0.2, color="grey", lw=0.6, ls="--")
    ax.set_xlabel("seconds (point: one 51 x 51 motion grid; rigid: 343 configurations)")
    ax.set_ylabel("max error vs reference (m/s)")
    ax.set_title("asymptotic solver: error vs time per motion and settings", fontsize=9)
    ax.legend(fontsize=6, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)

"""Compute the asymptotic velocity field of a plate motion (no ROS needed).

For every configuration of a grid (x varies fastest, then y, then theta) the part's velocity
(point part) or twist (rigid part: centre-of-mass velocity and yaw rate) averaged over the limit
cycle, in the plate frame, SI units. Configurations where the solver cannot give a number (contact
lost, frictional singularity, not converged) are reported invalid with the reason.

examples:
  ppod field config/motions/LineSinkX.yaml
  ppod field config/motions/Sink.yaml --x -0.08 0.08 33 --y -0.08 0.08 33 --plot sink.png
  ppod field config/motions/LineSinkX.yaml --mu 0.5 --json field.json
  ppod field config/motions/RigidU1.yaml --part config/parts/published_rigid.yaml \\
      --x -0.06 0.06 7 --y -0.06 0.06 7 --theta 0 6.2832 16 --plot rigid.png
  ppod field config/motions/Swirl3H.yaml --preset accurate --json - > field.json
  ppod field config/motions/Sink.yaml config/motions/Whirlpool.yaml --json fields/

Several motion files are solved in one call (one start-up); --json and --plot then name a
directory that gets one NAME.json / NAME.png per motion file ('--json -': one JSON object per line).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

HELP = "asymptotic velocity field of a plate motion on a grid (table, JSON, plot)"

#: Runs with more (configurations x cost) than this report progress on stderr.
_PROGRESS_WORK = 3000
#: Largest grid (configurations): results take about 200 bytes each, and the solver seconds each.
MAX_CONFIGS = 1_000_000


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("motion", metavar="MOTION.yaml", nargs="+",
                        help="plate motion (FORMATS.md); several: one field per file")
    parser.add_argument("--part", metavar="PART.yaml",
                        help="part description (default: a point part, mu 0.3)")
    parser.add_argument("--mu", metavar="MU", help="friction coefficient of the default point part")
    parser.add_argument("--x", nargs=3, metavar=("MIN", "MAX", "N"), default=None,
                        help="inclusive grid in x, m (default -0.1 0.1 21)")
    parser.add_argument("--y", nargs=3, metavar=("MIN", "MAX", "N"), default=None,
                        help="inclusive grid in y, m (default -0.1 0.1 21)")
    parser.add_argument("--theta", nargs=3, metavar=("MIN", "MAX", "N"), default=None,
                        help="inclusive grid in theta, rad, rigid parts only "
                             "(default: 8 angles over [0, 2 pi))")
    parser.add_argument("--json", metavar="OUT",
                        help="write the result as JSON to OUT ('-': standard output)")
    parser.add_argument("--plot", metavar="OUT.png",
                        help="save a quiver plot (invalid configurations marked)")
    parser.add_argument("--quiet", action="store_true", help="no progress or summary on stderr")
    s = parser.add_argument_group("solver settings (docs/solver.md)")
    s.add_argument("--preset", default="default", help="named settings: fast, default, accurate, reference")
    s.add_argument("--integrator", help="bs3, dopri5 or dop853")
    s.add_argument("--fixed-point", dest="fixed_point", help="anderson or picard")
    s.add_argument("--rtol", help="local error tolerance per step, relative to the velocity scale")
    s.add_argument("--rigid-rtol", dest="rigid_rtol", help="the same for rigid parts")
    s.add_argument("--fixed-point-rtol", dest="fixed_point_rtol", help="limit-cycle convergence tolerance")
    s.add_argument("--max-periods", dest="max_periods",
                   help="periods per configuration before 'not converged'")
    s.add_argument("--friction-eps", dest="friction_eps_mps",
                   help="rigid parts: regularisation speed (m/s)")
    s.add_argument("--threads", help="worker threads (default: all cores for large grids, 1 for small ones)")
    s.add_argument("--no-closed-form", dest="closed_form", action="store_false", default=None,
                   help="integrate also where the closed form applies")
    s.add_argument("--no-cache", dest="cache", action="store_false", default=None,
                   help="bypass the result cache")


def _grid(values, name: str, default: tuple[float, float, int]) -> np.ndarray:
    from ppod_ros.errors import ConfigError

    if values is None:
        lo, hi, n = default
    else:
        try:
            lo, hi = float(values[0]), float(values[1])
        except ValueError:
            raise ConfigError(f"--{name}: MIN and MAX must be numbers, "
                              f"got {values[0]!r} {values[1]!r}") from None
        try:
            n = int(values[2])
        except ValueError:
            raise ConfigError(f"--{name}: N must be an integer >= 1, got {values[2]!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ConfigError(f"--{name}: MIN and MAX must be finite, got {lo} {hi}")
    if n < 1:
        raise ConfigError(f"--{name}: N must be an integer >= 1, got {n}")
    if n > MAX_CONFIGS:
        raise ConfigError(f"--{name}: N = {n} is more than the {MAX_CONFIGS} configurations a field may have")
    if hi < lo:
        raise ConfigError(f"--{name}: MAX must be >= MIN, got {lo} {hi}")
    return np.linspace(lo, hi, n)


def _settings(args):
    from ppod_ros.errors import ConfigError
    from ppod_ros.physics import preset

    base = preset(args.preset)
    conv = {"integrator": str, "fixed_point": str, "rtol": float, "rigid_rtol": float,
            "fixed_point_rtol": float,
            "max_periods": int, "friction_eps_mps": float, "threads": int}
    changes = {}
    for key, kind in conv.items():
        raw = getattr(args, key)
        if raw is None:
            continue
        try:
            changes[key] = kind(raw)
        except ValueError:
            flag = "--" + key.replace("_mps", "").replace("_", "-")
            what = "an integer" if kind is int else "a number"
            raise ConfigError(f"{flag}: expected {what}, got {raw!r}") from None
    for key in ("closed_form", "cache"):
        if getattr(args, key) is not None:
            changes[key] = getattr(args, key)
    return base.replace(**changes) if changes else base


def run(args: argparse.Namespace) -> int:
    from ppod_ros.config.fields import check_number
    from ppod_ros.errors import ConfigError
    from ppod_ros.motion import PlateMotion
    from ppod_ros.parts import PointPart, load_part
    from ppod_ros.physics import grid_configs, solve_field

    paths = list(args.motion) if isinstance(args.motion, (list, tuple)) else [args.motion]
    motions = [PlateMotion.from_yaml(p) for p in paths]
    several = len(motions) > 1
    stems = [Path(p).stem for p in paths]
    if several and len(set(stems)) < len(stems):
        raise ConfigError(f"MOTION.yaml: several files share a name ({', '.join(stems)}); their outputs would "
                          f"overwrite each other")
    part = load_part(args.part) if args.part else PointPart(0.3)
    if args.mu is not None:
        if part.kind != "point":
            raise ConfigError("--mu: only for point parts; a rigid part's friction is set per contact in its "
                              "PART.yaml")
        try:
            mu = float(args.mu)
        except ValueError:
            raise ConfigError(f"--mu: expected a number >= 0, got {args.mu!r}") from None
        check_number(mu, "--mu", min_value=0.0)
        # mu_static follows mu unless the part file gave a larger static coefficient.
        mu_s = None if part.mu_static == part.mu else max(mu, part.mu_static)
        part = PointPart(mu, mu_s, part.footprint)
    xs = _grid(args.x, "x", (-0.1, 0.1, 21))
    ys = _grid(args.y, "y", (-0.1, 0.1, 21))
    n_theta = 1 if part.kind == "point" else (8 if args.theta is None else int(float(args.theta[2])))
    if xs.size * ys.size * n_theta > MAX_CONFIGS:
        raise ConfigError(f"--x, --y, --theta: {xs.size} x {ys.size} x {n_theta} configurations is more than "
                          f"the {MAX_CONFIGS} a field may have; use a coarser grid")
    if part.kind == "point":
        if args.theta is not None:
            raise ConfigError("--theta: only for rigid parts (a point part has no orientation)")
        configs = grid_configs(xs, ys)
    else:
        thetas = (np.linspace(0.0, 2 * math.pi, 8, endpoint=False) if args.theta is None
                  else _grid(args.theta, "theta", (0.0, 2 * math.pi, 8)))
        configs = grid_configs(xs, ys, thetas)
    settings = _settings(args)
    progress = None
    cost = 1 if part.kind == "point" else 20
    if not args.quiet and len(motions) * len(configs) * cost > _PROGRESS_WORK:
        t0 = time.perf_counter()

        def progress(done: int, total: int) -> None:
            print(f"ppod field: {100 * done // total:3d}% ({done}/{total} configurations, "
                  f"{time.perf_counter() - t0:.1f} s)", file=sys.stderr, flush=True)

    if several:
        return _run_several(args, motions, stems, part, configs, settings, progress)
    motion = motions[0]
    result = _finite_only(solve_field(motion, part, configs, settings, progress=progress))
    if args.json:
        text = result.to_json()
        if args.json == "-":
            print(text)
        else:
            try:
                Path(args.json).write_text(text + "\n", encoding="utf-8")
            except OSError as exc:
                raise ConfigError(f"--json {args.json}: cannot write: {exc.strerror or exc}") from exc
    else:
        print(format_table(result, motion))
    if args.plot:
        from ppod_ros.physics.plot import plot_field

        plot_field(result, motion, args.plot, part_label=_part_label(part))
    if not args.quiet:
        print(f"ppod field: {len(result)} configurations, {int(result.valid.sum())} valid, "
              f"{result.seconds:.3f} s solver (+{result.setup_seconds:.2f} s set-up)", file=sys.stderr)
    return 0


def _finite_only(result):
    """A velocity that is not finite (e.g. an absurd frequency) is never reported valid."""
    import dataclasses

    from ppod_ros.physics import _layout as layout

    bad = result.valid & ~np.all(np.isfinite(result.velocity), axis=1)
    if not bad.any():
        return result
    valid = result.valid & ~bad
    codes = np.where(bad, layout.NOT_CONVERGED, result.reason_code)
    return dataclasses.replace(result, valid=valid, reason_code=codes)


def _run_several(args, motions, stems, part, configs, settings, progress) -> int:
    """Several motion files: one solver call; one table / JSON / plot per motion."""
    from ppod_ros.errors import ConfigError
    from ppod_ros.physics import solve_fields

    batch = solve_fields(motions, part, configs, settings, progress=progress, warm=False)
    out_dirs = {}
    for flag in ("json", "plot"):
        dest = getattr(args, flag)
        if dest and dest != "-":
            out_dirs[flag] = Path(dest)
            try:
                out_dirs[flag].mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise ConfigError(f"--{flag} {dest}: with several motion files this is a directory; "
                                  f"cannot create it: {exc.strerror or exc}") from exc
    if args.plot == "-":
        raise ConfigError("--plot: with several motion files give a directory, not '-'")
    for m, (motion, stem) in enumerate(zip(motions, stems)):
        result = _finite_only(batch.field(m))
        if args.json == "-":
            print(result.to_json())
        elif args.json:
            target = out_dirs["json"] / f"{stem}.json"
            try:
                target.write_text(result.to_json() + "\n", encoding="utf-8")
            except OSError as exc:
                raise ConfigError(f"--json {target}: cannot write: {exc.strerror or exc}") from exc
        else:
            print(format_table(result, motion))
        if args.plot:
            from ppod_ros.physics.plot import plot_field

            plot_field(result, motion, str(out_dirs["plot"] / f"{stem}.png"), part_label=_part_label(part))
    if not args.quiet:
        print(f"ppod field: {len(motions)} motions x {configs.shape[0]} configurations, "
              f"{int(batch.valid.sum())} valid, {batch.seconds:.3f} s solver (+{batch.setup_seconds:.2f} s "
              f"set-up)", file=sys.stderr)
    return 0


def _part_label(part) -> str:
    if part.kind == "point":
        return f"point part, mu = {part.mu:g}, mu_s = {part.mu_static:g}"
    return f"rigid part, m = {part.mass:g} kg, h = {part.h:g} m, mu = {part.mu.tolist()}"


def format_table(result, motion) -> str:
    """A readable fixed-width table of the field, one configuration per line."""
    rigid = result.part_kind == "rigid"
    head = ["x [m]", "y [m]"] + (["theta [rad]"] if rigid else []) + ["vx [m/s]", "vy [m/s]"] \
        + (["omega [rad/s]"] if rigid else []) + ["stick", "periods", "reason"]
    nvalid = int(result.valid.sum())
    summary = f"# {len(result)} configurations, {nvalid} valid, solver {result.seconds:.3f} s"
    lines = [f"# {motion.describe()}", summary,
             "  ".join(f"{h:>13s}" for h in head[:-1]) + "  reason"]
    rows = zip(result.configs, result.velocity, result.valid, result.stick_fraction, result.periods,
               result.reason)
    for cfg, vel, ok, stick, per, why in rows:
        cells = [f"{c:13.6f}" for c in cfg]
        cells += [f"{v:+13.6e}" if ok else f"{'-':>13s}" for v in vel]
        cells.append(f"{stick:13.4f}" if ok else f"{'-':>13s}")
        cells.append(f"{per:13d}")
        lines.append("  ".join(cells) + "  " + ("" if ok else str(why)))
    return "\n".join(lines)

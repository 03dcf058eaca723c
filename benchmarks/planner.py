"""Field planner: design accuracy and time, closed-loop and sensorless accuracy, physics speed.

Everything runs in this process on the full models (no ROS, no camera). Sections:

  design       per requested field kind and one or two frequencies (11 or 23 inputs): R^2 over the
               working disc (radius 0.07 m, points where contact holds), valid fraction, and the
               design time from an empty design cache (the two-frequency time includes the
               one-frequency design it starts from). The process's first design also pays the
               solver's warm-up, reported on its own line.
  closed loop  the Task on the full dynamics with tracker noise (0.05 mm, 0.1 deg): a point part
               from starts spread over the plate (a ring at 0.065 m and the centre), the rigid
               bracket from several poses; time to done (device s) and the final error.
  sensorless   plan_sensorless played open loop (no poses at all): every start at once, final
               position (and orientation modulo half a turn) error, plan length and planning time.
  physics      the simulated device's parts physics per plate cycle (PartDynamics plus the contact
               separation, SimWorld.advance_parts) for 10 parts under a sink, without the device
               process, ROS or the camera: device seconds per wall second.

Targets (issue: field planner): R^2 >= 0.98 in <= 2 s; within 1 mm and 2 deg in <= 30 s from
anywhere on the plate; physics >= 20x real time for 10 parts.

examples:
  ppod bench planner
  ppod bench planner --quick
  ppod bench planner --sections design physics --out out/bench
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

HELP = "field planner: design R^2 and time, closed-loop and sensorless accuracy, physics speed"
SECTIONS = ("design", "closed", "sensorless", "physics")
GOAL = (0.02, -0.02)
DESIGNS = [("sink", [0.0, 0.0, 0.3]), ("sink", [0.03, -0.02, 0.3]), ("sink", [0.05, 0.04, 0.3]),
           ("line_sink", [0.01, 0.0, 0.5, 0.3]), ("transport", [0.01, 0.005]), ("rotation", [0.02, 0.01, 0.2]),
           ("rotation", [0.0, 0.0, -0.3]), ("orient", [0.02, -0.02, 0.0])]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--sections", nargs="+", choices=SECTIONS, default=list(SECTIONS),
                        help="which sections to run (default: all)")
    parser.add_argument("--quick", action="store_true", help="fewer designs, starts and seconds")
    parser.add_argument("--seed", type=int, default=0, help="tracker-noise seed (default 0)")


def _starts(n: int) -> list[list[float]]:
    angles = np.linspace(0, 2 * math.pi, n - 1, endpoint=False) + 0.3
    return [[0.065 * math.cos(a), 0.065 * math.sin(a)] for a in angles] + [[0.0, 0.0]]


RIGID_STARTS = [[0.05, -0.04, 0.9], [-0.05, 0.04, -1.2], [0.0, 0.06, 2.6], [-0.06, -0.02, 1.6]]


def bench_design(quick: bool) -> list[dict]:
    from ppod_ros.planning import FieldSpec, design_field
    from ppod_ros.planning import design as design_module

    t0 = time.perf_counter()
    design_field(FieldSpec.from_request("transport", [0.003, 0.0]))
    warm = time.perf_counter() - t0
    print(f"  warm-up (first design in the process, solver loading included): {warm:.2f} s", flush=True)
    rows = []
    for kind, params in (DESIGNS[:4] if quick else DESIGNS):
        spec = FieldSpec.from_request(kind, params)
        for harmonics in ((1,) if kind == "orient" else (1, 2)):
            design_module._CACHE.clear()
            t0 = time.perf_counter()
            r = design_field(spec, harmonics=harmonics)
            wall = time.perf_counter() - t0
            row = {"spec": spec.describe(), "harmonics": harmonics, "inputs": 12 * harmonics - 1, "r2": r.r2,
                   "rms_mmps": 1e3 * r.rms_error_mps, "valid": r.valid_fraction, "seconds": wall,
                   "messages": r.messages}
            rows.append(row)
            print(f"  {row['spec']:34s} {harmonics} freq: R^2 {r.r2:.4f}  {wall:5.2f} s", flush=True)
    return rows


def bench_closed(quick: bool, seed: int) -> tuple[list[dict], list]:
    from ppod_ros.parts import PointPart, published_rigid_part
    from ppod_ros.planning import Task
    from ppod_ros.planning.simulate import run_on_dynamics

    rows, paths = [], []
    cases = [("point", PointPart(0.3), s + [0.0], (*GOAL, None)) for s in _starts(4 if quick else 9)]
    cases += [("bracket", published_rigid_part(), s, (*GOAL, 0.0)) for s in RIGID_STARTS[:1 if quick else 4]]
    for kind, part, start, goal in cases:
        t0 = time.perf_counter()
        run = run_on_dynamics(Task([part], 0, goal), [part], [start], horizon_s=60.0, seed=seed)
        final = run.configurations[0]
        err = 1e3 * math.hypot(final[0] - goal[0], final[1] - goal[1])
        ang = None if goal[2] is None else abs(math.degrees((final[2] - goal[2] + math.pi) % (2 * math.pi) - math.pi))
        row = {"part": kind, "start": [round(v, 4) for v in start], "done": bool(run.step.done),
               "device_s": run.elapsed_s, "error_mm": err, "angle_deg": ang, "hops": run.hops,
               "wall_s": time.perf_counter() - t0, "text": run.step.text}
        rows.append(row)
        paths.append(run.trajectory[:, 0, :2])
        print(f"  {kind:7s} from {row['start']}: {run.step.text}", flush=True)
    return rows, paths


def bench_sensorless(quick: bool) -> tuple[list[dict], list]:
    from ppod_ros.parts import PointPart, published_rigid_part
    from ppod_ros.planning import SensorlessTask, plan_sensorless
    from ppod_ros.planning.simulate import run_on_dynamics

    rows, paths = [], []
    cases = [("point", PointPart(0.3), [s + [0.0] for s in _starts(9)], (*GOAL, None))]
    if not quick:
        cases.append(("bracket", published_rigid_part(), RIGID_STARTS, (*GOAL, 0.0)))
    for kind, part, starts, goal in cases:
        t0 = time.perf_counter()
        plan = plan_sensorless(part, goal)
        planning = time.perf_counter() - t0
        run = run_on_dynamics(SensorlessTask(plan), [part] * len(starts), starts, horizon_s=plan.total_s + 1)
        c = run.configurations
        err = 1e3 * np.hypot(c[:, 0] - goal[0], c[:, 1] - goal[1])
        ang = None if goal[2] is None else np.abs(np.degrees((c[:, 2] - goal[2] + math.pi / 2) % math.pi - math.pi / 2))
        row = {"part": kind, "starts": len(starts), "plan_s": plan.total_s, "planning_s": planning,
               "stages": [(s.name, s.duration_s) for s in plan.stages], "max_error_mm": float(err.max()),
               "mean_error_mm": float(err.mean()), "max_angle_deg_mod_180": None if ang is None else float(ang.max()),
               "hops": run.hops}
        rows.append(row)
        paths += [run.trajectory[:, i, :2] for i in range(len(starts))]
        print(f"  {kind}: {len(starts)} starts, plan {plan.total_s:.1f} s (planned in {planning:.1f} s): max error "
              f"{row['max_error_mm']:.2f} mm" + ("" if ang is None else f", {ang.max():.2f} deg mod 180"), flush=True)
    return rows, paths


def _world(kind: str):
    """10 of the packaged scene's parts spread over the working disc: point parts only (three on an
    inner ring, seven on an outer one), or ("mixed") two brackets side by side and eight point parts
    around them."""
    from ppod_ros.device import default_device_config
    from ppod_sim.ros_node import default_scene_path
    from ppod_sim.scene import Scene, ScenePart, load_scene
    from ppod_sim.world import SimWorld

    templates = {p.label: p for p in load_scene(default_scene_path()).parts}
    points = ["washer", "tile", "hex"]
    if kind == "mixed":
        layout = [("bracket", 0.035, 0.0, 1.57), ("bracket", -0.035, 0.0, 1.57)]
        layout += [(points[i % 3], 0.066 * math.cos(a), 0.066 * math.sin(a), 0.0)
                   for i, a in enumerate(np.linspace(0, 2 * math.pi, 8, endpoint=False) + 0.2)]
    else:
        layout = [(points[i % 3], 0.025 * math.cos(a), 0.025 * math.sin(a), 0.0)
                  for i, a in enumerate(np.linspace(0, 2 * math.pi, 3, endpoint=False))]
        layout += [(points[i % 3], 0.06 * math.cos(a), 0.06 * math.sin(a), 0.0)
                   for i, a in enumerate(np.linspace(0, 2 * math.pi, 7, endpoint=False) + 0.3)]
    parts = tuple(ScenePart(label, templates[label].part, templates[label].height_m, np.array([x, y, th]))
                  for label, x, y, th in layout)
    config = default_device_config().with_can(interface="virtual", channel=f"bench-planner-{kind}")
    return SimWorld(config, Scene(parts, 3), None, tick_fps=0.0)


def bench_physics(quick: bool) -> list[dict]:
    from ppod_ros.planning import FieldSpec, design_field
    from ppod_sim.truth import CycleTruth

    motion = design_field(FieldSpec.from_request("sink", [0.0, 0.0, 0.3])).motion
    seconds = 5.0 if quick else 20.0
    rows = []
    for kind in ("point", "mixed"):
        world = _world(kind)
        try:
            n_cycles = int(round(seconds * motion.frequency_hz))
            X = motion.phasor_table()
            z = np.zeros(6)
            world.advance_parts(CycleTruth(0, 0.0, motion.frequency_hz, 0, 1.0, X, np.zeros((1, 6)), z, z, z, z))
            world.physics_s = 0.0
            t0 = time.perf_counter()
            for c in range(1, n_cycles + 1):
                world.advance_parts(CycleTruth(c, c / motion.frequency_hz, motion.frequency_hz, 0, 1.0, X,
                                               np.zeros((1, 6)), z, z, z, z))
            wall = time.perf_counter() - t0
            truth = world.parts_truth()
            n = len(world.scene.parts)
            rows.append({"parts": f"{n} {'point parts' if kind == 'point' else 'parts: 2 brackets, 8 point'}",
                         "device_s": n_cycles / motion.frequency_hz, "wall_s": wall,
                         "real_time_factor": n_cycles / motion.frequency_hz / wall,
                         "on_plate": int(truth.on_plate.sum())})
            print(f"  {n} parts ({kind}): {rows[-1]['real_time_factor']:.0f}x real time", flush=True)
        finally:
            world.close()
    return rows


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    result: dict = {"quick": bool(args.quick)}
    paths: dict = {}
    if "design" in args.sections:
        print("Field designs (30 Hz, point part mu 0.3, device limits):")
        result["design"] = bench_design(args.quick)
    if "closed" in args.sections:
        print("Closed loop on the full dynamics, tracker noise 0.05 mm / 0.1 deg, goal (0.02, -0.02):")
        result["closed"], paths["closed"] = bench_closed(args.quick, args.seed)
    if "sensorless" in args.sections:
        print("Sensorless (no poses), goal (0.02, -0.02):")
        result["sensorless"], paths["sensorless"] = bench_sensorless(args.quick)
    if "physics" in args.sections:
        print("Parts physics of the simulated device (no device process, ROS or camera), sink at the centre:")
        result["physics"] = bench_physics(args.quick)
    _summary(result)
    (out / "planner.json").write_text(json.dumps(result, indent=1, default=float))
    written = [out / "planner.json"]
    if paths:
        _plot(paths, out / "planner.png")
        written.append(out / "planner.png")
    print("\nwrote " + " and ".join(str(p) for p in written))
    return 0


def _summary(r: dict) -> None:
    print("\nSummary")
    if r.get("design"):
        d = r["design"]
        for h in (1, 2):
            rows = [x for x in d if x["harmonics"] == h and not x["spec"].startswith("orient")]
            if rows:
                print(f"  design, {rows[0]['inputs']} inputs: R^2 {min(x['r2'] for x in rows):.4f}-"
                      f"{max(x['r2'] for x in rows):.4f}, {min(x['seconds'] for x in rows):.2f}-"
                      f"{max(x['seconds'] for x in rows):.2f} s ({len(rows)} fields)   target R^2 >= 0.98 in <= 2 s")
        for x in (x for x in d if x["spec"].startswith("orient")):
            print(f"  design, {x['spec']}: not fitted (PHYSICS.md's u1 motion, rotated and shifted); R^2 "
                  f"{x['r2']:.2f} against a line sink of gain 0.45 only describes its translation: what it is for, "
                  f"the stable orientation, is tested")
    for kind in ("point", "bracket"):
        rows = [x for x in r.get("closed", []) if x["part"] == kind]
        if rows:
            ok = [x for x in rows if x["done"]]
            ang = "" if kind == "point" else f", <= {max(x['angle_deg'] for x in rows):.2f} deg"
            print(f"  closed loop, {kind}: {len(ok)}/{len(rows)} done, {min(x['device_s'] for x in rows):.1f}-"
                  f"{max(x['device_s'] for x in rows):.1f} s, final <= {max(x['error_mm'] for x in rows):.2f} mm{ang}, "
                  f"{sum(x['hops'] for x in rows)} contact losses   target 1 mm, 2 deg, <= 30 s")
    for x in r.get("sensorless", []):
        ang = "" if x["max_angle_deg_mod_180"] is None else f", <= {x['max_angle_deg_mod_180']:.2f} deg mod 180"
        print(f"  sensorless, {x['part']}: {x['starts']} starts, {x['plan_s']:.1f} s plan, final "
              f"<= {x['max_error_mm']:.2f} mm{ang}")
    for x in r.get("physics", []):
        print(f"  physics, {x['parts']}: {x['real_time_factor']:.0f}x real time   target >= 20x")


def _plot(paths: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(paths), figsize=(5.5 * len(paths), 5.2), squeeze=False)
    for ax, (name, tracks) in zip(axes[0], paths.items()):
        ax.add_patch(plt.Circle((0, 0), 0.07, fill=False, ls="--", color="0.6"))
        for tr in tracks:
            ax.plot(1e3 * tr[:, 0], 1e3 * tr[:, 1], lw=1)
            ax.plot(1e3 * tr[0, 0], 1e3 * tr[0, 1], "o", ms=3, color="0.3")
        ax.plot(1e3 * GOAL[0], 1e3 * GOAL[1], "r+", ms=12)
        ax.set_title({"closed": "closed loop (Task), full dynamics", "sensorless": "sensorless plan, no poses"}[name])
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

"""The simulated world's parts physics on a recorded run: CPU time and accuracy per solver setting.

The simulated device advances its parts after every plate cycle (``SimWorld.advance_parts``, one
thread). This replays the cycles a run recorded (the plate's true motion per cycle, ramps and
mismatch included) through a fresh world of the demo scene with each solver setting, and reports
the physics thread's CPU time (the minimum over ``--repeats``), the rigid parts' integration steps,
the CPU time of the heaviest second of device time (above 1 s the device cannot keep real time),
contact losses, and the largest and the final deviation of every part's pose from a tight
reference run (same cycles; separation between parts included, as in the world).

Record a run's cycles with the environment variable ``PPOD_SIM_RECORD_CYCLES=FILE.npz`` on the
simulated device (``PPOD_SIM_RECORD_CYCLES=/tmp/demo_cycles.npz ppod demo --no-animation``: the
sim_device node stores them on the way out).

Settings are ``name=value`` lists separated by commas, on top of the world's settings
(``ppod_sim.world.SIM_SOLVER``); ``default`` is ``SolverSettings(threads=1)``, the world's settings
before issue 16.

examples:
  ppod bench sim_parts --cycles /tmp/demo_cycles.npz
  ppod bench sim_parts --cycles /tmp/demo_cycles.npz --settings world default friction_eps_mps=3e-5
"""

from __future__ import annotations

import argparse
import ast
import logging
import sys
import time
from importlib import resources
from pathlib import Path

import numpy as np

HELP = "the simulated world's parts physics on a recorded run: CPU time and accuracy per solver setting"

#: The reference: the pre-issue-16 model (friction_eps_mps 1e-6) with tolerances 100x tighter.
REFERENCE = "default,rtol=1e-9,rigid_rtol=1e-10,max_steps_per_period=10000000"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cycles", required=True, help="recorded cycles (.npz, PPOD_SIM_RECORD_CYCLES)")
    parser.add_argument("--scene", default="", help="scene YAML (default: the demo scene)")
    parser.add_argument("--settings", nargs="+", default=["default", "world"],
                        help="settings to time: 'world', 'default', or name=value,... on the world's")
    parser.add_argument("--reference", default=REFERENCE, help="the reference settings (default: %(default)s)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per setting; the fastest counts (default 3)")
    parser.add_argument("--cycles-limit", type=int, default=0, help="replay only this many cycles (0: all)")


def parse_settings(text: str):
    """'world', 'default' or 'name=value,...' (on the world's, or on 'default,' if it starts so)."""
    from ppod_ros.physics import SolverSettings
    from ppod_sim.world import SIM_SOLVER

    items = [s for s in text.split(",") if s]
    base = SIM_SOLVER
    if items and items[0] in ("world", "default"):
        base = SIM_SOLVER if items[0] == "world" else SolverSettings(threads=1)
        items = items[1:]
    changes = {}
    for item in items:
        key, _, value = item.partition("=")
        try:
            changes[key.strip()] = ast.literal_eval(value.strip())
        except (ValueError, SyntaxError):
            changes[key.strip()] = value.strip()
    return base.replace(**changes)


class _Losses(logging.Handler):
    def __init__(self):
        super().__init__(logging.WARNING)
        self.count = 0

    def emit(self, record: logging.LogRecord) -> None:
        if "lost contact" in record.getMessage():
            self.count += 1


def replay(cycles, settings, scene=None):
    """Advance a fresh world's parts over ``cycles``: (poses (n, N, 3), CPU per cycle (n,),
    rigid steps, contact losses, start times (n,))."""
    from ppod_ros.device import load_device_config
    from ppod_sim.scene import load_scene
    from ppod_sim.world import SimWorld

    scene = scene or load_scene(Path(str(resources.files("ppod_sim") / "data" / "scene.yaml")))
    world = SimWorld(load_device_config(None), scene, None, port=0, tick_fps=0.0, solver=settings)
    losses = _Losses()
    logger = logging.getLogger("ppod_sim.world")
    logger.addHandler(losses)
    try:
        world.dynamics._time = cycles[0].start_time_s
        poses = np.zeros((len(cycles), len(scene.parts), 3))
        cpu = np.zeros(len(cycles))
        for k, truth in enumerate(cycles):
            c0 = time.thread_time()
            world.advance_parts(truth)
            cpu[k] = time.thread_time() - c0
            poses[k] = world.parts_truth().poses
        rigid = sum(int(g.steps.sum()) for g in world.dynamics._groups if g.kind == 1)
    finally:
        logger.removeHandler(losses)
        world.process.close()
    return poses, cpu, rigid, losses.count, np.array([c.start_time_s for c in cycles])


def deviation(poses, ref):
    """Per part: largest and final position deviation (mm) and angle deviation (deg)."""
    d = poses - ref
    mm = 1e3 * np.hypot(d[..., 0], d[..., 1])
    deg = np.degrees(np.abs((d[..., 2] + np.pi) % (2 * np.pi) - np.pi))
    return mm.max(axis=0), mm[-1], deg.max(axis=0), deg[-1]


def run(args: argparse.Namespace) -> int:
    from ppod_sim.scene import load_scene
    from ppod_sim.truth import load_cycles

    try:
        cycles = load_cycles(args.cycles)
    except (OSError, ValueError, KeyError, EOFError) as exc:  # missing, not an .npz, not a recording
        print(f"ppod bench sim_parts: {args.cycles}: not a recording of plate cycles ({exc})", file=sys.stderr)
        return 2
    if not cycles:
        print(f"ppod bench sim_parts: {args.cycles}: no cycles recorded", file=sys.stderr)
        return 2
    if args.cycles_limit:
        cycles = cycles[:args.cycles_limit]
    scene = load_scene(args.scene) if args.scene else None
    ref_settings = parse_settings(args.reference)
    names = list(args.settings)
    span = cycles[-1].start_time_s - cycles[0].start_time_s
    print(f"{len(cycles)} cycles, {span:.1f} s of device time; reference: {ref_settings.describe()}")
    ref, ref_cpu, ref_steps, ref_lost, t = replay(cycles, ref_settings, scene)
    print(f"reference: CPU {ref_cpu.sum():.2f} s, rigid steps {ref_steps}, contact losses {ref_lost}")
    rigid = [i for i, p in enumerate((scene or _demo_scene()).parts) if p.part.__class__.__name__ == "RigidPart"]
    best = {}
    for _ in range(max(1, args.repeats)):  # interleaved, so that a busy spell hits every setting
        for name in names:
            poses, cpu, steps, lost, _t = replay(cycles, parse_settings(name), scene)
            if name not in best or cpu.sum() < best[name][1].sum():
                best[name] = (poses, cpu, steps, lost)
    sec = np.floor(t - t[0]).astype(int)
    print(f"{'settings':60s} {'CPU s':>6s} {'worst 1 s':>9s} {'rigid steps':>11s} {'lost':>4s}  "
          f"max / final deviation: position mm (all parts), angle deg (rigid parts)")
    for name in names:
        poses, cpu, steps, lost = best[name]
        worst = max(cpu[sec == s].sum() for s in np.unique(sec))
        mm_max, mm_end, deg_max, deg_end = deviation(poses, ref)
        print(f"{parse_settings(name).describe()[:60]:60s} {cpu.sum():6.2f} {worst:9.2f} {steps:11d} {lost:4d}  "
              f"{mm_max.max():.4f} / {mm_end.max():.4f} mm, "
              f"{deg_max[rigid].max() if rigid else 0.0:.4f} / {deg_end[rigid].max() if rigid else 0.0:.4f} deg")
    return 0


def _demo_scene():
    from ppod_sim.scene import load_scene

    return load_scene(Path(str(resources.files("ppod_sim") / "data" / "scene.yaml")))

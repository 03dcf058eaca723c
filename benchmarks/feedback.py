"""Closed-loop acceleration error on the simulated plant: iterations to 1 %, harmonics, estimation.

For each motion (default: the packaged suite, ``ppod goal --list-presets``), the simulated device runs
at its default mismatch (gain up to 15 %, phase up to 10 degrees, 5 % cross-coupling, a 3 % third
harmonic) with accelerometer noise on, faster than real time, in this process: the waveform
generator's core sends the goal over a virtual CAN bus, the feedback loop (the accel_feedback
node's core) estimates from the device's accelerometer summaries and corrects. Reported per motion:

  open loop   ||achieved - goal|| / ||goal|| before any correction (the true plate, simulator truth)
  iter<=1%    learning iterations until the estimate's error is <= 1 %
  err@5       true error after 5 iterations (or when converged earlier, at convergence)
  out-of-goal harmonics the goal lacks, relative to the fundamental, true plate, at the end
  est vs truth  median over estimates of ||estimate - truth|| / ||goal||

Then the goals a MovePart sends one after another (rotation, sink, rotation, sinks with shifted
centres, ...) on one device, with the plant learned online and without it: the true plate's error
once each goal has ramped in with its starting correction, before any learning step, and the
iterations to 1 %.

A suite motion that the device rejects for its contact-loss margin (it was chosen to test the solver
near contact loss) runs scaled down to the largest amplitude the device accepts, marked "x0.85".

examples:
  ppod bench feedback
  ppod bench feedback --seeds 1 2 3
  ppod bench feedback --motions config/motions/LineSinkX.yaml --quick
  ppod bench feedback --sections switching --seeds 1 2
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import time
from pathlib import Path

import numpy as np

HELP = "closed-loop acceleration error on the simulated plant (iterations to 1 %, harmonics, estimation)"
_channels = itertools.count()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--motions", nargs="+", type=Path, help="MOTION.yaml files (default: the packaged suite)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[1], help="simulator seeds (default: 1)")
    parser.add_argument("--iterations", type=int, default=8, help="learning iterations per run (default 8)")
    parser.add_argument("--quick", action="store_true", help="first three motions, 5 iterations")
    parser.add_argument("--no-sequence", action="store_true", help="skip the goal-sequence section")
    parser.add_argument("--sections", nargs="+", choices=sorted(SECTIONS), default=["motions", "sequence"],
                        help="sections to run (default: motions sequence); real: the PPOD2 lab's data "
                             "(estimation against the lab, injected faults, dead acquisitions, calibration); "
                             "switching: goals switched every 1.5 s as the planner does")
    parser.add_argument("--uncalibrated", action="store_true",
                        help="feedback on the nominal layout (no array calibration) despite the sensor errors")


def suite_motions() -> list[Path]:
    from importlib import resources

    return sorted(Path(str(resources.files("ppod_ros") / "data" / "motions")).glob("*.yaml"))


_CALIBRATION: list = []
_CALIBRATED = True  # --uncalibrated clears it


def simulated_calibration():
    """The array calibration of the simulated device (its default sensor errors), made once."""
    if not _CALIBRATION:
        from ppod_ros.device import default_device_config
        from ppod_sim.calibration import calibrate_simulated_device

        _CALIBRATION.append(calibrate_simulated_device(default_device_config(), seed=97))
    return _CALIBRATION[0]


class _Rig:
    """A simulated device, the waveform generator's core and the feedback loop, in this process.

    The device runs faster than real time on a virtual CAN bus; ``plant_learning`` False keeps the
    feedback on the nominal model (every goal starts from zero correction); ``plant_model_allowance``
    replaces the device's ``limits.plant_model_allowance`` (0: corrections judged through the
    nominal plant alone).
    """

    scale = np.array([1, 1, 1, 0.1, 0.1, 0.1])  # angular axes in m/s^2 at L = 0.1 m (PHYSICS.md)

    def __init__(self, seed: int, plant_learning: bool = True, calibrated: bool = True,
                 plant_model_allowance: float | None = None):
        from ppod_ros.actuation.generator import WaveformGenerator
        from ppod_ros.actuation.planning import GoalPlanner
        from ppod_ros.can import DeviceLink, open_bus
        from ppod_ros.control.learned_plant import PlantLearningSettings
        from ppod_ros.control.online import FeedbackLoop
        from ppod_ros.device import default_device_config
        from ppod_sim.device import SimDevice

        config = default_device_config().with_can(interface="virtual", channel=f"bench-fb-{next(_channels)}")
        if plant_model_allowance is not None:  # 0: plate-side limits through the nominal plant alone
            limits = dataclasses.replace(config.limits, plant_model_allowance=plant_model_allowance)
            config = dataclasses.replace(config, limits=limits)
        self.buses = [open_bus(config.can), open_bus(config.can)]
        self.device = SimDevice(config, self.buses[0], seed=seed)
        self.link = DeviceLink(self.buses[1], config)
        self.gen = WaveformGenerator(self.link, GoalPlanner(config))
        # The device's sensors have their default (lab-like) errors; the feedback uses the array
        # calibration that ppod calibrate accel stores, made once per process on a simulated device.
        self.loop = FeedbackLoop(config, plant_learning=PlantLearningSettings(enabled=plant_learning),
                                 calibration=simulated_calibration() if calibrated and _CALIBRATED else None)
        self.summaries: list = []
        self.link.on_summary.append(self.summaries.append)

    def close(self) -> None:
        for bus in self.buses:
            bus.shutdown()

    def advance(self, seconds: float) -> None:
        device, link = self.device, self.link
        end = device.time_s + seconds
        while device.time_s < end - 1e-12:
            link.heartbeat()
            device.advance(0.05)
            link.poll()

    def true_error(self, goal) -> tuple[float, float]:
        """(relative error of the true plate, its harmonics the goal lacks over those it has)."""
        from ppod_ros.motion import acceleration_error

        truth = self.device.last_truth().accel
        g = goal.phasor_table(truth.shape[0])
        in_goal = np.abs(g).sum(axis=1) > 0
        extra = np.linalg.norm(truth[~in_goal] * self.scale) / np.linalg.norm(truth[in_goal] * self.scale)
        return acceleration_error(g, truth)[1], float(extra)

    def start(self, goal) -> None:
        """Make ``goal`` the loop's goal and send its starting correction (stored or predicted)."""
        self.loop.set_goal(goal, self.device.time_s)
        self.summaries.clear()
        initial = self.loop.initial_correction_a
        if initial is not None:
            self.gen.apply_correction(goal.key, self.loop.controller.k, initial, start=True)

    def iterate(self, goal, until, max_device_s: float = 30.0):
        """Run learning iterations until ``until(result)`` is true; yields each result with a step."""
        start_s = self.device.time_s
        while self.device.time_s - start_s < max_device_s:
            self.advance(0.05)
            for s in self.summaries:
                res = self.loop.on_summary(s.k, s.phasors, goal.frequency_hz, s.samples_per_cycle,
                                           self.device.time_s, s.table_seq, s.first_cycle)
                if res is None or res.step is None:
                    continue
                yield res
                self.gen.apply_correction(goal.key, res.step.k, res.step.correction_a,
                                          measured_accel=res.measured_accel, measured_seq=res.table_seq)
                if until(res):
                    self.summaries.clear()
                    return
            self.summaries.clear()


def run_latency(goal, seed: int, latency_s: float, iterations: int = 6, tables: bool = True,
                summary_latency_s: float | None = None, stall_s: float = 0.0) -> list[tuple[int, float, int]]:
    """``goal`` as the running stack learns it, with ``latency_s`` (device time) on each path.

    The loop takes the goal up as it starts ramping in (as accel_feedback does); every summary
    reaches the loop and every correction reaches the generator ``latency_s`` late (the CAN bridge,
    DDS, a busy node). ``tables`` False hides the summaries' table numbers from the loop (as a
    caller that does not pass them, nor the cycle indices); ``summary_latency_s`` (default
    ``latency_s``) delays the summaries alone; ``stall_s`` holds the summaries after each new
    table's first one that long and then delivers them at once (a stalled bridge or node).
    Returns ``(iteration, estimated error, device table of the estimate's last summary)`` per
    learning step.
    """
    from collections import deque

    rig = _Rig(seed)
    steps: list[tuple[int, float, int]] = []
    try:
        out = rig.gen.submit(goal)
        if not out.accepted:
            raise RuntimeError(f"{goal.name}: {out.reason}")
        rig.loop.set_goal(goal, rig.device.time_s, ramp_left_fraction=1.0)
        rig.summaries.clear()
        summaries, corrections = deque(), deque()
        last_table, held_until = [None], [-1.0]
        while rig.device.time_s < 30.0 and (not steps or steps[-1][0] < iterations):
            rig.link.heartbeat()
            rig.device.advance(0.01)
            rig.link.poll()
            now = rig.device.time_s
            lag = latency_s if summary_latency_s is None else summary_latency_s
            for s in rig.summaries:
                if stall_s and s.table_seq != last_table[0]:
                    # The first summary of a new table arrives; the next ones stall and then arrive at once.
                    last_table[0], held_until[0] = s.table_seq, now + lag + stall_s
                    summaries.append((now + lag, s))
                    continue
                summaries.append((max(now + lag, held_until[0]), s))
            rig.summaries.clear()
            while corrections and corrections[0][0] <= now:
                res = corrections.popleft()[1]
                rig.gen.apply_correction(goal.key, res.step.k, res.step.correction_a,
                                         measured_accel=res.measured_accel, measured_seq=res.table_seq)
            while summaries and summaries[0][0] <= now:
                s = summaries.popleft()[1]
                res = rig.loop.on_summary(s.k, s.phasors, goal.frequency_hz, s.samples_per_cycle, now,
                                          s.table_seq if tables else None, s.first_cycle if tables else None)
                if res is not None and res.step is not None:
                    steps.append((res.step.iteration, res.step.error_relative, s.table_seq))
                    corrections.append((now + latency_s, res))
    finally:
        rig.close()
    return steps


def switching_goals(n: int, seed: int) -> list:
    """``n`` goals as the model-predictive planner switches them: each the template designs of
    :func:`planner_sequence` with every axis's phase turned at random and 30 % of random motion
    added, fitted to the envelope with the planner's 15 % headroom, 0.5 s ramps, all named "mpc"."""
    from ppod_ros.device import default_device_config
    from ppod_ros.motion import PlateMotion
    from ppod_ros.planning.envelope import fit_envelope

    rng = np.random.default_rng(seed)
    base, config, out = planner_sequence(), default_device_config(), []
    for _ in range(n):
        P = base[rng.integers(len(base))].phasor_table(1)[0]
        P = P * np.exp(1j * rng.uniform(0, 2 * np.pi, 6)) + rng.normal(size=6) * np.abs(P).mean() * 0.3
        goal = PlateMotion(30, [1], [np.abs(P)], [np.angle(P)], ramp_time_s=0.5, name="mpc")
        out.append(fit_envelope(goal, config, 0.15)[0])
    return out


def run_switching(seed: int, goals: int = 12, dwell_s: float = 1.5, status_latency_s: float = 0.1,
                  latency_s: float = 0.05) -> list[dict]:
    """Goals switched every ``dwell_s`` as the planner does, with the running stack's latencies.

    The feedback takes each goal up ``status_latency_s`` after the generator accepts it (its status
    message) and sends the starting correction; summaries and corrections travel ``latency_s``; a
    correction is applied to whatever goal is active (the generator matches corrections by goal
    name, and the planner names every goal "mpc"). Per goal: the true plate's error at the loop's
    first learning step (``first``: all harmonics; ``first_fundamental``: the goal's own), or None
    when the goal ended before one.
    """
    import heapq

    rig = _Rig(seed)
    queue: list = []
    order = itertools.count()
    rows: dict[int, dict] = {}
    current: dict = {"goal": None, "index": -1}

    def later(delay_s: float, fn) -> None:
        heapq.heappush(queue, (rig.device.time_s + delay_s, next(order), fn))

    def take_up(index: int, goal) -> None:
        current.update(goal=goal, index=index)
        rig.loop.set_goal(goal, rig.device.time_s, ramp_left_fraction=1.0)
        initial, k = rig.loop.initial_correction_a, None if rig.loop.controller is None else rig.loop.controller.k
        if initial is not None:
            later(latency_s, lambda: rig.gen.apply_correction(None, k, initial, start=True))

    def feed(summary) -> None:
        goal = current["goal"]
        if goal is None:
            return
        res = rig.loop.on_summary(summary.k, summary.phasors, goal.frequency_hz, summary.samples_per_cycle,
                                  rig.device.time_s, summary.table_seq, summary.first_cycle)
        if res is None or res.step is None:
            return
        if current["index"] not in rows:
            truth = rig.device.last_truth().accel
            g = goal.phasor_table(1)[0]
            rows[current["index"]] = {
                "first": rig.true_error(goal)[0], "source": rig.loop.initial_source or "none",
                "first_fundamental": float(np.linalg.norm((truth[0] - g) * rig.scale) / np.linalg.norm(g * rig.scale))}
        step, accel, seq = res.step, res.measured_accel, res.table_seq
        later(latency_s, lambda: rig.gen.apply_correction(None, step.k, step.correction_a, measured_accel=accel,
                                                          measured_seq=seq))

    goals_list = switching_goals(goals, seed)
    try:
        for index, goal in enumerate(goals_list):
            if not rig.gen.submit(goal).accepted:
                continue
            later(status_latency_s, lambda i=index, g=goal: take_up(i, g))
            end = rig.device.time_s + dwell_s
            while rig.device.time_s < end:
                rig.link.heartbeat()
                rig.device.advance(0.01)
                rig.link.poll()
                for summary in rig.summaries:
                    later(latency_s, lambda s=summary: feed(s))
                rig.summaries.clear()
                while queue and queue[0][0] <= rig.device.time_s:
                    heapq.heappop(queue)[2]()
    finally:
        rig.close()
    return [{"goal": i, **rows.get(i, {"first": None})} for i in range(len(goals_list))]


def _switching_section(args: argparse.Namespace, out: Path) -> list[dict]:
    runs = [{"seed": seed, "goals": run_switching(seed)} for seed in args.seeds]
    print("\nGoals switched every 1.5 s as the planner does (random template-like goals, 0.5 s ramps, stack "
          "latencies): true error at each goal's first learning step, all harmonics (the goal's own)")
    for r in runs:
        cells = ["-" if g["first"] is None else f"{100 * g['first']:.1f} ({100 * g['first_fundamental']:.1f})"
                 for g in r["goals"]]
        print(f"  seed {r['seed']}: " + ", ".join(cells))
    return runs


#: Largest envelope ratio of a suite motion scaled down to fit the device (room for corrections).
SCALED_GOAL_RATIO = 0.85


def run_case(goal, seed: int, iterations: int) -> dict:
    """One goal on a fresh simulated device; the whole loop in this process, faster than real time."""
    from ppod_ros.motion import acceleration_error

    rig = _Rig(seed)
    try:
        base, scaled = goal, 1.0
        out = rig.gen.submit(goal)
        while not out.accepted and out.limit == "limits.contact_margin_mps2" and scaled > 0.35:
            # Suite motions near contact loss are over the device's safety margin: run the largest
            # scaled copy the device accepts (same field shape), and say so.
            scaled = round(scaled - 0.05, 2)
            goal = base.scaled(scaled)
            out = rig.gen.submit(goal)
        envelope = rig.gen.planner.envelope
        while scaled < 1.0 and scaled > 0.35 and not envelope.check_motion(goal).within(SCALED_GOAL_RATIO):
            # Corrected tables are held to the envelope too: a scaled copy keeps room for the
            # corrections of the mismatched plant (15 % gain), or the loop could not converge.
            scaled = round(scaled - 0.05, 2)
            goal = base.scaled(scaled)
            out = rig.gen.submit(goal)
        if not out.accepted:
            return {"motion": goal.name, "seed": seed, "rejected": out.reason}
        rig.advance(max(goal.ramp_time_s or 0.5, 0.5) + 0.6)
        open_loop = rig.true_error(goal)[0]
        rig.start(goal)
        t0 = time.perf_counter()
        errors, est_err, first_ok, err5 = [], [], None, None
        for res in rig.iterate(goal, lambda r: r.step.iteration >= iterations):
            truth = rig.device.last_truth().accel
            K = res.estimate.phasors.shape[0]
            T = np.zeros((K, 6), complex)
            T[: min(K, truth.shape[0])] = truth[:K]
            est_err.append(acceleration_error(T, res.estimate.phasors)[0]
                           / acceleration_error(np.zeros((K, 6)), goal.phasor_table(K))[0])
            step = res.step
            errors.append(step.error_relative)
            if first_ok is None and step.error_relative <= 0.01:
                first_ok = step.iteration
            if step.iteration == 5:
                err5 = rig.true_error(goal)[0]
        rig.advance(0.7)
        final, out_of_goal = rig.true_error(goal)
        return {"motion": goal.name, "seed": seed, "scale": scaled, "open_loop": open_loop, "iter_to_1pct": first_ok,
                "err_at_5": err5 if err5 is not None else final, "final": final, "out_of_goal": out_of_goal,
                "est_vs_truth_median": float(np.median(est_err)) if est_err else float("nan"),
                "errors": errors, "device_s": rig.device.time_s, "wall_s": time.perf_counter() - t0}
    finally:
        rig.close()


def planner_sequence() -> list:
    """The goals a MovePart sends one after another: sinks whose centre moves, rotations, a sink again.

    Designed by the field planner (30 Hz, point part mu 0.3), as the field_planner node does.
    """
    from ppod_ros.planning.design import design_field, shift_centre
    from ppod_ros.planning.specs import FieldSpec

    sink = design_field(FieldSpec.from_request("sink", [0.02, -0.02, 0.3])).motion
    rot = design_field(FieldSpec.from_request("rotation", [0.05, -0.04, -0.3])).motion
    rot2 = design_field(FieldSpec.from_request("rotation", [0.045, -0.035, -0.3])).motion
    return [rot, sink, rot2, shift_centre(sink, 0.0004, 0.0), shift_centre(sink, 0.0008, -0.0004),
            design_field(FieldSpec.from_request("sink", [0.0, 0.0, 0.3])).motion,
            shift_centre(sink, -0.0005, 0.0006)]


def run_sequence(goals, seed: int, plant_learning: bool, iterations: int = 4) -> dict:
    """Goals one after another on one device, ``iterations`` learning steps each (as the planner does).

    Reported per goal: the true plate's error once the goal's ramp has settled and its starting
    correction (predicted by the learned plant, or none) is applied, before any learning step
    (``start``), and the learning iterations to 1 % (the first iteration measures ``start``).
    """
    rig = _Rig(seed, plant_learning=plant_learning)
    rows = []
    try:
        for goal in goals:
            out = rig.gen.submit(goal)
            if not out.accepted:
                rows.append({"motion": goal.name, "rejected": out.reason})
                continue
            rig.start(goal)
            rig.advance(max(goal.ramp_time_s or 0.5, 0.5) + 0.6)
            rig.summaries.clear()  # taken during the ramp
            row = {"motion": goal.name, "start": rig.true_error(goal)[0],
                   "source": rig.loop.initial_source or "none", "iter_to_1pct": None}
            for res in rig.iterate(goal, lambda r: r.step.iteration >= iterations):
                if row["iter_to_1pct"] is None and res.step.error_relative <= 0.01:
                    row["iter_to_1pct"] = res.step.iteration
            rows.append(row)
    finally:
        rig.close()
    return {"seed": seed, "plant_learning": plant_learning, "goals": rows}


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    for name in [s for s in SECTIONS if s in args.sections]:
        if name == "sequence" and args.no_sequence:
            continue
        results[name] = SECTIONS[name](args, out)
    (out / "feedback.json").write_text(json.dumps(results, indent=1, default=float))
    print(f"\nwrote {out / 'feedback.json'}")
    return 0


def _motions_section(args: argparse.Namespace, out: Path) -> list[dict]:
    from ppod_ros.motion import PlateMotion

    global _CALIBRATED
    _CALIBRATED = not args.uncalibrated
    paths = args.motions or suite_motions()
    iterations = 5 if args.quick else args.iterations
    if args.quick:
        paths = paths[:3]
    rows = []
    for path in paths:
        goal = PlateMotion.from_yaml(path)
        if not goal.name:
            goal = PlateMotion(goal.frequency_hz, goal.k, goal.amplitude, goal.phase, name=Path(path).stem)
        for seed in args.seeds:
            row = run_case(goal, seed, iterations)
            rows.append(row)
            print(f"  {row['motion']} seed {seed}: "
                  + (f"rejected: {row['rejected']}" if "rejected" in row else
                     f"errors {[round(100 * e, 2) for e in row['errors']]} %"), flush=True)
    print("\nClosed-loop acceleration error, simulated plant at default mismatch, noise on, sensor errors on, "
          + ("nominal layout (no calibration)" if args.uncalibrated else "array calibrated (ppod calibrate accel)"))
    print(f"{'motion':22s} {'seed':>4s} {'open loop':>10s} {'iter<=1%':>9s} {'err@5':>8s} {'out-of-goal':>11s} "
          f"{'est vs truth':>12s}")
    for r in rows:
        if "rejected" in r:
            print(f"{r['motion']:22s} {r['seed']:4d}   rejected by the device limits: {r['rejected']}")
            continue
        it = "-" if r["iter_to_1pct"] is None else str(r["iter_to_1pct"])
        name = r["motion"] if r["scale"] == 1 else f"{r['motion']} x{r['scale']:.2f}"
        print(f"{name:22s} {r['seed']:4d} {100 * r['open_loop']:9.2f}% {it:>9s} {100 * r['err_at_5']:7.3f}% "
              f"{100 * r['out_of_goal']:10.3f}% {100 * r['est_vs_truth_median']:11.3f}%")
    _plot(rows, out / "feedback.png")
    print(f"wrote {out / 'feedback.png'}")
    return rows


def _sequence_section(args: argparse.Namespace, out: Path) -> list[dict]:
    return _sequences(args.seeds)


def _sequences(seeds: list[int]) -> list[dict]:
    goals = planner_sequence()
    runs = [run_sequence(goals, seed, learn) for seed in seeds for learn in (False, True)]
    print("\nGoal sequence on one device (default mismatch): error once each goal has ramped in, "
          "before learning; iterations to 1 %")
    heads = [f"seed {r['seed']} " + ("learned" if r["plant_learning"] else "nominal") for r in runs]
    print(f"{'goal':32s} " + " ".join(f"{h:>21s}" for h in heads))
    for i, goal in enumerate(goals):
        cells = []
        for r in runs:
            g = r["goals"][i]
            it = "-" if g.get("iter_to_1pct") is None else str(g["iter_to_1pct"])
            cells.append("rejected" if "rejected" in g else f"{100 * g['start']:6.2f}% / {it:>2s} it")
        print(f"{goal.name[:32]:32s} " + " ".join(f"{c:>21s}" for c in cells))
    return runs


def _plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for r in rows:
        if r.get("errors"):
            ax.semilogy(range(1, len(r["errors"]) + 1), 100 * np.array(r["errors"]), "o-", ms=3,
                        label=f"{r['motion']} ({r['seed']})")
    ax.axhline(1.0, color="k", ls="--", lw=0.8)
    ax.set_xlabel("learning iteration")
    ax.set_ylabel("error ||e|| / ||goal|| (%)")
    ax.set_title("Closed-loop error on the simulated plant (default mismatch)")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _real_section(args: argparse.Namespace, out: Path) -> dict:
    """The PPOD2 lab's saved cycles: a fresh default estimator against the lab, faults, dead data, calibration."""
    from ppod_ros.estimation import AccelEstimator, EstimationError
    from ppod_ros.estimation.calibration import MotionData, calibrate
    from ppod_ros.estimation.faults import FAULTS, inject, swap_matters
    from ppod_ros.estimation.harmonic_fit import fit_harmonics
    from ppod_ros.estimation.ppod2 import read_ppod2_json
    from ppod_ros.motion import acceleration_error

    layout, records = read_ppod2_json(REAL_DATA)
    print(f"\nReal data: {REAL_DATA.name} (PPOD2 lab, {len(records)} records, fresh AccelEstimator(layout, "
          f"harmonics=6), nominal layout)")
    print(f"{'record':12s} {'f (Hz)':>7s} {'vs lab':>8s}  dropped")
    est_rows = []
    for name, rec in records.items():
        est = AccelEstimator(layout, harmonics=6).from_cycle(rec.samples_mps2, rec.sample_rate_hz)
        lab = fit_harmonics(rec.time_s, rec.lab_estimate, rec.frequency_hz, 6).phasors
        err = acceleration_error(lab, est.table(6))[1]
        est_rows.append({"record": name, "vs_lab": err, "dropped": est.dropped})
        print(f"{name:12s} {est.frequency_hz:7.2f} {100 * err:7.2f}%  {list(est.dropped) or '-'}")
    fault_rows = {}
    same_signal = 0
    for fault, (n, _) in FAULTS.items():
        cases = caught = 0
        for name, rec in records.items():
            if name == "Zeros":
                continue
            y = rec.samples_mps2
            live = np.flatnonzero(np.sqrt(np.mean(y**2, axis=0)) >= 1.0)
            pairs = [(a, b) for i, a in enumerate(live) for b in live[i + 1:]]
            # A swap of two channels carrying nearly the same signal on this record changes nothing
            # the record can show: such pairs are not cases (swap_matters, half the larger reading).
            combos = [(c,) for c in live] if n == 1 else [p for p in pairs if swap_matters(y, *p)]
            same_signal += 0 if n == 1 else len(pairs) - len(combos)
            for chans in combos:
                cases += 1
                try:
                    est = AccelEstimator(layout, harmonics=6).from_cycle(inject(y, fault, chans, seed=int(chans[0])),
                                                                         rec.sample_rate_hz)
                except EstimationError:
                    caught += 1
                    continue
                caught += all(layout.names[c] in est.dropped for c in chans)
        fault_rows[fault] = (caught, cases)
    print("\nInjected faults on live channels (>= 1 m/s^2 RMS) of the 9 driven records: caught / cases")
    for fault, (c, n) in fault_rows.items():
        print(f"  {fault:8s} {c:4d} / {n:4d}  ({100 * c / n:.1f} %)")
    print(f"  (swapped: {same_signal} pairs of live channels not counted, their readings on that record "
          f"differing by less than half the larger: swap_matters)")
    swap_effect = _swaps_by_effect(layout, records)
    c, n = swap_effect
    print(f"  swapped, every pair of live channels whose swap moves an estimate that trusts every channel by "
          f">= {100 * SWAP_EFFECT:.0f} % (the rest move it by less): "
          f"{c} / {n} ({100 * c / n:.1f} %)")
    dead = {"all zero": lambda y: np.zeros_like(y), "stuck ADC": lambda y: np.broadcast_to(y[0], y.shape).copy(),
            "stopped": lambda y: np.vstack([y[: y.shape[0] // 2], np.broadcast_to(y[y.shape[0] // 2 - 1],
                                                                                  (y.shape[0] - y.shape[0] // 2,
                                                                                   y.shape[1]))])}
    dead_rows = {}
    for kind, kill in dead.items():
        flagged = 0
        for rec in records.values():
            try:
                AccelEstimator(layout, harmonics=6).from_cycle(kill(rec.samples_mps2), rec.sample_rate_hz)
            except EstimationError as exc:
                flagged += "dead acquisition" in str(exc)
        dead_rows[kind] = (flagged, len(records))
    print("Dead acquisitions flagged: " + ", ".join(f"{k} {f}/{n}" for k, (f, n) in dead_rows.items()))
    motions = [MotionData.from_samples(n, r.time_s, r.samples_mps2, r.frequency_hz) for n, r in records.items()
               if n != "Zeros"]
    cal = calibrate(layout, motions)
    print("\nCalibration on the real subset, each motion held out in turn (misfit = residual / reading)")
    print(f"{'held-out motion':14s} {'nominal':>9s} {'calibrated':>11s}")
    for name, v in cal.report.items():
        print(f"{name:14s} {100 * v['nominal']:8.2f}% {100 * v['calibrated']:10.2f}%")
    print("gains: " + " ".join(f"{n} {g:.3f}" for n, g in zip(cal.names, cal.gain)))
    print("axis changes (deg): " + " ".join(f"{n} {d:.1f}" for n, d in zip(cal.names, cal.axis_change_deg)))
    return {"estimation": est_rows, "faults": fault_rows, "swapped_by_effect": swap_effect, "dead": dead_rows,
            "calibration": cal.report}


#: A swap counts as a case of the effect rule when it moves the all-channel estimate by this fraction of it.
SWAP_EFFECT = 0.01


def _swaps_by_effect(layout, records) -> tuple[int, int]:
    """(caught, cases) over every pair of live channels whose swap moves the all-channel estimate >= SWAP_EFFECT."""
    from ppod_ros.estimation import AccelEstimator, EstimationError, HealthSettings
    from ppod_ros.estimation.faults import inject
    from ppod_ros.motion import acceleration_error

    trusting = HealthSettings(residual_threshold=1e12)  # no residual drops: what the swap does to the estimate
    cases = caught = 0
    for name, rec in records.items():
        if name == "Zeros":
            continue
        y = rec.samples_mps2
        base = AccelEstimator(layout, harmonics=6, health=trusting).from_cycle(y, rec.sample_rate_hz).table(6)
        live = np.flatnonzero(np.sqrt(np.mean(y**2, axis=0)) >= 1.0)
        for i, a in enumerate(live):
            for b in live[i + 1:]:
                z = inject(y, "swapped", (a, b))
                moved = AccelEstimator(layout, harmonics=6, health=trusting).from_cycle(z, rec.sample_rate_hz)
                if acceleration_error(base, moved.table(6))[1] < SWAP_EFFECT:
                    continue
                cases += 1
                try:
                    est = AccelEstimator(layout, harmonics=6).from_cycle(z, rec.sample_rate_hz)
                except EstimationError:
                    caught += 1
                    continue
                caught += all(layout.names[c] in est.dropped for c in (a, b))
    return caught, cases


def _calibration_section(args: argparse.Namespace, out: Path) -> dict:
    """Recovery of the simulated device's injected sensor errors by the calibration.

    Compared with the truth as the calibration's convention represents it (``equivalent_calibration``,
    which reads every rigid motion as the true sensors do): the directions the array cannot see are
    fixed alike on both sides. The raw truth's difference is printed too.
    """
    from ppod_ros.device import default_device_config
    from ppod_ros.estimation.calibration import equivalent_calibration
    from ppod_sim.sensors import DEFAULT_BENDING, SensorErrors

    config = default_device_config()
    cal = simulated_calibration()
    w, _ = SensorErrors.default(config.accelerometers.num_channels).sensing(
        np.asarray(config.accelerometers.position_m), np.asarray(config.accelerometers.axis))
    truth = equivalent_calibration(config.accelerometers.layout, w)
    raw_gain = np.linalg.norm(w, axis=1)
    raw_gain /= raw_gain.mean()
    raw_axis = w / np.linalg.norm(w, axis=1)[:, None]

    def angle(a, b):
        return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=1), -1, 1)))

    gerr, aerr = np.abs(cal.gain - truth.gain), angle(cal.axis, truth.axis)
    raw_g, raw_a = np.abs(truth.gain - raw_gain), angle(truth.axis, raw_axis)
    print("\nCalibration of the simulated device (default sensor errors, bending included), 6 motions,")
    print("against the truth under the calibration's convention (equivalent_calibration)")
    print(f"{'channel':10s} {'truth gain':>10s} {'fitted':>8s} {'gain err':>9s} {'axis err':>9s}   "
          f"{'convention vs raw truth':>24s}")
    for i, n in enumerate(cal.names):
        print(f"{n:10s} {truth.gain[i]:10.4f} {cal.gain[i]:8.4f} {100 * gerr[i]:8.2f}% {aerr[i]:7.2f} deg   "
              f"{100 * raw_g[i]:8.2f}% {raw_a[i]:7.2f} deg")
    print(f"max gain error {100 * gerr.max():.2f} % (tangential {100 * gerr[0::2].max():.2f} %, vertical "
          f"{100 * gerr[1::2].max():.2f} %), max axis error {aerr.max():.2f} deg")
    print(f"plate bending fitted (saddle of the vertical channels per unit p''z): cos 2theta "
          f"{100 * cal.bending[0]:+.2f} %, sin 2theta {100 * cal.bending[1]:+.2f} % (simulated: cos 2theta "
          f"{100 * DEFAULT_BENDING:.2f} % of the true readings)")
    print("unobservable (fixed by convention):")
    for u in cal.unobservable:
        print(f"  {u}")
    return {"gain_error_max": float(gerr.max()), "gain_error_max_tangential": float(gerr[0::2].max()),
            "axis_error_max_deg": float(aerr.max()), "convention_vs_raw_axis_max_deg": float(raw_a.max()),
            "convention_vs_raw_gain_max": float(raw_g.max()), "bending": [float(v) for v in cal.bending]}


REAL_DATA = Path(__file__).resolve().parents[1] / "tests" / "data" / "ppod2_real_subset.json"
SECTIONS = {"motions": _motions_section, "sequence": _sequence_section, "real": _real_section,
            "calibration": _calibration_section, "switching": _switching_section}

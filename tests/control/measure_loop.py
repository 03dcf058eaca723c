"""Print the feedback core's figures on the synthetic rig (not a test; the tests check the bounds).

    .venv/bin/python -m tests.control.measure_loop

Tables: estimation error against the rigid-body truth (LineSinkX, realistic noise, several seeds),
closed-loop error per iteration for several goals and mismatches, and the core's own time per
estimate and per update on this machine. ``ppod bench feedback`` (the lead's) runs the same against
the simulated device.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ppod_ros.control import DeviceLimits, LearningController, PlantModel, run_learning
from ppod_ros.estimation import AccelEstimator
from ppod_ros.motion import PlateMotion, acceleration_error
from tests.control.rig import LAYOUT, NOISE_MPS2, RATE_HZ, Rig
from tests.control.synthetic_plant import SyntheticPlate, mismatched_response, nominal_response
from tests.estimation.plate_sim import readings, sample_times

GOALS = {
    "LineSinkX": PlateMotion(30, [1], [[10, 0, 0, 0, 100, 0]], [[0, 0, 0, 0, 3 * math.pi / 2, 0]]),
    "rotation": PlateMotion(30, [1], [[4, 4, 0, 0, 0, 60]], [[0, math.pi / 2, 0, 0, 0, 0]]),
    "two harmonics": PlateMotion(
        30, [1, 2], [[8, 0, 2, 0, 60, 0], [2, 0, 0, 0, 10, 0]], [[0, 0, 1, 0, 4.7, 0], [1, 0, 0, 0, 2, 0]]
    ),
}
LIMITS = DeviceLimits(max_current_a=5.0, max_step_a=2.0)


def estimation_table(seeds: int = 10) -> None:
    goal = GOALS["LineSinkX"]
    t = sample_times(30, 10, RATE_HZ)
    clean = readings(goal.phasor_table(1), [1], 30, t, LAYOUT.position_m, LAYOUT.axis)
    est = AccelEstimator(LAYOUT)
    plain = AccelEstimator(LAYOUT, second_order_terms=(), gravity_mps2=0.0)
    errs, times = [], []
    for seed in range(seeds):
        r = clean + np.random.default_rng(seed).normal(0, NOISE_MPS2, clean.shape)
        t0 = time.perf_counter()
        e = est.from_samples(t, r, 30)
        times.append(time.perf_counter() - t0)
        errs.append(acceleration_error(goal.phasor_table(6), e.table(6))[1])
    noise_free = acceleration_error(goal.phasor_table(6), est.from_samples(t, clean, 30).table(6))[1]
    uncorrected = acceleration_error(goal.phasor_table(6), plain.from_samples(t, clean, 30).table(6))[1]
    print(
        f"Estimation, LineSinkX, default layout, 10 cycles at {RATE_HZ:g} Hz, noise {NOISE_MPS2} m/s^2 RMS:"
    )
    print(f"  noise-free, corrected:     {noise_free:.2e} of the goal norm")
    print(f"  noise-free, first order:   {uncorrected:.2e}")
    print(f"  noisy ({seeds} seeds):        median {np.median(errs):.2e}, max {np.max(errs):.2e}")
    print(
        f"  time per estimate:         median {1e3 * np.median(times):.1f} ms (12 channels, "
        f"{t.size} samples each)"
    )


def loop_table() -> None:
    print("\nClosed loop (nominal model; true plate 15 % gain, 10 deg phase, 5 % coupling off; 3 % added")
    print("third harmonic; noise on). Relative error after n updates (n = 0: open loop):")
    print(
        f"  {'goal':14s} {'gain':>5s} {'phase':>6s}  "
        + " ".join(f"{n:>7d}" for n in range(7))
        + "   to<=1%  out-of-goal  ms/update"
    )
    nominal = PlantModel.from_response(nominal_response, 30.0, [1, 2, 3])
    for name, goal in GOALS.items():
        for gain, phase in [(1.15, 10.0), (0.85, -10.0), (1.15, -10.0), (0.85, 10.0)]:
            ctrl = LearningController(goal, nominal, LIMITS)
            plate = SyntheticPlate(mismatched_response(gain, phase, 0.05, seed=0), 30.0, third=0.03, seed=0)
            rig = Rig(plate, ctrl.feedforward_a, seed=0)
            updates = []
            original = ctrl.update

            def timed(measured, original=original, updates=updates):
                t0 = time.perf_counter()
                out = original(measured)
                updates.append(time.perf_counter() - t0)
                return out

            ctrl.update = timed
            res = run_learning(ctrl, rig.measure, max_iterations=7, stop_when_converged=False)
            errs = res.errors()
            n_ok = next((i for i, e in enumerate(errs) if e <= 0.01), None)
            ogr = res.steps[n_ok].out_of_goal_relative if n_ok is not None else float("nan")
            print(
                f"  {name:14s} {gain:5.2f} {phase:+6.0f}  "
                + " ".join(f"{e:7.4f}" for e in errs)
                + f"   {n_ok!s:>6s}  {ogr:11.4f}  {1e3 * np.median(updates):9.2f}"
            )


if __name__ == "__main__":
    estimation_table()
    loop_table()

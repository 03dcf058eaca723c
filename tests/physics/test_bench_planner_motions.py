"""``ppod bench solver --planner-motions``: its rigid baseline, its recording and its sampling."""

import math

import numpy as np

import ppod_ros.physics as physics
from ppod_bench.solver import CONFIG as CONFIG_DIR
from ppod_bench.solver_planner import collect_planner_calls, motion_class, rigid_baseline_average, sample_calls
from ppod_ros.motion import PlateMotion
from ppod_ros.parts import PointPart, RigidPart, load_part
from ppod_ros.physics import PRESETS, solve_field


def test_the_rigid_baseline_written_from_physics_md_agrees_with_the_solver():
    motion = PlateMotion.from_yaml(CONFIG_DIR / "motions" / "RigidU1.yaml")
    part = load_part(CONFIG_DIR / "parts" / "published_rigid.yaml")
    q = [0.02, 0.01, 0.3]                                    # the part slides all cycle here
    ours = solve_field(motion, part, np.array([q]), PRESETS["accurate"])
    base, periods, finished = rigid_baseline_average(motion, part, q, rtol=1e-7, atol=1e-10, tol=1e-7)
    assert finished and ours.valid[0] and 2 <= periods < 200
    assert abs(ours.velocity[0][0]) > 0.02                   # a real motion, not two zeros agreeing
    assert np.abs(base[:2] - ours.velocity[0][:2]).max() <= 1e-6
    assert abs(base[2] - ours.velocity[0][2]) <= 1e-5


def test_the_rigid_baseline_flags_a_contact_lifting_off():
    part = load_part(CONFIG_DIR / "parts" / "published_rigid.yaml")
    amp = np.zeros((1, 6))
    amp[0, 2] = 15.0                                          # vertical 15 m/s^2 > g: the part leaves the plate
    amp[0, 0] = 10.0
    motion = PlateMotion(30.0, [1], amp, np.zeros((1, 6)))
    base, periods, finished = rigid_baseline_average(motion, part, [0.0, 0.0, 0.0], rtol=1e-6, atol=1e-9, tol=1e-6)
    assert finished and periods == 1 and np.isnan(base).all()


def test_the_rigid_baseline_stops_at_its_budget_with_a_lower_bound_flag():
    motion = PlateMotion.from_yaml(CONFIG_DIR / "motions" / "RigidU1.yaml")
    part = load_part(CONFIG_DIR / "parts" / "published_rigid.yaml")
    _base, periods, finished = rigid_baseline_average(motion, part, [0.02, 0.01, 0.3], budget_s=0.0)
    assert not finished and periods == 0


def test_planner_motion_names_map_to_their_classes():
    assert [motion_class(n) for n in ("sink@0", "carry@2", "turn-@1", "turn+@0", "spin+@1", "spin", "orient@0",
                                      "line@0,1", "mpc", "", "sink(0, 0, 0.3)")] == [
        "sink", "carry", "turn", "turn", "spin", "spin", "orient", "line", "mpc", "mpc", "design"]


def _motion(name, a):
    amp = np.zeros((1, 6))
    amp[0, 0], amp[0, 5] = 5.0, a
    return PlateMotion(30.0, [1], amp, np.zeros((1, 6)), name=name)


def test_sampling_spreads_over_classes_per_part_kind_and_skips_repeats_and_rest():
    point, rigid = PointPart(0.3), load_part(CONFIG_DIR / "parts" / "published_rigid.yaml")
    sinks = [_motion("sink@0", 10.0 + k) for k in range(5)]
    calls = [(sinks + [_motion("turn+@0", 50.0), PlateMotion.zero(30.0, name="rest")], point, np.zeros((1, 2))),
             (sinks[:2] + [_motion("mpc", 70.0)], point, np.zeros((1, 2))),     # repeats of two sinks
             ([_motion("spin", 80.0)], rigid, np.zeros((1, 3)))]
    out = sample_calls(calls, per_kind=3, seed=0)
    kinds = [s[0] for s in out]
    assert kinds.count("point") == 3 and kinds.count("rigid") == 1
    assert {s[1] for s in out if s[0] == "point"} == {"sink", "turn", "mpc"}    # one per class first
    keys = [s[2].key for s in out]
    assert len(keys) == len(set(keys)) and not any(s[2].is_zero() for s in out)
    assert isinstance(out[-1][3], RigidPart) and out[-1][4].shape == (1, 3)


def test_recording_the_planner_captures_its_solver_calls_and_restores_the_solver():
    real = physics.solve_fields
    calls = collect_planner_calls([1], scenes=1, seconds=1.0)
    assert physics.solve_fields is real
    assert calls, "the planner made no solver call"
    for motions, part, cfg in calls:
        assert motions and cfg.ndim == 2 and cfg.shape[1] == (3 if isinstance(part, RigidPart) else 2)
    names = {motion_class(m.name) for motions, _, _ in calls for m in motions if not m.is_zero()}
    assert "sink" in names and math.isfinite(len(names))

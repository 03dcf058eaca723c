"""Local probes (MpcSettings.local_probes, MultiTask._probe_velocities): a point part feels the plate
only at its own point, so its Gauss-Newton columns along the plate's rotation inputs follow from its
columns along the translation inputs (the chain rule), and only the translation probes are solved
for point parts. Model predictions only: no wall-clock assertions."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

import ppod_ros.planning.mpc as mpc
from ppod_bench import planner as bench
from ppod_ros.errors import ConfigError
from ppod_ros.parts import PointPart, published_rigid_part
from ppod_ros.planning.mpc import MpcSettings, MultiTask, PartGoal
from ppod_ros.planning.predict import predict_velocities

PARTS = [published_rigid_part(), PointPart(0.3), PointPart(0.25)]
GOALS = [PartGoal(0, 0.02, -0.02, 0.0, 2e-3, np.radians(3)), PartGoal(1, -0.03, 0.02, None, 2e-3),
         PartGoal(2, 0.03, 0.03, None, 2e-3)]
POSES = np.array([[-0.03, 0.03, 1.0], [0.035, -0.02, 0.0], [-0.01, -0.04, 0.0]])


def _probes(task: MultiTask) -> list:
    """The probes of a Gauss-Newton step over two harmonics from a sink moved off the centre, with
    a second harmonic, as ``MultiTask._refine`` builds them."""
    v = mpc._to_vector(mpc.moved(task._base("sink"), 0.01, -0.005), 2)
    v[6:12] = 0.05 * v[:6]
    v[18:24] = -0.04 * v[12:18]
    n, fd = v.size, task.settings.fd_step
    return [mpc._to_motion(v, 30.0, 2)] + [mpc._to_motion(v + fd * np.eye(n)[j], 30.0, 2) for j in range(n)]


def test_the_rotation_columns_of_point_parts_follow_from_the_translation_probes():
    task = MultiTask(PARTS, GOALS, timeout_s=30.0, settings=MpcSettings(local_probes=True))
    probes = _probes(task)
    vel, ok = task._probe_velocities(probes, POSES)
    assert vel.shape == (25, 3, 3) and ok.all()
    fd = task.settings.fd_step
    axis = np.arange(24) % 6
    for row, part in ((1, PARTS[1]), (2, PARTS[2])):
        solved, valid = predict_velocities(probes, part, POSES[row:row + 1, :2], task._probe_solver())
        assert valid.all()
        J_solved = (solved[1:, 0] - solved[0, 0]) / fd          # (24, 2): every probe solved
        J_local = (vel[1:, row, :2] - vel[0, row, :2]) / fd
        # The translation columns are the solved probes themselves (to the solver's tolerance: the
        # calls start from different warm starts).
        np.testing.assert_allclose(vel[1:, row, :2][axis < 3], solved[1:, 0][axis < 3], rtol=0, atol=1e-5)
        # The rotation columns agree with the solved probes to the finite differences' accuracy
        # (the probes are the same size in the inputs, not at the part's point).
        big = np.abs(J_solved).max()
        assert big > 1e-3
        err = np.abs(J_local - J_solved)[axis >= 3]
        assert err.max() <= 0.03 * big
        # ... and are not trivially the translation columns or zero.
        assert np.abs(J_local[axis >= 3]).max() > 0.2 * big
    # The rigid part's rows are solved for every probe (its contacts feel the whole plate motion).
    assert np.all(np.abs(vel[1:, 0] - vel[0, 0]).max(axis=1) > 0)


def test_point_parts_are_solved_for_the_translation_probes_only(monkeypatch):
    solved = []
    real = mpc.predict_velocities

    def record(motions, part, cfg, settings=None, **kw):
        solved.append((part.kind, len(motions)))
        return real(motions, part, cfg, settings, **kw)

    monkeypatch.setattr(mpc, "predict_velocities", record)
    for local, point_probes in ((True, 12), (False, 24)):
        task = MultiTask(PARTS, GOALS, timeout_s=30.0, settings=MpcSettings(local_probes=local))
        probes = _probes(task)
        solved.clear()
        if local:
            task._probe_velocities(probes, POSES)
        else:
            task._velocities(probes, POSES, True)
        counts = {}
        for kind, m in solved:
            counts[kind] = counts.get(kind, 0) + m
        # The start is solved for every part once (both point parts share one call per model).
        assert counts["rigid"] == 25
        assert counts["point"] == 2 * (1 + point_probes)


def test_a_step_with_local_probes_plans_a_motion_for_three_parts():
    task = MultiTask(PARTS, GOALS, timeout_s=30.0, settings=MpcSettings(local_probes=True))
    out = task.step(0.0, POSES)
    assert out.motion is not None and task.plan_searched[-1]


def test_the_setting_is_a_bool():
    assert isinstance(MpcSettings().local_probes, bool)
    with pytest.raises(ConfigError, match="local_probes"):
        MpcSettings(local_probes="yes")


def test_the_benchmark_reads_planner_settings_as_name_value_pairs(tmp_path):
    s = bench.mpc_settings(["local_probes=false", "line_search=best", "fd_step=0.05"])
    assert (s.local_probes, s.line_search, s.fd_step) == (False, "best", 0.05)
    # A number without a dot (YAML 1.1 reads 1e-3 as text) is the number.
    assert bench.mpc_settings(["fd_step=3e-2"]).fd_step == 0.03
    for bad, match in ((["local_probs=true"], "unknown MpcSettings field 'local_probs'"),
                       (["local_probes"], "expected NAME=VALUE"), (["fd_step=-1"], "fd_step"),
                       (["local_probes=maybe"], "local_probes")):
        with pytest.raises(ConfigError, match=match):
            bench.mpc_settings(bad)
    args = argparse.Namespace(sections=["multipart"], quick=True, seed=0, out=str(tmp_path), counts=[1],
                              scenes=1, scene_seconds=1.0, planners=["mpc"], mpc=["local_probs=1"])
    with pytest.raises(ConfigError, match="local_probs"):
        bench.run(args)
    args.mpc, args.paired = [], ["local_probs=1"]
    with pytest.raises(ConfigError, match="--paired: unknown MpcSettings field 'local_probs'"):
        bench.run(args)


def test_the_benchmark_pairs_the_planner_with_a_copy_on_the_same_states(tmp_path, capsys):
    args = argparse.Namespace(sections=["multipart"], quick=True, seed=0, out=str(tmp_path), counts=[3], scenes=1,
                              scene_seconds=3.0, planners=["mpc"], mpc=[], paired=["local_probes=false"])
    assert bench.run(args) == 0
    out = capsys.readouterr().out
    assert "multipart 3, paired" in out and "with local_probes=false" in out
    result = json.loads((tmp_path / "planner.json").read_text())
    assert result["paired_settings"] == ["local_probes=false"] and result["mpc_settings"] == []
    (row,) = result["multipart"]
    pairs = row["plan_cpu_paired_ms"]
    # A pair per step both searched (the first step, which pays the designs, left out).
    assert 1 <= len(pairs) <= len(row["plan_cpu_searched_ms"])
    assert all(len(p) == 2 and p[0] > 0 and p[1] > 0 for p in pairs)
    assert all(p[0] in row["plan_cpu_searched_ms"] for p in pairs)

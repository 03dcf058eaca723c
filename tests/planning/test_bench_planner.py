"""The planner benchmark runs its sections and writes what it reports (no timing assertions)."""

import argparse
import json

import pytest

from ppod_bench import planner as bench


def test_the_benchmark_runs_sensorless_and_physics_sections(tmp_path, capsys):
    args = argparse.Namespace(sections=["sensorless", "physics"], quick=True, seed=0, out=str(tmp_path))
    assert bench.run(args) == 0
    out = capsys.readouterr().out
    assert "Summary" in out and "target >= 20x" in out
    result = json.loads((tmp_path / "planner.json").read_text())
    (point,) = result["sensorless"]
    assert point["starts"] == 9 and point["max_error_mm"] <= 0.5 and point["hops"] == 0
    assert [r["on_plate"] for r in result["physics"]] == [10, 10]
    assert all(r["device_s"] == 5.0 and r["real_time_factor"] > 0 for r in result["physics"])
    assert (tmp_path / "planner.png").stat().st_size > 1000


def test_the_multipart_section_runs_both_planners_on_the_same_scenes(tmp_path, capsys):
    args = argparse.Namespace(sections=["multipart"], quick=True, seed=0, out=str(tmp_path), counts=[1], scenes=1,
                              scene_seconds=15.0)
    assert bench.run(args) == 0
    out = capsys.readouterr().out
    assert "multipart 1, mpc" in out and "multipart 1, template" in out
    result = json.loads((tmp_path / "planner.json").read_text())
    assert result["plant_learning"] == "learner"   # the feedback's own plant learner (--plant-learning)
    rows = result["multipart"]
    assert [r["planner"] for r in rows] == ["mpc", "template"]
    mpc = rows[0]
    assert mpc["count"] == 1 and len(mpc["parts"]) == 1 and 0.2 <= mpc["parts"][0]["mu"] <= 0.45
    assert len(mpc["switch_deviation_mm"]) == 1 and mpc["device_s"] <= 16.0
    # The worst over every switch is the worse of the first two motions' and the later ones'.
    assert mpc["switch_deviation_mm"][0] == pytest.approx(max(mpc["switch_deviation_first2_mm"][0],
                                                              mpc["switch_deviation_later_mm"][0]))
    assert "first two motions median" in out
    assert all(t > 0 for t in mpc["plan_ms"])
    # The planning thread's CPU per replanning step beside the wall time (load-independent).
    assert len(mpc["plan_cpu_ms"]) == len(mpc["plan_ms"]) and all(t > 0 for t in mpc["plan_cpu_ms"])
    assert "thread CPU median" in out
    # The steps that searched the candidates, apart (the others kept the motion within its dwell).
    assert 0 < len(mpc["plan_cpu_searched_ms"]) < len(mpc["plan_cpu_ms"])
    assert set(mpc["plan_cpu_searched_ms"]) <= set(mpc["plan_cpu_ms"]) and "steps that searched" in out

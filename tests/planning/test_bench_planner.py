"""The planner benchmark runs its sections and writes what it reports (no timing assertions)."""

import argparse
import json

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

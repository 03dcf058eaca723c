"""The tracker benchmark's scoring runs and reports sane figures on a short sequence."""

import argparse
import json

from ppod_bench import tracker as bench
from ppod_sim.camera.scenarios import make_scene


def test_the_benchmark_scores_a_short_sequence(tmp_path, capsys):
    args = argparse.Namespace(parts=[5], frames=4, seed=3, quick=False, all_cores=True, out=str(tmp_path), camera=None)
    assert bench.run(args) == 0
    out = capsys.readouterr().out
    assert "posRMSmm" in out and "targets:" in out
    row = json.loads((tmp_path / "tracker.json").read_text())["rows"][0]
    assert row["parts"] == 5 and row["id_swaps"] == 0 and row["tracks_created"] == 5
    assert row["pos_rms_mm"] < 0.2 and row["theta_rms_deg"] < 0.3
    assert (tmp_path / "tracker.png").stat().st_size > 1000


def test_benchmark_scenes_never_let_parts_overlap():
    for n in (1, 5, 10, 20):
        scene = make_scene(n, seed=n)
        assert min(scene.min_clearance_m(0.05 * k) for k in range(200)) >= 0.001 - 1e-9


def test_the_benchmark_renders_and_tracks_with_a_camera_file(tmp_path, capsys, stack_camera_path):
    # --camera: the stack's own 640 x 512 camera (where the plate calibration's corner window once
    # cost 0.14-0.20 mm of position RMS).
    args = argparse.Namespace(parts=[1], frames=6, seed=3, quick=False, all_cores=True, out=str(tmp_path),
                              camera=stack_camera_path)
    assert bench.run(args) == 0
    assert "rendered 640x512 sequences" in capsys.readouterr().out
    row = json.loads((tmp_path / "tracker.json").read_text())["rows"][0]
    assert row["tracks_created"] == 1 and row["pos_rms_mm"] < 0.1

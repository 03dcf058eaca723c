"""``ppod calibrate accel``: real data in, a per-device calibration out; bad input is one line."""

import json
from pathlib import Path

import numpy as np

from ppod_nodes.cli.main import main
from ppod_ros.estimation.calibration import load_calibration
from ppod_ros.estimation.ppod2 import read_ppod2_json

DATA = Path(__file__).resolve().parents[1] / "data" / "ppod2_real_subset.json"


def test_calibrating_the_real_subset_stores_a_calibration_per_device_and_prints_the_cross_validation(
        tmp_path, capsys):
    assert main(["calibrate", "accel", "--ppod2-json", str(DATA), "--device-id", "ppod2",
                 "--cache-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "skipping Zeros" in out and "held-out motion" in out and "common gain" in out
    cal = load_calibration(tmp_path, "ppod2")
    assert cal.names == read_ppod2_json(DATA)[0].names
    assert abs(np.mean(cal.gain) - 1) < 1e-9
    assert len(cal.report) == 9


def test_too_few_motions_are_refused_in_one_line(tmp_path, capsys):
    data = json.loads(DATA.read_text())
    data["signals"] = {k: data["signals"][k] for k in ("TransX", "Zeros")}
    src = tmp_path / "few.json"
    src.write_text(json.dumps(data))
    assert main(["calibrate", "accel", "--ppod2-json", str(src), "--no-store"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "need at least 2" in err[0]


def test_no_input_is_a_one_line_error(capsys):
    assert main(["calibrate", "accel"]) == 2
    assert "give exactly one input" in capsys.readouterr().err

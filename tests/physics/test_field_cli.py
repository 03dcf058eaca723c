"""`ppod field`: the FORMATS.md contract (JSON layout, grid order, defaults), plots and bad input."""

import json

import numpy as np
import pytest

from ppod_nodes.cli.main import main
from ppod_ros.parts import published_rigid_part

LINESINKX = ("name: LineSinkX\nfrequency_hz: 30\nharmonics:\n"
             "  - {k: 1, amplitude: [10, 0, 0, 0, 100, 0], phase: [0, 0, 0, 0, 4.71238898, 0]}\n")


@pytest.fixture
def motion(tmp_path):
    path = tmp_path / "LineSinkX.yaml"
    path.write_text(LINESINKX)
    return path


def test_point_field_json_follows_formats_md_with_x_fastest_and_the_published_values(tmp_path, motion):
    out = tmp_path / "f.json"
    assert main(["field", str(motion), "--x", "-0.05", "0.05", "3", "--y", "0", "0.02", "2",
                 "--json", str(out), "--plot", str(tmp_path / "f.png")]) == 0
    data = json.loads(out.read_text())
    assert {"configs", "velocity", "valid", "reason", "seconds"} <= set(data)
    assert np.allclose(data["configs"], [[-0.05, 0], [0, 0], [0.05, 0], [-0.05, 0.02], [0, 0.02], [0.05, 0.02]])
    assert all(data["valid"]) and data["reason"] == [None] * 6
    v = np.array(data["velocity"])
    assert v.shape == (6, 2)
    # Line sink: towards x = 0, odd in x, nothing along y (PHYSICS.md: v_x about -0.28 x).
    assert v[2, 0] < 0 < v[0, 0] and abs(v[1, 0]) < 1e-6 and np.allclose(v[:, 1], 0, atol=1e-6)
    assert (tmp_path / "f.png").read_bytes()[:4] == b"\x89PNG"


def test_rigid_field_defaults_to_eight_angles_and_mu_with_a_rigid_part_is_an_error(tmp_path, motion, capsys):
    import yaml

    part = tmp_path / "rigid.yaml"
    part.write_text(yaml.safe_dump(published_rigid_part().to_dict()))
    out = tmp_path / "r.json"
    assert main(["field", str(motion), "--part", str(part), "--x", "0", "0", "1", "--y", "0", "0", "1",
                 "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert np.allclose(np.array(data["configs"])[:, 2], np.arange(8) * 2 * np.pi / 8)
    assert all(v is None or len(v) == 3 for v in data["velocity"])
    assert main(["field", str(motion), "--part", str(part), "--mu", "0.5"]) == 2
    assert "mu" in capsys.readouterr().err


def test_bad_motion_files_are_one_line_errors_naming_the_field(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text(LINESINKX.replace("frequency_hz: 30", "frequency_hz: -5"))
    assert main(["field", str(bad)]) == 2
    assert "frequency_hz" in capsys.readouterr().err
    unknown = tmp_path / "unknown.yaml"
    unknown.write_text(LINESINKX + "colour: red\n")
    assert main(["field", str(unknown)]) == 2
    assert "colour" in capsys.readouterr().err


def test_several_motion_files_give_one_field_json_each_and_one_line_each_on_stdout(tmp_path, motion, capsys):
    sink = tmp_path / "Sink.yaml"
    sink.write_text("name: Sink\nfrequency_hz: 30\nharmonics:\n"
                    "  - {k: 1, amplitude: [10, 10, 0, 100, 100, 0], "
                    "phase: [0, 1.57079633, 0, 3.14159265, 4.71238898, 0]}\n")
    grid = ["--x", "-0.05", "0.05", "3", "--y", "0", "0.02", "2"]
    assert main(["field", str(motion), str(sink), *grid, "--json", str(tmp_path / "out"), "--quiet"]) == 0
    files = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert files == ["LineSinkX.json", "Sink.json"]
    one = tmp_path / "single.json"
    assert main(["field", str(sink), *grid, "--json", str(one), "--quiet"]) == 0
    single = json.loads(one.read_text())
    batch = json.loads((tmp_path / "out" / "Sink.json").read_text())
    assert batch["configs"] == single["configs"] and batch["motion"] == "Sink"
    assert np.allclose(np.array(batch["velocity"], float), np.array(single["velocity"], float), atol=1e-12)
    capsys.readouterr()
    assert main(["field", str(motion), str(sink), *grid, "--json", "-", "--quiet"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert [json.loads(line)["motion"] for line in lines] == ["LineSinkX", "Sink"]

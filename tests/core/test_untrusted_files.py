"""Files are untrusted input: every bad motion, part or device file is a one-line ConfigError."""

import warnings

import pytest

from ppod_ros.config.fields import MAX_YAML_BYTES, parse_yaml_text
from ppod_ros.device import load_device_config
from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion
from ppod_ros.parts import load_part

MOTION = "frequency_hz: 30\nharmonics:\n  - k: 1\n    amplitude: [{a}, 0, 0, 0, 0, 0]\n    phase: [0, 0, 0, 0, 0, 0]\n"
BOMB = "".join(f"{c}: &{c} [{', '.join(['*' + p] * 9) if p.strip() else '1'}]\n"
               for p, c in zip(" abcdefgh", "abcdefghi")) + "frequency_hz: *i\n"


@pytest.mark.parametrize(
    "content, match",
    [
        ("name: caf\xe9\nfrequency_hz: 30\n".encode("latin-1"), "not UTF-8"),
        ("name: x\nfrequency_hz: 30\n".encode("utf-16"), "not UTF-8"),
        (bytes(range(256)) * 4, "not UTF-8"),
        (b"name: x\x00\nfrequency_hz: 30\n", "NUL"),
        (("a: " + "[" * 5000 + "]" * 5000 + "\n").encode(), "nested deeper"),
        (BOMB.encode(), "aliases"),
        (b"frequency_hz: 30\nfrequency_hz: 40\nharmonics: []\n", "duplicate key 'frequency_hz' \\(line 2\\)"),
        (MOTION.format(a="true").encode(), "boolean"),
        (b"frequency_hz: [30\n", "not valid YAML"),
        (b"name: x\n" + b"# padding\n" * (MAX_YAML_BYTES // 10 + 1), "more than"),
    ],
)
def test_a_bad_motion_file_is_one_line_naming_the_file(tmp_path, content, match):
    path = tmp_path / "motion.yaml"
    path.write_bytes(content)
    with pytest.raises(ConfigError, match=match) as info:
        PlateMotion.from_yaml(path)
    assert "\n" not in str(info.value) and str(path) in str(info.value) and len(str(info.value)) < 400


def test_the_same_checks_guard_parts_and_device_descriptions(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_bytes(("a: " + "[" * 3000 + "]" * 3000 + "\n").encode())
    for loader in (load_part, load_device_config):
        with pytest.raises(ConfigError, match="nested deeper"):
            loader(bad)


def test_exponents_without_a_dot_are_numbers_and_booleans_are_not():
    motion = PlateMotion.from_yaml_text(MOTION.format(a="1e-5"))
    assert motion.amplitude[0, 0] == pytest.approx(1e-5)
    assert parse_yaml_text("x: 2E+3\ny: -1e-5\nz: '1e-5'\n", "t") == {"x": 2000.0, "y": -1e-5, "z": "1e-5"}
    with pytest.raises(ConfigError, match="boolean"):
        PlateMotion.from_yaml_text(MOTION.format(a="false"))


def test_ppod_field_refuses_a_grid_too_large_up_front_and_never_reports_nan_as_valid(tmp_path, capsys):
    import json

    from ppod_nodes.cli.main import main

    motion = tmp_path / "m.yaml"
    motion.write_text(MOTION.format(a="1"))
    assert main(["field", str(motion), "--x", "0", "1", "100000", "--y", "0", "1", "100000"]) == 2
    err = capsys.readouterr().err
    assert "more than the" in err and err.strip().count("\n") == 0
    tiny = tmp_path / "tiny.yaml"
    tiny.write_text(MOTION.format(a="1").replace("frequency_hz: 30", "frequency_hz: 1e-160"))
    out = tmp_path / "f.json"
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)   # the overflow is reported as invalid rows, not warned
        assert main(["field", str(tiny), "--x", "0", "0.01", "2", "--y", "0", "0", "1", "--json", str(out),
                     "--quiet"]) == 0
    data = json.loads(out.read_text(), parse_constant=lambda c: pytest.fail(f"invalid JSON constant {c}"))
    assert not any(data["valid"]) and all(v is None for v in data["velocity"])

"""`ppod replay` reads recordings as untrusted input: every truncated, empty or foreign file is one line."""

from pathlib import Path

import pytest

from ppod_ros.errors import ConfigError

pytestmark = pytest.mark.ros

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "session_linesinkx.mcap"


def test_every_truncation_empty_and_non_mcap_file_is_a_config_error(tmp_path):
    from ppod_nodes.record.replay import plan_replay

    data = FIXTURE.read_bytes()
    cuts = sorted({0, 1, 7, 8, 9, 100} | set(range(0, len(data), max(1, len(data) // 60))))
    path = tmp_path / "cut.mcap"
    for n in cuts:
        path.write_bytes(data[:n])
        try:
            plan_replay(path)
        except ConfigError as exc:
            assert "\n" not in str(exc)
    path.write_bytes(b"name: not a recording\n")
    with pytest.raises(ConfigError, match="not a readable MCAP"):
        plan_replay(path)
    flipped = bytearray(data)
    for i in range(9, len(flipped), max(1, len(flipped) // 200)):
        flipped[i] ^= 0x5A
    path.write_bytes(bytes(flipped))
    try:
        plan_replay(path)
    except ConfigError as exc:
        assert "\n" not in str(exc)


def test_ppod_replay_answers_a_truncated_file_with_exit_2_and_one_line(tmp_path):
    import subprocess
    import sys

    path = tmp_path / "cut.mcap"
    path.write_bytes(FIXTURE.read_bytes()[:5000])
    out = subprocess.run([sys.executable, "-m", "ppod_nodes.cli.main", "replay", str(path), "--info"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert out.stderr.strip().count("\n") == 0 and "not a readable MCAP" in out.stderr

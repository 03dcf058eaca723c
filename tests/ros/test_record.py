"""`ppod record` writes MCAP with ROS 2 serialization that the mcap-ros2 decoder and rclpy read back."""

import pytest

from tests.ros.helpers import ROOT, ppod

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_record_writes_a_readable_mcap_of_a_running_talker(tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from ppod_nodes.record.mcap_io import read_mcap, read_metadata

    cfg = tmp_path / "talker.yaml"
    cfg.write_text((ROOT / "tests" / "support" / "two_nodes.yaml").read_text()
                   .replace("{rate_hz: 20.0}", "{rate_hz: 20.0, topic: /ppod/test_talk}"))
    stack = ppod("up", "--config", str(cfg), "--only", "motion_talker")
    out = tmp_path / "session.mcap"
    try:
        stack.wait_for("all nodes up", 60)
        rec = ppod("record", str(out), "--duration", "6")  # 120 messages; discovery may take seconds under load
        assert rec.wait(60) == 0, rec.output
    finally:
        stack.p.send_signal(2)
        stack.wait(30)
    msgs = [m for m in read_mcap(out) if m.topic == "/ppod/test_talk"]
    assert len(msgs) >= 20, len(msgs)
    decoded = [m.decode() for m in msgs]
    counts = [int(d.harmonics[0].amplitude[0]) for d in decoded]
    assert counts == sorted(counts) and len(set(counts)) == len(counts)
    assert decoded[0].name.startswith("talk-")
    # An independent decoder (the one Foxglove's Python tooling uses) reads the same file.
    with open(out, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        names = [dm.name for _, ch, _, dm in reader.iter_decoded_messages() if ch.topic == "/ppod/test_talk"]
    assert names == [d.name for d in decoded]
    assert read_metadata(out)["ppod"]["recorded_by"] == "ppod record"

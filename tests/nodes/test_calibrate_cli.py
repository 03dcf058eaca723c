"""``ppod calibrate accel``: real data in, a per-device calibration out; bad input is one line."""

import json
import time
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


def _six_motions(per_motion):
    """Per-cycle summaries of six rigid motions on the packaged device's layout, read by channels with
    known gain errors (mean 1): (layout, frequency, k, rows (n, K, C), motion of each row, gains)."""
    from ppod_ros.device import default_device_config
    from ppod_ros.motion import GRAVITY_MPS2

    layout = default_device_config().accelerometers.layout
    C, freq, k = layout.num_channels, 38.0, np.array([1, 2])
    rng = np.random.default_rng(3)
    gain = 1 + 0.05 * rng.uniform(-1, 1, C)
    gain /= gain.mean()
    rows, seg = [], []
    for m in range(6):
        U = np.zeros((k.size, 6), complex)
        U[0] = rng.normal(size=6) + 1j * rng.normal(size=6)
        U[0, m] += 3.0  # each motion leads in one direction
        Y = np.stack([layout.measurement_matrix(2 * np.pi * freq * kk, GRAVITY_MPS2) @ U[i] for i, kk in enumerate(k)])
        for _ in range(per_motion):
            rows.append(Y * gain + 1e-5 * rng.normal(size=Y.shape))
            seg.append(m)
    return layout, freq, k, rows, seg, gain


def _check_calibration(tmp_path, device_id, layout, gain):
    cal = load_calibration(tmp_path, device_id)
    assert cal.names == tuple(layout.names)
    # Every held-out motion is explained better by the calibration fitted on the other five, and the
    # gains come back up to what the coplanar array cannot see (docs/feedback.md, "unobservable").
    assert len(cal.report) == 6
    assert all(v["calibrated"] < 0.5 * v["nominal"] for v in cal.report.values()), cal.report
    np.testing.assert_allclose(cal.gain, gain, atol=0.025)


def test_an_mcap_of_recorded_summaries_over_six_motions_calibrates_the_device(ros, tmp_path, capsys):
    # What accel_feedback publishes (AccelSummary on ppod/accel_summaries), recorded as ppod record
    # does, read back by ppod calibrate accel, which splits it into steady motions.
    from ppod_msgs.msg import AccelSummary

    from ppod_nodes.common import qos, topics
    from ppod_nodes.record.mcap_io import McapRecorder

    layout, freq, k, rows, _, gain = _six_motions(6)
    topic = "/" + topics.ACCEL_SUMMARIES
    pub = ros.helper.create_publisher(AccelSummary, topic, qos.STREAM)
    path = tmp_path / "session.mcap"
    recorder = McapRecorder(ros.helper, path, lambda t, _type: t == topic, discovery_period_s=0.2)
    try:
        assert ros.wait_until(lambda: topic in recorder._subs, 10)
        time.sleep(0.5)  # the recorder's subscription matched
        for Y in rows:
            pub.publish(AccelSummary(frequency_hz=freq, samples_per_cycle=256, channels=list(layout.names),
                                     k=[int(x) for x in k], real_mps2=Y.real.ravel().tolist(),
                                     imag_mps2=Y.imag.ravel().tolist()))
            time.sleep(0.01)
        assert ros.wait_until(lambda: recorder.counts.get(topic, 0) >= len(rows), 10)
    finally:
        recorder.close()
    assert main(["calibrate", "accel", str(path), "--device-id", "sim", "--cache-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "from 6 motions" in out and "stored" in out
    _check_calibration(tmp_path, "sim", layout, gain)


def test_an_npz_recording_of_summaries_over_six_motions_recovers_the_injected_gains(tmp_path, capsys):
    # The same six motions recorded as .npz (one segment per motion).
    from ppod_ros.estimation import AccelRecording, write_recording

    layout, freq, k, rows, seg, gain = _six_motions(4)
    rec = AccelRecording(freq, tuple(layout.names), k=k, summaries=np.stack(rows), summary_segment=np.array(seg))
    path = write_recording(rec, tmp_path / "six_motions.npz")
    assert main(["calibrate", "accel", str(path), "--device-id", "sim", "--cache-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "held-out motion" in out and "stored" in out
    _check_calibration(tmp_path, "sim", layout, gain)

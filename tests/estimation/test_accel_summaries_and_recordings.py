"""Estimation from per-cycle harmonic summaries (a device DSP's output) and from recorded files."""

import math

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.estimation import (
    AccelerometerLayout,
    AccelEstimator,
    AccelRecording,
    EstimationError,
    fit_harmonics,
    read_recording,
    register_reader,
    write_recording,
)
from ppod_ros.estimation.recording import READERS
from ppod_ros.motion import PlateMotion, acceleration_error
from tests.estimation.plate_sim import readings, sample_times

LAYOUT = AccelerometerLayout.default()
GOAL = PlateMotion(30, [1], [[10, 0, 0, 0, 100, 0]], [[0, 0, 0, 0, 3 * math.pi / 2, 0]], name="LineSinkX")
RATE_HZ = 6000.0  # 200 samples per cycle at 30 Hz


def _cycle_summaries(cycles=8, noise=0.1, seed=0, K=6):
    """What a device DSP sends: per cycle, per channel, the phasors of harmonics 1..K (cycles, K, C)."""
    t = sample_times(30, cycles, RATE_HZ)
    r = readings(GOAL.phasor_table(1), [1], 30, t, LAYOUT.position_m, LAYOUT.axis)
    r += np.random.default_rng(seed).normal(0, noise, r.shape)
    per = int(RATE_HZ / 30)
    return np.stack(
        [
            fit_harmonics(t[i * per : (i + 1) * per], r[i * per : (i + 1) * per], 30, K).phasors
            for i in range(cycles)
        ]
    )


def _error(est):
    return acceleration_error(GOAL.phasor_table(6), est.table(6))[1]


def test_summaries_give_the_same_estimate_as_raw_samples():
    P = _cycle_summaries(noise=0.0)
    est = AccelEstimator(LAYOUT).from_summaries(range(1, 7), P, 30)
    assert _error(est) < 2e-5
    assert est.cycles == 8


def test_noisy_summaries_average_over_cycles_and_report_their_scatter():
    P = _cycle_summaries(noise=0.1, seed=1)
    est = AccelEstimator(LAYOUT).from_summaries(range(1, 7), P, 30)
    assert _error(est) <= 0.002
    assert np.all(est.std > 0)


def test_a_channel_whose_summaries_die_mid_run_is_dropped():
    P = _cycle_summaries(seed=2)
    P[3:, :, 4] = 0.0  # u130.t reads nothing from cycle 3 on
    est = AccelEstimator(LAYOUT).from_summaries(range(1, 7), P, 30)
    assert list(est.dropped) == ["u130.t"]
    assert _error(est) <= 0.002


def test_missing_and_flagged_summaries_are_skipped_and_an_all_flagged_channel_is_dropped():
    P = _cycle_summaries(seed=3)
    P[2, :, 0] = np.nan  # one lost summary
    flags = np.zeros((8, 12), bool)
    flags[:, 9] = True  # the DSP flags u250.z as overloaded in every cycle
    flags[5, 3] = True
    est = AccelEstimator(LAYOUT).from_summaries(range(1, 7), P, 30, faulty=flags)
    assert est.dropped == {"u250.z": "missing: 0 of 8 cycle summaries valid"}
    assert _error(est) <= 0.002


def test_stuck_summaries_are_dropped():
    P = _cycle_summaries(seed=4)
    P[:, :, 7] = P[0, :, 7]  # the same summary repeated for u230.z
    P[:, :, 7] *= 1.3
    est = AccelEstimator(LAYOUT).from_summaries(range(1, 7), P, 30)
    assert list(est.dropped) == ["u230.z"] and "stuck" in est.dropped["u230.z"]


def test_summaries_of_harmonics_one_to_three_only_still_estimate_the_fundamental():
    P = _cycle_summaries(noise=0.0)[:, :3]
    est = AccelEstimator(LAYOUT).from_summaries([1, 2, 3], P, 30)
    assert est.k.tolist() == [1, 2, 3]
    assert acceleration_error(GOAL.phasor_table(3), est.table(3))[1] < 2e-5


def test_summaries_with_too_few_healthy_channels_raise_a_fault():
    P = _cycle_summaries(seed=5)
    P[:, :, [0, 2, 4, 6, 8]] = np.nan
    with pytest.raises(EstimationError, match="no longer determine"):
        AccelEstimator(LAYOUT).from_summaries(range(1, 7), P, 30)


def test_summary_arguments_are_checked():
    P = _cycle_summaries(noise=0.0)
    with pytest.raises(ConfigError, match="ascending"):
        AccelEstimator(LAYOUT).from_summaries([2, 1, 3, 4, 5, 6], P, 30)
    with pytest.raises(ConfigError, match="phasors: expected shape"):
        AccelEstimator(LAYOUT).from_summaries([1, 2], P, 30)
    with pytest.raises(ConfigError, match="variance"):
        AccelEstimator(LAYOUT).from_summaries(range(1, 7), P[0], 30, variance=-np.ones((6, 12)))


def _sample_recording(segments=2, with_extras=True):
    t = sample_times(30, 6, RATE_HZ)
    r = readings(GOAL.phasor_table(1), [1], 30, t, LAYOUT.position_m, LAYOUT.axis)
    r[5, 3] = np.nan
    seg = np.repeat(np.arange(segments), -(-t.size // segments))[: t.size]
    extras = {}
    if with_extras:
        extras = dict(
            command_k=np.array([1, 2, 3]),
            commands_a=np.arange(segments * 18).reshape(segments, 3, 6) * (1 + 0.5j),
            goal=GOAL,
            meta={"device_id": "sim-1", "seed": 7},
        )
    return AccelRecording(30.0, LAYOUT.names, t, r, seg, **extras)


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_sample_recordings_round_trip_and_estimate_per_segment(tmp_path, suffix):
    rec = _sample_recording(with_extras=suffix == ".npz")
    back = read_recording(write_recording(rec, tmp_path / f"rec{suffix}"))
    assert back.channels == rec.channels and back.kind == "samples"
    np.testing.assert_array_equal(back.time_s, rec.time_s)
    np.testing.assert_array_equal(np.isnan(back.samples_mps2), np.isnan(rec.samples_mps2))
    np.testing.assert_allclose(back.samples_mps2, rec.samples_mps2, equal_nan=True)
    assert back.segments() == [0, 1]
    if suffix == ".npz":
        assert back.goal == GOAL and back.meta == {"device_id": "sim-1", "seed": 7}
        np.testing.assert_array_equal(back.command(1)[1], rec.command(1)[1])
    est = AccelEstimator(LAYOUT).from_recording(back, segment=1)
    assert _error(est) < 2e-5


def test_a_recording_appears_whole_or_not_at_all(tmp_path, monkeypatch):
    """A reader watching the directory (ppod/capture_raw's test did) never opens a half-written file:
    the writer fills a hidden file beside it and renames it; a failed write leaves nothing."""
    rec = _sample_recording(with_extras=True)
    seen = []

    def failing(recording, path):
        seen.append(path)
        path.write_bytes(b"PK\x03\x04 half a zip")
        raise OSError("disk full")

    from ppod_ros.estimation import recording as module

    monkeypatch.setitem(module.WRITERS, ".npz", failing)
    with pytest.raises(OSError):
        write_recording(rec, tmp_path / "raw_1.npz")
    assert list(tmp_path.iterdir()) == [] and seen[0].name.startswith(".") and seen[0].parent == tmp_path
    monkeypatch.undo()
    out = write_recording(rec, tmp_path / "raw_1.npz")
    assert [p.name for p in tmp_path.iterdir()] == ["raw_1.npz"] and read_recording(out).goal == GOAL


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_summary_recordings_round_trip(tmp_path, suffix):
    P = _cycle_summaries(cycles=4, seed=6)
    P[1, :, 2] = np.nan
    rec = AccelRecording(30.0, LAYOUT.names, k=np.arange(1, 7), summaries=P, summary_segment=[0, 0, 1, 1])
    back = read_recording(write_recording(rec, tmp_path / f"sum{suffix}"))
    assert back.kind == "summaries" and back.segments() == [0, 1]
    np.testing.assert_allclose(back.summaries, P, equal_nan=True)
    est = AccelEstimator(LAYOUT).from_recording(back, segment=1)
    assert _error(est) < 0.004


def test_recording_files_are_validated_strictly(tmp_path):
    path = tmp_path / "bad.npz"
    np.savez(path, frequency_hz=30.0, channels=np.array(["a"]), colour=np.array([1]))
    with pytest.raises(ConfigError, match=r"unknown arrays \['colour'\]"):
        read_recording(path)
    csv_path = tmp_path / "bad.csv"
    csv_path.write_text("# frequency_hz: 30\n# operator: me\ntime_s,a\n0,1\n")
    with pytest.raises(ConfigError, match="unknown keys"):
        read_recording(csv_path)
    with pytest.raises(ConfigError, match="no accelerometer-recording reader for '.mcap'"):
        read_recording(tmp_path / "x.mcap")
    with pytest.raises(ConfigError, match="either raw samples"):
        AccelRecording(30.0, ("a",))
    with pytest.raises(ConfigError, match="name one with segment="):
        AccelEstimator(LAYOUT).from_recording(_sample_recording())


def test_a_reader_for_another_format_plugs_in_by_suffix(tmp_path, monkeypatch):
    monkeypatch.setitem(READERS, ".npz", READERS[".npz"])  # restore the table after the test
    rec = _sample_recording(segments=1, with_extras=False)
    calls = []

    def fake_mcap_reader(path):
        calls.append(path)
        return rec

    monkeypatch.delitem(READERS, ".mcap", raising=False)
    register_reader(".mcap", fake_mcap_reader)
    try:
        assert read_recording(tmp_path / "session.mcap") is rec
    finally:
        READERS.pop(".mcap", None)
    assert calls == [tmp_path / "session.mcap"]

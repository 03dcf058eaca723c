"""Raw captures on request: the device's raw samples of whole cycles as a recording the estimator and
``ppod calibrate accel`` read, agreeing with the summaries of the same plate."""

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.estimation import AccelEstimator, read_recording, write_recording
from ppod_ros.estimation.recording import recording_from_captures
from ppod_ros.motion import PlateMotion, acceleration_error

LINESINKX = PlateMotion(30, [1], [[10, 0, 0, 0, 100, 0]], [[0, 0, 0, 0, 3 * np.pi / 2, 0]], ramp_time_s=0.3,
                        name="LineSinkX")


def test_a_raw_capture_estimates_the_plate_as_its_summaries_do(tmp_path):
    from ppod_bench.feedback import _Rig

    rig = _Rig(7)
    captures = []
    rig.link.on_raw.append(captures.append)
    try:
        assert rig.gen.submit(LINESINKX).accepted
        rig.advance(1.5)
        rig.summaries.clear()
        rig.link.request_raw(0xFFF, 3, capture_id=5)
        for _ in range(400):  # summaries pause while the capture is sent (device time, bounded)
            rig.advance(0.05)
            if captures:
                break
        rig.advance(0.5)
        summaries = rig.summaries[-6:]
    finally:
        rig.close()
    assert captures and captures[0].capture_id == 5 and captures[0].n_cycles == 3
    layout = rig.loop.config.accelerometers.layout
    rec = recording_from_captures(captures, 30.0, layout.names, meta={"device": "sim"})
    path = write_recording(rec, tmp_path / "raw.npz")
    back = read_recording(path)
    assert back.channels == layout.names and back.samples_mps2.shape == (3 * captures[0].samples_per_cycle, 12)
    est = AccelEstimator(layout, harmonics=6)
    raw = est.from_recording(back, 0)
    summ = est.from_summaries(summaries[0].k, np.stack([s.phasors for s in summaries]), 30.0)
    # The same plate two ways: raw samples (AC coupling not undone, about 0.1 % at 30 Hz) and the
    # device's own harmonic summaries.
    assert acceleration_error(summ.table(6), raw.table(6))[1] < 0.01
    assert acceleration_error(LINESINKX.phasor_table(6), raw.table(6))[1] < 0.3  # the plate is playing the goal


def test_captures_that_do_not_fit_are_one_line_errors():
    class Cap:
        def __init__(self, channels):
            self.channels, self.samples_per_cycle = channels, 8
            self.samples = np.zeros((8, len(channels)))

    names = [f"c{i}" for i in range(3)]
    with pytest.raises(ConfigError, match="captures"):
        recording_from_captures([], 30.0, names)
    with pytest.raises(ConfigError, match="same channels"):
        recording_from_captures([Cap((0, 1)), Cap((0, 2))], 30.0, names)
    with pytest.raises(ConfigError, match="frequency_hz"):
        recording_from_captures([Cap((0,))], 0.0, names)

"""Array calibration from operating data: recovery of injected errors, refusal, cross-validation, store."""

import math
from pathlib import Path

import numpy as np
import pytest

from ppod_ros.estimation import AccelerometerLayout, AccelEstimator
from ppod_ros.estimation.calibration import (
    CalibrationError,
    MotionData,
    calibrate,
    load_calibration,
    save_calibration,
)
from ppod_ros.estimation.ppod2 import read_ppod2_json
from tests.estimation.plate_sim import readings, sample_times

LAYOUT = AccelerometerLayout.default()
GAIN = np.array([1.01, 0.99, 1.02, 0.98, 1.0, 1.01, 0.92, 0.99, 1.06, 1.0, 0.98, 1.02])
DATA = Path(__file__).resolve().parents[1] / "data" / "ppod2_real_subset.json"


def _tilted(e, deg, about):
    about = about / np.linalg.norm(about)
    th = math.radians(deg)
    return e * math.cos(th) + np.cross(about, e) * math.sin(th) + about * (about @ e) * (1 - math.cos(th))


def _true_axes():
    axis = LAYOUT.axis.copy()
    axis[6] = _tilted(axis[6], 4.0, np.cross(axis[6], [0, 0, 1]))   # out of the plate, like the lab's ch6
    axis[8] = _tilted(axis[8], -4.0, np.cross(axis[8], [0, 0, 1]))  # ch8 the other way
    axis[3] = _tilted(axis[3], 1.0, np.array([1.0, 0, 0]))
    return axis


def _motions(axis, n=8, seed=1, noise=0.05):
    rng = np.random.default_rng(seed)
    f, t = 30.0, sample_times(30.0, 4, 5000)
    out = []
    for i in range(n):
        U = (rng.normal(size=6) * [5, 5, 5, 50, 50, 50] * np.exp(1j * rng.uniform(0, 2 * np.pi, 6)))[None]
        y = readings(U, np.array([1]), f, t, LAYOUT.position_m, axis) * GAIN + rng.normal(0, noise, (t.size, 12))
        out.append(MotionData.from_samples(f"m{i}", t, y, f, 3))
    return out


def test_injected_gains_are_recovered_within_1_5_percent_and_vertical_axes_within_half_a_degree():
    axis = _true_axes()
    cal = calibrate(LAYOUT, _motions(axis))
    # Raw: within 1.5 % (the blind combinations below move the tangential gains by up to 1.1 %).
    assert np.abs(cal.gain - GAIN / GAIN.mean()).max() <= 0.015
    # Axes: the vertical channels within half a degree; the tangential ones within one degree,
    # because a coplanar array is blind to some combinations of them (e.g. a common tilt out of the
    # plate trades with alpha_z), which the calibration fixes by the least change from nominal.
    ang = np.degrees(np.arccos(np.clip(np.sum(cal.axis * axis, axis=1), -1, 1)))
    assert ang[1::2].max() <= 0.5 and ang[0::2].max() <= 1.0, ang
    assert cal.unobserved_basis.shape[1] == 7
    assert cal.unobservable[0].startswith("common gain")
    assert np.all(cal.gain_std < 0.01) and np.all(cal.axis_std_deg < 0.5)


def test_opposite_out_of_plane_tilts_are_seen_within_half_a_degree():
    axis = _true_axes()
    cal = calibrate(LAYOUT, _motions(axis))
    ang = np.degrees(np.arccos(np.clip(np.sum(cal.axis * axis, axis=1), -1, 1)))
    assert ang[[6, 8]].max() <= 0.5, ang


def test_one_kind_of_motion_is_refused_naming_the_channels_and_what_to_record():
    f, t = 30.0, sample_times(30.0, 4, 5000)
    motions = []
    for amp in (5.0, 8.0, 3.0):
        U = np.array([[0, 0, amp, 0, 0, 0]], complex)  # vertical bounce only
        motions.append(MotionData.from_samples(f"bounce{amp}", t, readings(U, np.array([1]), f, t, LAYOUT.position_m,
                                                                            LAYOUT.axis), f, 3))
    with pytest.raises(CalibrationError, match="ill-conditioned") as info:
        calibrate(LAYOUT, motions)
    assert "u10.t" in str(info.value) and "record a motion" in str(info.value)


def test_on_the_real_subset_the_held_out_misfit_improves_on_most_motions_and_the_calibration_round_trips(tmp_path):
    layout, recs = read_ppod2_json(DATA)
    motions = [MotionData.from_samples(n, r.time_s, r.samples_mps2, r.frequency_hz) for n, r in recs.items()
               if n != "Zeros"]
    cal = calibrate(layout, motions)
    better = [m for m, v in cal.report.items() if v["calibrated"] < v["nominal"]]
    assert len(cal.report) == 9 and len(better) >= 7
    assert cal.gain[6] < 0.97 and cal.gain[8] > 1.01  # the lab's weak and strong tangential channels
    path = save_calibration(cal, tmp_path, "ppod2")
    assert path.name == "accel_calibration.json"
    back = load_calibration(tmp_path, "ppod2")
    assert np.allclose(back.gain, cal.gain) and np.allclose(back.axis, cal.axis)
    assert load_calibration(tmp_path, "other") is None
    # The estimator with the calibration keeps every channel and still agrees with the lab's fit
    # (the lab used the nominal layout) within a few percent.
    est = AccelEstimator(layout, harmonics=6, calibration=back)
    rec = recs["Circle"]
    assert est.from_cycle(rec.samples_mps2, rec.sample_rate_hz).dropped == {}
    broken = rec.samples_mps2.copy()
    broken[:, 6] *= 0.5
    assert "ch6" in est.from_cycle(broken, rec.sample_rate_hz).dropped

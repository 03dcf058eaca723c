"""Array calibration from operating data: recovery of injected errors, refusal, cross-validation, store."""

import math
from pathlib import Path

import numpy as np
import pytest

from ppod_ros.estimation import AccelerometerLayout, AccelEstimator, EstimationError
from ppod_ros.estimation.calibration import (
    CalibrationError,
    MotionData,
    calibrate,
    equivalent_calibration,
    load_calibration,
    save_calibration,
)
from ppod_ros.estimation.ppod2 import read_ppod2_json
from ppod_ros.estimation.unobservable import DIRECTIONS, direction_fields
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


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=1), -1, 1)))


def test_injected_errors_are_recovered_to_0_1_percent_and_0_1_degree_up_to_the_unobservable_directions():
    axis = _true_axes()
    cal = calibrate(LAYOUT, _motions(axis))
    # The truth as the calibration's convention represents it: it reads every motion exactly as the
    # true sensors do (next test), so only the unobservable directions separate it from them.
    truth = equivalent_calibration(LAYOUT, axis * GAIN[:, None])
    assert np.abs(cal.gain - truth.gain).max() <= 0.001
    assert _angle_deg(cal.axis, truth.axis).max() <= 0.1
    assert cal.unobserved_basis.shape[1] == 10
    assert [u.split(" (fixed")[0] for u in cal.unobservable] == list(DIRECTIONS)
    assert cal.unobservable[0].startswith("common gain")
    assert np.all(cal.gain_std < 0.01) and np.all(cal.axis_std_deg < 0.5)
    # The convention (least change from nominal) lands within 0.5 % and 0.5 degree of the raw truth here.
    assert np.abs(cal.gain - GAIN / GAIN.mean()).max() <= 0.005
    assert _angle_deg(cal.axis, axis).max() <= 0.5


def test_the_equivalent_calibration_reads_every_rigid_motion_as_the_true_sensors_do():
    w = _true_axes() * GAIN[:, None]
    eq = equivalent_calibration(LAYOUT, w)
    w_eq = eq.gain[:, None] * eq.axis
    rng = np.random.default_rng(4)
    for f in (12.0, 23.0, 40.0):  # any frequency: the tilted-gravity lift shifts every lever alike
        lever = LAYOUT.position_m + [0.0, 0.0, 9.81 / (2 * np.pi * f) ** 2]
        U = (rng.normal(size=6) + 1j * rng.normal(size=6)) * [5, 5, 5, 50, 50, 50]
        Y = w @ U[:3] + np.einsum("cj,cj->c", np.cross(lever, w), np.broadcast_to(U[3:], (12, 3)))
        # The same readings, explained exactly by the equivalent sensitivities and some rigid motion.
        H = np.concatenate([w_eq, np.cross(lever, w_eq)], axis=1)
        V = np.linalg.lstsq(H, Y, rcond=None)[0]
        # 1e-5, not exact: the layout's radii are equal only to 1e-4 (positions to 0.1 mm), so three of
        # the ring's directions are seen, at 1e-7 to 1e-6 of the best seen one (fixed all the same).
        assert np.linalg.norm(H @ V - Y) <= 1e-5 * np.linalg.norm(Y)


def test_each_named_unobservable_direction_with_its_motion_change_leaves_every_reading_unchanged():
    # Gains and out-of-plane tilts of tangential axes keep the ring's symmetry exactly (a vertical axis
    # tilted in the plate, like _true_axes' ch3, makes the in-plane directions faintly seen).
    axis = LAYOUT.axis.copy()
    axis[[6, 8]] = _true_axes()[[6, 8]]
    w = axis * GAIN[:, None]
    rho = LAYOUT.position_m - LAYOUT.position_m.mean(axis=0)
    radius = float(np.mean(np.linalg.norm(rho[:, :2], axis=1)))
    fields = direction_fields(LAYOUT.position_m, w)
    rng = np.random.default_rng(2)
    U = rng.normal(size=6) * [5, 5, 5, 50, 50, 50]
    eps = 1e-6

    def read(w_, u_):  # first order, levers from the ring's centre: w . (p'' + alpha x rho)
        return np.einsum("cj,cj->c", w_, u_[None, :3] + np.cross(u_[None, 3:], rho))

    for name, make in DIRECTIONS.items():
        n_t = make(radius)
        changed = read(w + eps * fields[name], U - eps * (n_t.T @ U))
        assert np.abs(changed - read(w, U)).max() <= 1e-9 * np.abs(read(w, U)).max(), name


def test_opposite_out_of_plane_tilts_are_seen_within_half_a_degree():
    axis = _true_axes()
    cal = calibrate(LAYOUT, _motions(axis))
    assert _angle_deg(cal.axis, axis)[[6, 8]].max() <= 0.5


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
    # Every healthy record keeps every channel with the calibration's allowances (mean + 2 std of
    # each channel's held-out misfit; the median alone dropped ch0 and ch10 on ShearX).
    for name, rec in recs.items():
        assert est.from_cycle(rec.samples_mps2, rec.sample_rate_hz).dropped == {}, name
    rec = recs["Circle"]
    assert est.from_cycle(rec.samples_mps2, rec.sample_rate_hz).dropped == {}
    broken = rec.samples_mps2.copy()
    broken[:, 6] *= 0.5
    # Caught: dropped, or an error naming it (ch8, 20 degrees away, is the other candidate).
    try:
        assert "ch6" in est.from_cycle(broken, rec.sample_rate_hz).dropped
    except EstimationError as exc:
        assert "ch6" in str(exc) and "ch6" in exc.channel_status and exc.channel_status["ch6"] != "ok"

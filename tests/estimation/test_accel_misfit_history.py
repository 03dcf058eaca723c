"""Misfit learned from operation: per-channel allowance from healthy estimates, stored per device."""

from pathlib import Path

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.estimation import AccelEstimator, EstimationError
from ppod_ros.estimation.calibration import MIN_ALLOWANCE
from ppod_ros.estimation.faults import inject, swap_matters
from ppod_ros.estimation.misfit import MisfitHistory, MisfitSettings, load_misfit, misfit_path, save_misfit
from ppod_ros.estimation.ppod2 import read_ppod2_json

DATA = Path(__file__).resolve().parents[1] / "data" / "ppod2_real_subset.json"
LAYOUT, RECORDS = read_ppod2_json(DATA)
DRIVEN = [n for n in RECORDS if n != "Zeros"]


def _learned() -> MisfitHistory:
    history = MisfitHistory(LAYOUT.names, MisfitSettings(min_estimates=len(DRIVEN)))
    for name in DRIVEN:
        rec = RECORDS[name]
        est = AccelEstimator(LAYOUT, harmonics=6).from_cycle(rec.samples_mps2, rec.sample_rate_hz)
        assert history.add(est)
    return history


def test_every_used_channel_reports_its_misfit_and_a_dropped_one_none():
    rec = RECORDS["ShearX"]
    est = AccelEstimator(LAYOUT, harmonics=6).from_cycle(inject(rec.samples_mps2, "zeroed", (3,)), rec.sample_rate_hz)
    assert "ch3" in est.dropped
    assert np.isnan(est.channel_misfit[3])
    kept = np.delete(est.channel_misfit, 3)
    assert np.all(np.isfinite(kept)) and np.all((kept >= 0) & (kept < 0.5))


def test_the_allowance_is_learned_from_healthy_estimates_only_and_used_after_enough_of_them():
    history = MisfitHistory(LAYOUT.names, MisfitSettings(min_estimates=len(DRIVEN)))
    rec = RECORDS["ShearX"]
    broken = AccelEstimator(LAYOUT, harmonics=6).from_cycle(inject(rec.samples_mps2, "zeroed", (3,)),
                                                            rec.sample_rate_hz)
    assert not history.add(broken)  # a channel was dropped: nothing learned
    assert history.allowance() is None and not history.ready
    history = _learned()
    allow = history.allowance()
    assert history.ready and allow.shape == (12,)
    assert np.all(allow >= MIN_ALLOWANCE)
    # Per channel: the two worst-fitting tangential channels (ch6, ch8: tilted axes, gain errors) get
    # the widest allowance, the well-fitting ones much less than the 50 % default.
    assert set(np.argsort(allow)[-2:]) == {6, 8}
    assert np.sum(allow < 0.3) >= 7
    # A fresh estimator with the learned allowance still keeps every channel of every real record.
    for name, rec in RECORDS.items():
        est = AccelEstimator(LAYOUT, harmonics=6, misfit_allowance=allow).from_cycle(rec.samples_mps2,
                                                                                     rec.sample_rate_hz)
        assert est.dropped == {}, name


@pytest.mark.parametrize("motion", ["LineSinkX", "TransX"])
def test_a_fresh_estimator_catches_the_mirror_image_swap_by_exchanging_the_pair_back(motion):
    # ch3 and ch9 are vertical channels at (x, +-y) (mirror images across the x axis): swapping them
    # reads exactly like reversing alpha_x on those two channels, 2 alpha_x y. LineSinkX and TransX
    # have little roll beside their pitch (which both read alike, at the same x), so the swap misfits
    # by only 27-34 % of their readings: within the default 50 % allowance of a device with no
    # history (which must pass this device's healthy weak channels, up to 36 %). Exchanging the two
    # back leaves 27-34 % of the misfit; no exchange leaves less than 77 % on a healthy record.
    rec = RECORDS[motion]
    y = inject(rec.samples_mps2, "swapped", (3, 9))
    with pytest.raises(EstimationError, match="swapped in wiring: exchanging ch3 and ch9") as info:
        AccelEstimator(LAYOUT, harmonics=6).from_cycle(y, rec.sample_rate_hz)
    assert info.value.channel_status["ch3"].startswith("swapped with ch9?")
    assert info.value.channel_status["ch9"].startswith("swapped with ch3?")
    # The learned allowance (ch3, ch9 misfit 1-6 % when healthy) sees it as well.
    allow = _learned().allowance()
    try:
        est = AccelEstimator(LAYOUT, harmonics=6, misfit_allowance=allow).from_cycle(y, rec.sample_rate_hz)
    except EstimationError:
        return
    assert {"ch3", "ch9"} <= set(est.dropped)


def test_stored_per_device_and_read_back(tmp_path):
    history = _learned()
    path = save_misfit(history, tmp_path, "ppod2")
    assert path == misfit_path(tmp_path, "ppod2") and path.parent.name == "ppod2"
    back = load_misfit(tmp_path, "ppod2", MisfitSettings(min_estimates=len(DRIVEN)))
    assert back.names == history.names
    np.testing.assert_allclose(back.allowance(), history.allowance())
    assert load_misfit(tmp_path, "other") is None
    path.write_text("{not json")
    with pytest.raises(ConfigError, match="unreadable misfit history"):
        load_misfit(tmp_path, "ppod2")


def test_bad_arguments_are_one_line_config_errors():
    with pytest.raises(ConfigError, match="min_estimates"):
        MisfitSettings(min_estimates=1)
    with pytest.raises(ConfigError, match="names"):
        MisfitHistory(["a", "a"])
    with pytest.raises(ConfigError, match="misfit_allowance"):
        AccelEstimator(LAYOUT, misfit_allowance=np.ones(3))


def test_the_same_swap_is_caught_at_once_on_the_motions_with_roll():
    # What the fresh estimator misses on LineSinkX and TransX it catches on every other driven record
    # whose ch3 and ch9 readings the swap changes (swap_matters): an error or both channels dropped.
    for name, rec in RECORDS.items():
        if name in ("Zeros", "LineSinkX", "TransX") or not swap_matters(rec.samples_mps2, 3, 9):
            continue
        y = inject(rec.samples_mps2, "swapped", (3, 9))
        try:
            est = AccelEstimator(LAYOUT, harmonics=6).from_cycle(y, rec.sample_rate_hz)
        except EstimationError:
            continue
        assert {"ch3", "ch9"} <= set(est.dropped), name

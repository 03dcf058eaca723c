"""Real data: the PPOD2 lab's saved cycles (tests/data/ppod2_real_subset.json, benbdon/PPOD2).

A fresh default estimator must accept the real device (every channel kept, within 2 % of the lab's
own rigid-body fit), catch channels broken on purpose, and refuse dead acquisitions.
"""

from pathlib import Path

import numpy as np
import pytest

from ppod_ros.estimation import AccelEstimator, EstimationError
from ppod_ros.estimation.faults import FAULTS, inject, swap_matters
from ppod_ros.estimation.harmonic_fit import fit_harmonics
from ppod_ros.estimation.ppod2 import read_ppod2_json
from ppod_ros.motion import acceleration_error

DATA = Path(__file__).resolve().parents[1] / "data" / "ppod2_real_subset.json"
LAYOUT, RECORDS = read_ppod2_json(DATA)
DRIVEN = [n for n in RECORDS if n != "Zeros"]


def _lab_phasors(rec):
    return fit_harmonics(rec.time_s, rec.lab_estimate, rec.frequency_hz, 6).phasors


def _estimate(y, rec):
    return AccelEstimator(LAYOUT, harmonics=6).from_cycle(y, rec.sample_rate_hz)


@pytest.mark.parametrize("name", list(RECORDS))
def test_a_fresh_default_estimator_keeps_every_real_channel_and_agrees_with_the_lab_within_2_percent(name):
    rec = RECORDS[name]
    est = _estimate(rec.samples_mps2, rec)
    assert est.dropped == {}
    assert acceleration_error(_lab_phasors(rec), est.table(6))[1] <= 0.02


def test_the_period_is_the_datas_own():
    rec = RECORDS["LineSinkX"]
    est = _estimate(rec.samples_mps2, rec)
    assert est.frequency_hz == pytest.approx(rec.sample_rate_hz / rec.samples_mps2.shape[0])
    # 263 samples at 10 kHz: 38.02 Hz, not the nominal 38
    est = AccelEstimator(LAYOUT, harmonics=6).from_cycle(rec.samples_mps2[:263], 10000.0)
    assert est.frequency_hz == pytest.approx(10000.0 / 263)


def test_the_undriven_record_is_live_noise_not_a_dead_acquisition():
    rec = RECORDS["Zeros"]
    assert 0.1 < np.sqrt(np.mean(rec.samples_mps2**2)) < 0.2
    est = _estimate(rec.samples_mps2, rec)
    assert est.dropped == {}
    assert np.abs(est.phasors[:, :3]).max() < 0.1


@pytest.mark.parametrize("fault", [f for f, (n, _) in FAULTS.items() if n == 1])
def test_single_channel_faults_on_live_real_channels_are_caught_every_time(fault):
    missed = []
    for name in DRIVEN:
        rec = RECORDS[name]
        live = np.flatnonzero(np.sqrt(np.mean(rec.samples_mps2**2, axis=0)) >= 1.0)
        for c in live:
            y = inject(rec.samples_mps2, fault, (c,), seed=int(c))
            try:
                est = _estimate(y, rec)
            except EstimationError:
                continue
            if LAYOUT.names[c] not in est.dropped:
                missed.append((name, LAYOUT.names[c]))
    assert missed == [], missed


def test_two_swapped_channels_are_caught_in_every_pair_and_never_misattributed():
    # A swap is caught by an EstimationError (the record cannot say which channels are broken) or
    # by dropping both; dropping other channels instead would feed the swapped pair to the estimate.
    cases = caught = 0
    wrong = []
    for name in ("LineSinkX", "Centrifuge", "TransY"):
        rec = RECORDS[name]
        live = np.flatnonzero(np.sqrt(np.mean(rec.samples_mps2**2, axis=0)) >= 1.0)
        for i, a in enumerate(live):
            for b in live[i + 1 :]:
                if not swap_matters(rec.samples_mps2, a, b):
                    continue
                cases += 1
                try:
                    est = _estimate(inject(rec.samples_mps2, "swapped", (a, b)), rec)
                except EstimationError as exc:
                    caught += 1
                    if "swapped in wiring" in str(exc) and f"{LAYOUT.names[a]} and {LAYOUT.names[b]}" not in str(exc):
                        wrong.append((name, LAYOUT.names[a], LAYOUT.names[b], str(exc)))
                    continue
                both = LAYOUT.names[a] in est.dropped and LAYOUT.names[b] in est.dropped
                caught += both
                if est.dropped and not both:
                    wrong.append((name, LAYOUT.names[a], LAYOUT.names[b], sorted(est.dropped)))
    assert cases > 100
    assert wrong == []
    assert caught == cases


@pytest.mark.parametrize(
    "kill",
    [
        lambda y: np.zeros_like(y),
        lambda y: np.broadcast_to(y[0], y.shape).copy(),
        lambda y: np.vstack([y[:300], np.broadcast_to(y[299], (200, y.shape[1]))]),
    ],
    ids=["all zero", "stuck ADC", "stopped changing"],
)
def test_a_dead_acquisition_is_an_error_never_a_plate_at_rest(kill):
    rec = RECORDS["LineSinkX"]
    with pytest.raises(EstimationError, match="dead acquisition") as info:
        _estimate(kill(rec.samples_mps2), rec)
    assert all("dead acquisition" in s for s in info.value.channel_status.values())


def test_dead_summaries_are_an_error_too():
    rec = RECORDS["Zeros"]
    fit = fit_harmonics(rec.time_s, rec.samples_mps2, rec.frequency_hz, 6)
    est = AccelEstimator(LAYOUT, harmonics=6)
    live = est.from_summaries(fit.k, fit.phasors, rec.frequency_hz, variance=fit.variance)
    assert live.dropped == {}  # live noise on a plate at rest: fine
    with pytest.raises(EstimationError, match="exactly zero"):
        est.from_summaries(fit.k, np.zeros_like(fit.phasors), rec.frequency_hz)
    with pytest.raises(EstimationError, match="identical"):
        est.from_summaries(fit.k, np.stack([fit.phasors] * 3), rec.frequency_hz)

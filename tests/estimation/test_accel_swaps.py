"""Two channels swapped in wiring: the exchange test against brute-force refits and on readings."""

import math

import numpy as np
import pytest

from ppod_ros.estimation import AccelerometerLayout, AccelEstimator, EstimationError
from ppod_ros.estimation.swaps import exchange_ratios
from tests.estimation.plate_sim import readings, sample_times

LAYOUT = AccelerometerLayout.default()


def _residual(H, Y):
    return math.sqrt(sum(np.sum(np.abs(Y[k] - H[k] @ np.linalg.lstsq(H[k], Y[k], rcond=None)[0]) ** 2)
                         for k in range(H.shape[0])))


def test_the_exchange_formula_equals_refitting_every_exchanged_pair():
    rng = np.random.default_rng(3)
    H = np.stack([LAYOUT.measurement_matrix(2 * math.pi * 30 * k, 9.81) for k in (1, 2)])
    Y = np.einsum("kcj,kj->kc", H, rng.normal(size=(2, 6)) + 1j * rng.normal(size=(2, 6)))
    Y = Y + 0.05 * (rng.normal(size=Y.shape) + 1j * rng.normal(size=Y.shape))
    ratio = exchange_ratios(H, Y)
    base = _residual(H, Y)
    for a, b in [(0, 1), (3, 9), (6, 8), (2, 11)]:
        Z = Y.copy()
        Z[:, [a, b]] = Z[:, [b, a]]
        assert ratio[a, b] == pytest.approx(_residual(H, Z) / base, rel=1e-9)
        assert ratio[b, a] == pytest.approx(ratio[a, b], rel=1e-12)
    assert np.all(np.isinf(np.diag(ratio)))


def test_a_swapped_pair_on_a_simulated_plate_is_named_and_a_healthy_one_passes():
    f, t = 30.0, sample_times(30.0, 4, 2000)
    U = np.array([[10, 0, 0, 0, 100 * np.exp(1.5j * np.pi), 0]], complex)  # LineSinkX
    y = readings(U, np.array([1]), f, t, LAYOUT.position_m, LAYOUT.axis)
    y = y + np.random.default_rng(1).normal(0, 0.02, y.shape)
    est = AccelEstimator(LAYOUT, harmonics=3)
    assert est.from_samples(t, y, f).dropped == {}
    y[:, [1, 5]] = y[:, [5, 1]]
    a, b = LAYOUT.names[1], LAYOUT.names[5]
    with pytest.raises(EstimationError) as info:
        est.from_samples(t, y, f)
    status = info.value.channel_status
    assert status[a] != "ok" and status[b] != "ok", status

"""The feedback loop learns each channel's misfit from its healthy estimates and uses it without a calibration."""

import numpy as np

from ppod_ros.control.online import FeedbackLoop
from ppod_ros.device import default_device_config
from ppod_ros.estimation.misfit import MisfitHistory, MisfitSettings

FREQ_HZ = 38.0
SAMPLES = 256
K = np.arange(1, 7)


def _summaries(config, n, seed=0):
    """n summaries of one rigid motion read by channels with gain errors (a device-sized misfit)."""
    rng = np.random.default_rng(seed)
    layout = config.accelerometers.layout
    U = np.zeros((K.size, 6), complex)
    U[0] = [3.0, 1.0j, 2.0, 5.0, -4.0j, 8.0]
    U[1] = [0.5, 0.2, 0.8j, 1.0, 0.5, 2.0]
    gain = 1 + 0.06 * np.sign(np.sin(np.arange(layout.num_channels) * 1.7))
    Y = np.stack([layout.measurement_matrix(2 * np.pi * FREQ_HZ * k, 0.0) @ U[i] for i, k in enumerate(K)])
    Y = Y * gain
    return [Y + 1e-3 * (rng.normal(size=Y.shape) + 1j * rng.normal(size=Y.shape)) for _ in range(n)]


def _feed(loop, summaries, t0_s=1.0):
    """Summaries one cycle apart from device time t0_s (no goal: the loop only estimates)."""
    for i, Y in enumerate(summaries):
        loop.on_summary(K, Y, FREQ_HZ, SAMPLES, t0_s + i / FREQ_HZ)


def test_without_a_calibration_the_learned_allowance_replaces_the_default_once_ready():
    config = default_device_config()
    names = config.accelerometers.layout.names
    history = MisfitHistory(names, MisfitSettings(min_estimates=3))
    loop = FeedbackLoop(config, misfit=history)
    loop.set_goal(None, 0.0)
    default = loop.estimator._solver.allowance.copy()
    per_estimate = loop.settings.summaries_per_estimate
    _feed(loop, _summaries(config, 2 * per_estimate))
    assert history.count.min() == 2 and not history.ready
    np.testing.assert_array_equal(loop.estimator._solver.allowance, default)
    _feed(loop, _summaries(config, per_estimate, seed=1), t0_s=2.0)
    assert history.ready
    np.testing.assert_allclose(loop.estimator._solver.allowance, history.allowance())
    assert not np.allclose(loop.estimator._solver.allowance, default)


def test_a_calibration_keeps_its_own_allowance_while_the_history_still_learns():
    from ppod_ros.estimation.calibration import AccelCalibration

    config = default_device_config()
    layout = config.accelerometers.layout
    C = layout.num_channels
    cal = AccelCalibration(tuple(layout.names), np.ones(C), layout.axis.copy(), layout.axis.copy(),
                           layout.position_m.copy(), np.zeros(C), np.zeros(C), np.full(C, 0.1), ("a",), ())
    history = MisfitHistory(layout.names, MisfitSettings(min_estimates=2))
    loop = FeedbackLoop(config, calibration=cal, misfit=history)
    loop.set_goal(None, 0.0)
    _feed(loop, _summaries(config, 3 * loop.settings.summaries_per_estimate))
    assert history.ready
    np.testing.assert_allclose(loop.estimator._solver.allowance, cal.misfit_allowance())

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from ppod_ros.control import DeviceLimits, LearningSettings, PlantModel, as_plant, peak_a
from ppod_ros.errors import ConfigError
from ppod_ros.estimation import HealthSettings
from tests.control.synthetic_plant import nominal_response

complex_tables = arrays(
    complex, (3, 6), elements=st.complex_numbers(max_magnitude=3.0, allow_nan=False, allow_infinity=False)
)


@settings(max_examples=200, deadline=None)
@given(
    ff=complex_tables,
    prev=complex_tables,
    prop=complex_tables,
    max_current=st.floats(0.5, 10),
    max_step=st.floats(0.01, 5),
)
def test_limited_commands_never_exceed_either_limit_and_keep_the_update_direction(
    ff, prev, prop, max_current, max_step
):
    limits = DeviceLimits(max_current_a=max_current, max_step_a=max_step)
    out, report = limits.apply(prev, prop, ff)
    assert np.all(peak_a(ff + out) <= max_current * (1 + 1e-9))
    was_over = peak_a(ff + prev) > max_current
    step = out - prev
    ok = ~was_over
    # Within the limits before: the step is within the step limit and along the proposed direction.
    assert np.all(peak_a(step)[ok] <= max_step * (1 + 1e-9))
    for j in np.flatnonzero(ok):
        want = prop[:, j] - prev[:, j]
        if np.abs(want).sum() > 1e-9:
            t = np.vdot(want, step[:, j]).real / np.vdot(want, want).real
            np.testing.assert_allclose(step[:, j], t * want, atol=1e-9)
            assert -1e-12 <= t <= 1 + 1e-12
    # Nothing was cut silently.
    changed = ~np.all(np.isclose(out, prop, atol=1e-12), axis=0)
    assert set(np.flatnonzero(changed)) <= {e.actuator for e in report.events}


def test_a_proposal_within_limits_passes_unchanged_with_an_empty_report():
    limits = DeviceLimits(max_current_a=[2, 2, 2, 2, 2, 3], max_step_a=1.0)
    prev = np.zeros((2, 6), complex)
    prop = np.full((2, 6), 0.2 + 0.1j)
    out, report = limits.apply(prev, prop, np.full((2, 6), 0.5))
    np.testing.assert_array_equal(out, prop)
    assert not report.clipped and report.describe() == "within limits"


def test_limits_are_validated():
    with pytest.raises(ConfigError, match="limits.max_current_a: must be > 0"):
        DeviceLimits(max_current_a=0.0, max_step_a=1.0)
    with pytest.raises(ConfigError, match="max_step_a"):
        DeviceLimits(max_current_a=1.0, max_step_a=[1, 2])
    with pytest.raises(ConfigError, match="share shape"):
        DeviceLimits(1.0, 1.0).apply(np.zeros((2, 6)), np.zeros((3, 6)))


def test_plant_model_evaluates_the_response_at_each_harmonic_frequency():
    plant = PlantModel.from_response(nominal_response, 30.0, [1, 2, 3])
    np.testing.assert_allclose(plant.matrix(2), nominal_response([60.0])[0])
    U = np.random.default_rng(0).normal(size=(3, 6)) + 0j
    np.testing.assert_allclose(plant.response(plant.solve(U, [1, 2, 3]), [1, 2, 3]), U, atol=1e-12)
    assert plant.condition(1) < 10


def test_a_singular_plant_is_rejected_naming_the_harmonic():
    G = nominal_response([30.0, 60.0])
    G[1][:, 5] = G[1][:, 4]  # two actuators that do the same thing at 60 Hz
    with pytest.raises(ConfigError, match=r"harmonic 2 \(60 Hz\) is singular or ill-conditioned"):
        PlantModel(30.0, [1, 2], G)


def test_plant_inputs_are_checked():
    with pytest.raises(ConfigError, match="expected shape"):
        PlantModel.from_response(lambda f: np.zeros((2, 6, 6)), 30.0, [1, 2, 3])
    with pytest.raises(ConfigError, match="finite"):
        PlantModel(30.0, [1], np.full((1, 6, 6), np.nan))
    with pytest.raises(ConfigError, match="has no matrix for harmonic 4"):
        PlantModel.from_response(nominal_response, 30.0, [1, 2]).matrix(4)
    with pytest.raises(ConfigError, match="is for 30 Hz"):
        as_plant(PlantModel.from_response(nominal_response, 30.0, [1]), 25.0, [1])


def test_a_table_of_matrices_is_a_plant():
    table = {k: nominal_response([30.0 * k])[0] for k in (3, 1, 2)}
    plant = as_plant(table, 30.0, [1, 2, 3])
    assert plant.k.tolist() == [1, 2, 3] and plant.source == "table"


def test_learning_and_health_settings_load_strictly_from_parameter_mappings():
    s = LearningSettings.from_dict({"gain": 0.8, "divergence_iterations": 4})
    assert s.gain == 0.8 and s.divergence_iterations == 4 and s.tolerance == 0.01
    with pytest.raises(ConfigError, match="learning.colour"):
        LearningSettings.from_dict({"colour": 1})
    with pytest.raises(ConfigError, match="learning.divergence_iterations: expected an integer"):
        LearningSettings.from_dict({"divergence_iterations": 2.5})
    with pytest.raises(ConfigError, match="learning: learning.gain: must be in"):
        LearningSettings.from_dict({"gain": 3.0})
    assert HealthSettings.from_dict({"residual_threshold": 6}).residual_threshold == 6.0

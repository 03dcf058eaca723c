"""Goal planning: valid goals become tables; goals over a limit are rejected whole, naming it."""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ppod_ros.actuation.corrections import CORRECTION_GUARD
from ppod_ros.actuation.planning import GoalPlanner, contact_margin, plate_peaks
from ppod_ros.can.protocol import CURRENT_LSB_A
from ppod_ros.device import default_device_config
from ppod_ros.errors import ConfigError, LimitError
from ppod_ros.motion import GRAVITY_MPS2, PlateMotion

CFG = default_device_config()
PLANNER = GoalPlanner(CFG)
LINESINKX = PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0], name="LineSinkX")


def test_linesinkx_is_accepted_with_its_predictions():
    plan = PLANNER.plan(LINESINKX)
    assert plan.currents_a.shape == (3, 6)  # room for harmonics 1..3
    assert np.all(plan.currents_a[1:] == 0)
    assert plan.ramp_s == CFG.timing.default_ramp_s
    assert plan.contact_margin_mps2 == pytest.approx(GRAVITY_MPS2 - 100 * 0.08, abs=1e-3)
    assert plan.plate_accel_peak_mps2 == pytest.approx(10.0, rel=1e-3)
    assert plan.plate_angular_accel_peak_radps2 == pytest.approx(100.0, rel=1e-3)
    assert np.all(plan.stroke_peak_m > 1e-4) and np.all(plan.stroke_peak_m < CFG.limits.leg_stroke_m)
    p = plan.prediction
    assert np.all(p.current_peak_a < CFG.limits.coil_current_a)
    assert np.allclose(p.accel[0], LINESINKX.phasor_table(1)[0], atol=1e-4)
    # The table is on the protocol's grid: what the device will receive exactly.
    assert np.allclose(plan.currents_a.real / CURRENT_LSB_A, np.round(plan.currents_a.real / CURRENT_LSB_A))


def test_the_goals_ramp_time_is_used_but_never_below_the_device_minimum_for_a_goal():
    assert PLANNER.plan(PlateMotion.single(30, [5, 0, 0, 0, 0, 0], ramp_time_s=2.0)).ramp_s == 2.0
    assert CFG.timing.min_ramp_s < CFG.timing.min_goal_ramp_s == 0.2
    for asked in (0.0, 0.05, 0.1):
        ramp = PLANNER.plan(PlateMotion.single(30, [5, 0, 0, 0, 0, 0], ramp_time_s=asked)).ramp_s
        assert ramp == CFG.timing.min_goal_ramp_s


def test_the_table_has_rows_for_the_goals_third_order_distortion_products_where_the_device_allows():
    two = PlateMotion(30.0, [1, 2], [[10, 0, 0, 0, 100, 0], [2, 0, 0, 0, 0, 0]], np.zeros((2, 6)))
    assert PLANNER.plan(two).currents_a.shape == (6, 6)  # 3 x 2
    three = PlateMotion(30.0, [1, 3], [[10, 0, 0, 0, 100, 0], [2, 0, 0, 0, 0, 0]], np.zeros((2, 6)))
    plan = PLANNER.plan(three)
    assert plan.currents_a.shape == (9, 6) and not np.any(plan.currents_a[3:])  # zero rows cost no frames
    # At 100 Hz harmonic 5 is the last within limits.frequency_range_hz (400 Hz): rows stop there.
    assert PLANNER.plan(PlateMotion(100.0, [1, 2], [[5, 0, 0, 0, 0, 0], [1, 0, 0, 0, 0, 0]],
                                    np.zeros((2, 6)))).currents_a.shape == (4, 6)
    narrow = dataclasses.replace(CFG, limits=dataclasses.replace(CFG.limits, max_table_harmonic=5))
    assert GoalPlanner(narrow).plan(three).currents_a.shape == (5, 6)


def test_a_zero_motion_plans_a_zero_table():
    plan = PLANNER.plan(PlateMotion.zero(30.0))
    assert not np.any(plan.currents_a)
    assert plan.contact_margin_mps2 == GRAVITY_MPS2


def rejected(motion, planner=PLANNER):
    with pytest.raises(LimitError) as info:
        planner.plan(motion)
    return info.value


@pytest.mark.parametrize(
    ("motion", "limit", "overrides"),
    [
        (PlateMotion(30.0, [6], [[1, 0, 0, 0, 0, 0]], [[0] * 6]), "limits.max_harmonic", {}),
        (PlateMotion.single(10.0, [1, 0, 0, 0, 0, 0]), "limits.excluded_bands_hz", {}),
        (PlateMotion.single(2.0, [1, 0, 0, 0, 0, 0]), "limits.frequency_range_hz", {}),
        (PlateMotion(90.0, [5], [[1, 0, 0, 0, 0, 0]], [[0] * 6]), "limits.frequency_range_hz", {}),
        (PlateMotion.single(30.0, [40, 0, 0, 0, 0, 0]), "limits.plate_accel_mps2", {}),
        (PlateMotion.single(60.0, [0, 0, 0, 0, 0, 500]), "limits.plate_angular_accel_radps2", {}),
        (LINESINKX.scaled(1.5), "limits.contact_margin_mps2", {}),
        (PlateMotion.single(20.0, [0, 0, 0, 0, 0, 300]), "limits.leg_stroke_m", {}),
        (PlateMotion.single(60.0, [0, 29, 0, 0, 0, 0]), "limits.coil_temperature_c", {}),
        (LINESINKX, "limits.coil_current_a", {"coil_current_a": 1.0}),
        (LINESINKX, "limits.amplifier_voltage_v", {"amplifier_voltage_v": 3.0}),
    ],
)
def test_goals_over_a_limit_are_rejected_naming_the_limit_value_and_request(motion, limit, overrides):
    cfg = CFG.replace("limits", **overrides) if overrides else CFG
    exc = rejected(motion, GoalPlanner(cfg) if overrides else PLANNER)
    assert exc.limit == limit
    assert limit in str(exc)
    assert math.isfinite(exc.limit_value) and math.isfinite(exc.requested)
    name = limit.split(".")[1]
    configured = getattr(cfg.limits, name)
    if name == "contact_margin_mps2":
        assert exc.requested < exc.limit_value == configured
    elif name in ("frequency_range_hz", "excluded_bands_hz"):
        assert exc.requested == pytest.approx(motion.frequency_hz * motion.k.max())
    else:
        assert exc.requested > exc.limit_value == configured


def test_thermal_limit_rejects_a_goal_whose_rms_current_overheats_the_coils():
    cfg = CFG.replace("limits", coil_temperature_c=30.0)
    with pytest.raises(LimitError) as info:
        GoalPlanner(cfg).plan(LINESINKX)
    assert info.value.limit == "limits.coil_temperature_c"
    assert info.value.requested > 30.0
    assert "I^2 R" in str(info.value)


def test_invalid_goals_never_become_a_plate_motion():
    with pytest.raises(ConfigError, match="frequency_hz"):
        PlateMotion.single(-30.0, [1, 0, 0, 0, 0, 0])
    with pytest.raises(ConfigError, match="finite"):
        PlateMotion.single(30.0, [math.nan, 0, 0, 0, 0, 0])
    with pytest.raises(ConfigError, match="1..10"):
        PlateMotion(30.0, [11], [[1, 0, 0, 0, 0, 0]], [[0] * 6])
    with pytest.raises(ConfigError, match="PlateMotion"):
        PLANNER.plan({"frequency_hz": 30})


def test_contact_margin_and_peaks_match_closed_forms():
    motion = PlateMotion.single(25.0, [0, 0, 2.0, 30.0, 40.0, 0])
    # a_n min over the disc: p''z - r |(alpha_x, alpha_y)|, all in phase: 2 + 0.08 * 50 at the peak.
    assert contact_margin(motion, 0.08) == pytest.approx(GRAVITY_MPS2 - 2.0 - 0.08 * 50.0, rel=1e-3)
    acc, ang = plate_peaks(motion)
    assert acc == pytest.approx(2.0, rel=1e-3) and ang == pytest.approx(50.0, rel=1e-3)


def test_corrections_are_added_to_the_feedforward_table():
    plan = PLANNER.plan(LINESINKX)
    corr = np.zeros((3, 6), complex)
    corr[2, 1] = 0.05 + 0.02j  # a third-harmonic correction the goal lacks
    result = PLANNER.correct(plan, corr)
    assert result.limited_by is None and result.scale == 1.0 and not result.step_clipped
    assert np.allclose(result.currents_a - plan.currents_a, corr, atol=2 * CURRENT_LSB_A)


def test_correction_steps_are_clipped_to_the_configured_step_and_reported():
    plan = PLANNER.plan(LINESINKX)
    corr = np.full((1, 6), 1.0 + 0j)
    result = PLANNER.correct(plan, corr, k=np.array([1]))
    assert result.step_clipped
    assert np.allclose(np.abs(result.applied_a[0]), CFG.limits.correction_step_a, atol=2 * CURRENT_LSB_A)
    # Applying the same request again takes the next step from where the last one ended; that
    # step would take LineSinkX past its contact margin (the plate-motion envelope applies to
    # corrected tables too), so it is scaled back and the limit is named.
    again = PLANNER.correct(plan, corr, previous=result.applied_a, k=np.array([1]))
    assert again.limited_by == "limits.contact_margin_mps2" and 0.0 < again.scale < 1.0
    reached = np.abs(again.applied_a[0])
    assert np.all(reached > CFG.limits.correction_step_a) and np.all(reached < 2 * CFG.limits.correction_step_a)
    assert again.envelope.within(1.0 - CORRECTION_GUARD + 1e-9)


@settings(max_examples=25, deadline=None)
@given(
    st.lists(
        st.complex_numbers(max_magnitude=20.0, allow_nan=False, allow_infinity=False),
        min_size=18,
        max_size=18,
    )
)
def test_corrected_tables_never_pass_an_actuator_limit(values):
    cfg = CFG.replace("limits", correction_step_a=50.0, coil_current_a=2.0)
    planner = GoalPlanner(cfg)
    plan = planner.plan(LINESINKX)
    result = planner.correct(plan, np.array(values).reshape(3, 6))
    planner.check_table(result.prediction)  # raises if over a limit
    assert np.max(result.prediction.current_peak_a) <= 2.0
    if result.limited_by is not None:
        assert 0.0 <= result.scale < 1.0


def test_corrections_outside_the_table_are_refused():
    plan = PLANNER.plan(LINESINKX)
    with pytest.raises(ConfigError, match="k: correction harmonics"):
        PLANNER.correct(plan, np.zeros((1, 6)), k=np.array([4]))
    with pytest.raises(ConfigError, match="finite"):
        PLANNER.correct(plan, np.full((3, 6), np.nan))

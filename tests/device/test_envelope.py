"""The one envelope checker: refined extrema, every limit on every corrected table, forbidden rows."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ppod_ros.actuation.corrections import CORRECTION_GUARD
from ppod_ros.actuation.envelope import LIMIT_ORDER, Envelope, refined_max, table_peak
from ppod_ros.actuation.harmonics import synthesize
from ppod_ros.actuation.planning import GoalPlanner
from ppod_ros.device import default_device_config
from ppod_ros.errors import LimitError
from ppod_ros.motion import PlateMotion

CFG = default_device_config()
PLANNER = GoalPlanner(CFG)
LINESINKX = PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0], name="LineSinkX")


def test_refined_peaks_find_the_true_extremum_between_samples():
    # A phase that puts the crest halfway between two of the 64 samples: the grid misses 0.12 %.
    phase = math.pi / 64
    table = np.array([[1.0 * np.exp(1j * phase)], [0.3j]])
    theta = np.linspace(0, 2 * math.pi, 2_000_001)
    exact = np.max(np.abs(np.sin(theta + phase) + 0.3 * np.cos(2 * theta)))
    assert table_peak(table)[0] == pytest.approx(exact, rel=1e-9)
    grid = refined_max(lambda th: np.sin(th + phase)[:, None], 64)
    assert grid[0] == pytest.approx(1.0, abs=1e-12)


def test_the_refinement_column_by_column_finds_what_the_dense_one_does():
    """refined_max's ``at`` evaluates each column only at its own candidates (the dense form evaluates
    every column at every column's candidates and keeps the diagonal): the same extrema."""
    rng = np.random.default_rng(11)
    for k in (np.array([1]), np.array([1, 2, 3])):
        table = rng.normal(size=(k.size, 18)) + 1j * rng.normal(size=(k.size, 18))
        dense = refined_max(lambda th, table=table, k=k: np.abs(synthesize(table, k, th)), 64 * int(k.max()))
        by_column = table_peak(table, k)
        assert np.allclose(by_column, dense, rtol=1e-13, atol=0)
        theta = np.linspace(0, 2 * math.pi, 400_001)
        truth = np.max(np.abs(synthesize(table, k, theta)), axis=0)
        assert np.all(by_column >= truth * (1 - 1e-9)) and np.all(by_column <= truth * (1 + 1e-9))


def test_exact_strokes_of_motions_checked_together_are_each_motions_own():
    env = Envelope(CFG)
    rng = np.random.default_rng(5)
    scale = [2, 2, 1, 20, 20, 20]
    motions = [LINESINKX, LINESINKX.scaled(0.4)] + [
        PlateMotion.from_phasors(30.0, [1], (rng.normal(size=(1, 6)) + 1j * rng.normal(size=(1, 6))) * scale)
        for _ in range(3)]
    together = env.exact_strokes([m.pruned() for m in motions])
    for motion, row in zip(motions, together):
        assert np.array_equal(env.exact_stroke(motion.pruned()), row)


def test_a_goals_report_gives_every_limit_as_a_ratio_that_scales_with_the_amplitude():
    env = Envelope(CFG)
    full = env.check_motion(LINESINKX)
    half = env.check_motion(LINESINKX.scaled(0.5))
    assert set(full.ratios) == set(LIMIT_ORDER)
    for name in LIMIT_ORDER[2:]:
        assert half.ratios[name] == pytest.approx(0.5 * full.ratios[name], rel=2e-3), name
    assert full.worst()[0] == "limits.contact_margin_mps2" and full.within(1.0)
    assert not full.within(1 / 1.15)  # LineSinkX has less than 15 % headroom on its contact margin
    assert full.over(1 / 1.15) == ["limits.contact_margin_mps2"]
    # The table of the goal predicts the goal itself through the nominal plant.
    plan = PLANNER.plan(LINESINKX)
    table = env.check_table(plan.frequency_hz, plan.currents_a)
    for name in LIMIT_ORDER:
        assert table.ratios[name] == pytest.approx(full.ratios[name], rel=1e-4, abs=1e-9), name


def test_motions_checked_together_are_reported_as_each_alone():
    # check_motions shares the vectorised passes of motions of one frequency and harmonics: every
    # report is check_motion's, in order, across groups (a zero motion, two frequencies, two harmonics);
    # for one-harmonic motions (the planner's) bit for bit.
    env = Envelope(CFG)
    rng = np.random.default_rng(7)
    motions = [LINESINKX, LINESINKX.scaled(0.3), PlateMotion.zero(30.0),
               PlateMotion.single(35, [4, 0, 1, 0, 40, 20], [0, 0, 1.0, 0, 2.0, 0.5]), LINESINKX.scaled(1.4)]
    for _ in range(2):
        X = (rng.normal(size=(2, 6)) + 1j * rng.normal(size=(2, 6))) * [2, 2, 1, 20, 20, 20]
        motions.append(PlateMotion.from_phasors(30.0, [1, 2], X))
    together = env.check_motions(motions)
    assert len(together) == len(motions)
    for motion, report in zip(motions, together):
        alone = env.check_motion(motion)
        assert alone.forbidden_rows == report.forbidden_rows and alone.worst_actuator == report.worst_actuator
        for name in LIMIT_ORDER:
            if motion.num_harmonics <= 1:
                assert report.ratios[name] == alone.ratios[name] or (math.isnan(report.values[name])
                                                                     and math.isnan(alone.values[name])), name
            else:   # two harmonics: a wider table's sums may differ in the last bit
                assert report.ratios[name] == pytest.approx(alone.ratios[name], rel=1e-12, abs=1e-15), name
    assert not together[4].within(1.0) and together[1].within(1.0)


def test_a_row_at_a_forbidden_frequency_is_reported_with_an_infinite_ratio():
    env = Envelope(CFG)
    table = np.zeros((3, 6), complex)
    table[0, 0] = 0.01  # 10 Hz: inside the excluded band 3-18 Hz
    report = env.check_table(10.0, table)
    assert report.forbidden_rows == (1,) and report.ratios["limits.excluded_bands_hz"] == math.inf
    err = report.error()
    assert isinstance(err, LimitError) and err.limit == "limits.excluded_bands_hz"
    top = np.zeros((3, 6), complex)
    top[2, 0] = 0.01  # harmonic 3 of 140 Hz = 420 Hz, above the 400 Hz band
    assert env.check_table(140.0, top).over() == ["limits.frequency_range_hz"]


def test_no_correction_ever_reaches_a_row_at_a_forbidden_frequency():
    # Fundamental 10 Hz with only its second harmonic (20 Hz): the table's row 1 (10 Hz) lies in the
    # excluded band. A correction there is dropped and reported; the table's row 1 stays zero.
    goal = PlateMotion(10.0, [2], [[2, 0, 0, 0, 0, 0]], [[0] * 6], name="k2-only")
    plan = PLANNER.plan(goal)
    corr = np.zeros((3, 6), complex)
    corr[0] = 0.05
    corr[2] = 0.01j
    result = PLANNER.correct(plan, corr)
    assert result.blocked_rows == (1,)
    assert not np.any(result.currents_a[0])
    assert np.allclose(result.applied_a[2], 0.01j, atol=4e-6)
    assert result.envelope.forbidden_rows == ()


@settings(max_examples=20, deadline=None)
@given(
    st.lists(st.complex_numbers(max_magnitude=3.0, allow_nan=False, allow_infinity=False), min_size=18,
             max_size=18),
    st.sampled_from([LINESINKX, LINESINKX.scaled(0.3), PlateMotion.single(45, [4, 2, 1, 0, 0, 20])]),
)
def test_corrected_tables_stay_inside_every_limit_of_the_envelope(values, goal):
    planner = GoalPlanner(CFG.replace("limits", correction_step_a=3.0))
    plan = planner.plan(goal)
    result = planner.correct(plan, np.array(values).reshape(3, 6))
    base = planner.plan_envelope(plan).ratios
    for name in LIMIT_ORDER:
        allowed = min(1.0, max(1.0 - CORRECTION_GUARD, base[name]))
        assert result.envelope.ratios[name] <= allowed + 1e-12, name
    # An independent recheck of the table as sent.
    assert planner.envelope.check_table(plan.frequency_hz, result.currents_a).within(1.0)


def test_a_correction_past_the_stroke_is_scaled_back_and_named():
    planner = GoalPlanner(CFG.replace("limits", correction_step_a=5.0, leg_stroke_m=0.0005,
                                      plate_angular_accel_radps2=1e4, plate_accel_mps2=1e3))
    plan = planner.plan(LINESINKX.scaled(0.3))
    yaw = np.array([[1, -1, 1, -1, 1, -1]]) * 3.0 + 0j
    result = planner.correct(plan, yaw, k=np.array([1]))
    assert result.limited_by == "limits.leg_stroke_m" and 0 < result.scale < 1
    assert result.envelope.ratios["limits.leg_stroke_m"] <= 1 - CORRECTION_GUARD + 1e-12


def test_a_ramp_that_does_not_fit_the_protocol_is_rejected_at_planning_naming_the_limit():
    with pytest.raises(LimitError, match="ramp field") as info:
        PLANNER.plan(PlateMotion.single(30, [10, 0, 0, 0, 100, 0], ramp_time_s=70.0))
    assert info.value.limit == "protocol.max_ramp_s" and info.value.requested == 70.0

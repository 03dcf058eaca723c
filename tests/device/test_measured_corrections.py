"""Plate-side limits of a corrected table judged on the measured plate (issue 14, fifth session).

A plate weaker than the nominal model near the contact margin: the correction that makes it do the
accepted goal looks, through the nominal plant, like more than the goal. Judged on the measurement
(measured + P_nominal (T_new - T_measured)) it passes; a measurement that lies cannot push the
nominal prediction past ``limits.plant_model_allowance``.
"""

import dataclasses

import numpy as np
import pytest

from ppod_ros.actuation.corrections import CORRECTION_GUARD, MeasuredTable
from ppod_ros.actuation.envelope import PLATE_LIMITS
from ppod_ros.actuation.planning import GoalPlanner
from ppod_ros.device import default_device_config
from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion, acceleration_error

CFG = default_device_config()
CONTACT = "limits.contact_margin_mps2"
#: LineSinkX scaled to use 98 % of the allowed loss of normal acceleration (its own ratio is 0.908).
GOAL = PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0], name="LineSinkX").scaled(
    0.98 / 0.908
)
WEAK = 0.87  # the true plate does 87 % of what the nominal plant predicts (Sink's stall was 13.4 %)


def with_allowance(allowance: float) -> GoalPlanner:
    limits = dataclasses.replace(CFG.limits, plant_model_allowance=allowance)
    return GoalPlanner(dataclasses.replace(CFG, limits=limits))


def learn(planner: GoalPlanner, gain: float, use_measurement: bool, claimed: float | None = None,
          iterations: int = 8):
    """Learning steps on a plate ``gain`` x nominal, the loop knowing the plant (G = gain P).

    ``claimed``: the plate measurement reports ``claimed`` x nominal instead (a wrong measurement).
    Returns the plan, the last result and the true plate's relative error after each step.
    """
    plan = planner.plan(GOAL)
    f, K = plan.frequency_hz, plan.currents_a.shape[0]
    goal = GOAL.phasor_table(K)
    applied = np.zeros_like(plan.currents_a)
    results, errors = [], []
    for _ in range(iterations):
        nominal = planner.plant.predict(f, plan.currents_a + applied, "accel")
        measured = (gain if claimed is None else claimed) * nominal
        believed = gain if claimed is None else claimed
        step = np.linalg.solve(believed * planner.plant.responses(f * np.arange(1, K + 1), ("accel",))["accel"],
                               (goal - measured)[..., None])[..., 0]
        anchor = MeasuredTable(applied.copy(), measured) if use_measurement else None
        res = planner.correct(plan, applied + step, previous=applied, measured=anchor)
        applied = res.applied_a
        results.append(res)
        true = gain * planner.plant.predict(f, plan.currents_a + applied, "accel")
        errors.append(acceleration_error(goal, true)[1])
    return plan, results, np.array(errors)


def test_through_the_nominal_plant_the_weak_plate_stalls_at_the_contact_margin():
    planner = with_allowance(0.25)
    _, results, errors = learn(planner, WEAK, use_measurement=False)
    assert results[-1].limited_by == CONTACT and results[-1].scale == 0.0
    assert errors[-1] > 0.10  # stuck near the plant's 13 % shortfall


def test_judged_on_the_measured_plate_the_correction_reaches_the_goal_within_the_limits():
    planner = with_allowance(0.25)
    plan, results, errors = learn(planner, WEAK, use_measurement=True)
    assert errors[-1] < 0.01, errors
    allowed = max(1 - CORRECTION_GUARD, planner.plan_envelope(plan).ratios[CONTACT])
    f = plan.frequency_hz
    for res in results:
        # The measured-plate prediction of every table sent is within the limits ...
        assert res.measured_ratios is not None
        assert all(res.measured_ratios[n] <= allowed + 1e-9 for n in PLATE_LIMITS if n == CONTACT)
        # ... and so is the true plate (here weaker than the prediction: the step's model error is on
        # the safe side), while the nominal plant sees more than the limit, within the allowance.
        true = WEAK * planner.plant.predict(f, res.currents_a, "accel")
        assert planner.envelope.check_plate(f, true)[1][CONTACT] <= allowed + 1e-9
        assert res.envelope.ratios[CONTACT] <= allowed + 0.25 + 1e-9
    assert results[-1].envelope.ratios[CONTACT] > 1.0  # the nominal model alone would have refused it


def test_a_measurement_claiming_a_weaker_plate_cannot_push_past_the_allowance():
    # The plate is exactly nominal; the measurement says it does half of that.
    for allowance in (0.25, 0.1):
        planner = with_allowance(allowance)
        plan, results, _ = learn(planner, 1.0, use_measurement=True, claimed=0.5, iterations=12)
        allowed = max(1 - CORRECTION_GUARD, planner.plan_envelope(plan).ratios[CONTACT])
        ratios = [res.envelope.ratios[CONTACT] for res in results]
        assert max(ratios) <= allowed + allowance + 1e-9
        assert max(ratios) > allowed + allowance - 0.01  # it pushed as far as the backstop lets it
        for res in results:
            for name in PLATE_LIMITS:
                base = max(1 - CORRECTION_GUARD, planner.plan_envelope(plan).ratios[name])
                assert res.envelope.ratios[name] <= min(1.0, base) + allowance + 1e-9, name


def test_allowance_zero_judges_through_the_nominal_plant_as_before():
    with_zero = with_allowance(0.0)
    _, with_meas, _ = learn(with_zero, WEAK, use_measurement=True, iterations=3)
    _, without, _ = learn(with_zero, WEAK, use_measurement=False, iterations=3)
    for a, b in zip(with_meas, without):
        assert np.array_equal(a.currents_a, b.currents_a) and a.measured_ratios is None


def test_a_measurement_of_the_wrong_shape_is_refused_naming_the_argument():
    planner = with_allowance(0.25)
    plan = planner.plan(GOAL)
    bad = MeasuredTable(np.zeros((1, 6), complex), np.zeros((3, 6), complex))
    with pytest.raises(ConfigError, match="measured.correction_a"):
        planner.correct(plan, np.zeros_like(plan.currents_a), measured=bad)


def test_table_rows_above_the_measured_harmonics_are_judged_through_the_nominal_plant():
    planner = with_allowance(0.25)
    plan = planner.plan(GOAL)
    f, K = plan.frequency_hz, plan.currents_a.shape[0]
    assert K >= 3
    # A measurement of the fundamental only; the correction asks for current at harmonic 3.
    measured = planner.plant.predict(f, plan.currents_a, "accel")[:1]
    step = np.zeros_like(plan.currents_a)
    step[2] = 0.05
    res = planner.correct(plan, step, measured=MeasuredTable(np.zeros_like(plan.currents_a), measured))
    nominal = planner.plant.predict(f, res.currents_a, "accel")
    expected = planner.envelope.check_plate(f, np.concatenate([measured, nominal[1:]]))[1]
    for name in PLATE_LIMITS:
        assert res.measured_ratios[name] == pytest.approx(expected[name], rel=1e-9)

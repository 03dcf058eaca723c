"""A bounded run of the safety campaign (`ppod bench safety`): its independent checks find nothing."""

from ppod_bench.safety import Checker, bitflips, campaign
from ppod_ros.actuation.planning import GoalPlanner
from ppod_ros.device import default_device_config
from ppod_ros.motion import PlateMotion


def test_the_independent_checker_agrees_with_the_envelope_on_a_goal():
    config = default_device_config()
    planner = GoalPlanner(config)
    plan = planner.plan(PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0]))
    ratios, forbidden = Checker(config).check(plan.frequency_hz, plan.currents_a)
    ours = planner.envelope.check_table(plan.frequency_hz, plan.currents_a).ratios
    assert not forbidden
    for name, r in ratios.items():
        assert abs(r - ours[name]) <= 2e-3 * max(ours[name], 1e-3), name  # stroke: exact vs linear legs


def test_a_short_campaign_with_faults_finds_no_unsafe_table_and_no_exception():
    res = campaign(40, seed=5, drop=0.05, corrupt=0.05, reversals=0.25)
    c = res["counts"]
    assert c["goals"] == 40 and c["tables accepted by the device"] > 0
    assert c.get("over-limit tables", 0) == 0, res["worst"]
    assert c.get("accepted with current at a forbidden frequency", 0) == 0
    assert c.get("accepted tables that differ from what was sent", 0) == 0
    assert c.get("exceptions", 0) == 0, res["exceptions"]
    # A spin near the legs' stroke reversed, with a correction in its ramp, faults nothing.
    assert c.get("reversals (a spin near the stroke limit reversed, corrected in its ramp)", 0) > 0, c
    assert c["device faults (stroke, voltage, current, thermal)"] == 0
    # Corrections judged on a (random, mostly wrong) measured plate were sent too, and stayed within
    # the plate-side limits plus limits.plant_model_allowance on the independent nominal plant.
    assert c.get("corrections judged on a measured plate", 0) > 0, c


def test_no_single_bit_flip_of_any_frame_of_a_table_is_accepted_as_another_table():
    flips = bitflips(1, seed=3)
    assert flips["unaltered tables accepted (control)"] == 1
    assert flips["single-bit variants sent"] > 700
    assert flips["accepted tables that differ from what was sent"] == 0

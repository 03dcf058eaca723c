"""Plant identification, the per-device plant and correction stores, and replay from recordings."""

import math

import numpy as np
import pytest

from ppod_ros.control import (
    CorrectionStore,
    DeviceLimits,
    IdentificationPlan,
    LearningController,
    PlantModel,
    PlantStore,
    identify,
    replay_recording,
    run_identification,
    run_learning,
)
from ppod_ros.errors import ConfigError, LimitError
from ppod_ros.estimation import AccelEstimator, AccelRecording, read_recording, write_recording
from ppod_ros.motion import PlateMotion
from tests.control.rig import LAYOUT, Rig
from tests.control.synthetic_plant import SyntheticPlate, mismatched_response, nominal_response

LINE_SINK_X = PlateMotion(
    30, [1], [[10, 0, 0, 0, 100, 0]], [[0, 0, 0, 0, 3 * math.pi / 2, 0]], name="LineSinkX"
)
LIMITS = DeviceLimits(max_current_a=5.0, max_step_a=2.0)
NOMINAL = PlantModel.from_response(nominal_response, 30.0, [1, 2, 3])


def _true_plate(**kw):
    return SyntheticPlate(mismatched_response(1.15, 10.0, 0.05, seed=2), 30.0, **kw)


def test_plan_drives_one_actuator_at_a_time_per_harmonic_after_a_baseline():
    plan = IdentificationPlan(30.0, (1, 2, 3), [0.2, 0.1, 0.05], settle_cycles=5, measure_cycles=10)
    steps = plan.steps()
    assert len(steps) == 1 + 3 * 6
    assert steps[0].is_baseline and not np.any(steps[0].command_a)
    for step in steps[1:]:
        nonzero = np.argwhere(step.command_a != 0)
        assert nonzero.tolist() == [[plan.k.index(step.k), step.actuator]]
        assert step.command_a[plan.k.index(step.k), step.actuator] == plan.amplitude_a[plan.k.index(step.k)]
    assert plan.duration_s() == pytest.approx(19 * 15 / 30)


def test_identification_recovers_the_true_plant_through_the_accelerometers():
    plate = _true_plate()
    rig = Rig(plate, np.zeros((3, 6)), seed=1)
    plan = IdentificationPlan.scaled_to(NOMINAL, accel_mps2=2.0)
    plant = run_identification(plan, rig.measure_step, limits=LIMITS)
    assert plant.source == "identified"
    true = plate.response(np.array([30.0, 60.0, 90.0]))
    scale = np.array([1, 1, 1, 0.1, 0.1, 0.1])[:, None]
    for i in range(3):
        rel = np.linalg.norm((plant.G[i] - true[i]) * scale) / np.linalg.norm(true[i] * scale)
        assert rel < 0.01
    # The nominal model is 15-20 % off the same plate.
    assert np.linalg.norm((NOMINAL.G[0] - true[0]) * scale) / np.linalg.norm(true[0] * scale) > 0.1


def test_identification_subtracts_what_the_plate_does_without_drive():
    plan = IdentificationPlan(30.0, (1,), 0.5)
    true = nominal_response([30.0])[0]
    offset = np.full((1, 6), 0.3 + 0.1j)  # the plate moves a little without drive (another source)
    measurements = [offset] + [(true @ s.command_a[0] + offset[0])[None] for s in plan.steps()[1:]]
    np.testing.assert_allclose(identify(plan, measurements).G[0], true, atol=1e-12)
    with pytest.raises(ConfigError, match="7 steps in the plan, 6 measurements"):
        identify(plan, measurements[:-1])


def test_a_plan_over_the_current_limit_is_refused_before_driving():
    plan = IdentificationPlan(30.0, (1,), 6.0)
    driven = []
    with pytest.raises(LimitError):
        run_identification(plan, driven.append, limits=LIMITS)
    assert driven == []


def test_plant_store_round_trips_and_is_reused_across_restarts_and_fundamentals(tmp_path):
    store = PlantStore(tmp_path)
    calls = []

    def identify_once():
        calls.append(1)
        return NOMINAL

    plant = store.get_or_identify("ppod-A", 30.0, [1, 2, 3], identify_once)
    again = PlantStore(tmp_path).get_or_identify("ppod-A", 30.0, [1, 2, 3], identify_once)  # a restart
    assert len(calls) == 1
    np.testing.assert_array_equal(again.G, plant.G)
    assert again.source == "nominal"
    # Harmonic 2 at 15 Hz is 30 Hz: it reuses harmonic 1 of the 30 Hz identification.
    half = PlantStore(tmp_path).load("ppod-A", 15.0, [2])
    np.testing.assert_array_equal(half.G[0], NOMINAL.G[0])
    assert PlantStore(tmp_path).load("ppod-A", 15.0, [1, 2]) is None  # 15 Hz itself was never measured
    assert PlantStore(tmp_path).load("ppod-B", 30.0, [1]) is None  # another device
    entries = store.entries("ppod-A")
    assert [e["excitation_hz"] for e in entries] == [30.0, 60.0, 90.0] and entries[1]["k"] == 2
    # Refresh on demand identifies again and overwrites.
    store.get_or_identify("ppod-A", 30.0, [1, 2, 3], identify_once, refresh=True)
    assert len(calls) == 2


def test_plant_store_rejects_bad_device_ids_and_corrupt_files(tmp_path):
    store = PlantStore(tmp_path)
    with pytest.raises(ConfigError, match="device_id"):
        store.save("../etc", NOMINAL)
    store.save("dev", NOMINAL)
    store.path("dev", 30.0).write_bytes(b"not an npz")
    with pytest.raises(ConfigError, match="not a readable cache file"):
        store.load("dev", 30.0, [1])


def test_learned_corrections_are_cached_per_goal_and_survive_a_restart(tmp_path):
    store = CorrectionStore(tmp_path)
    corr = np.arange(18).reshape(3, 6) * (0.01 + 0.02j)
    store.save("ppod-A", LINE_SINK_X, [1, 2, 3], corr, meta={"error_relative": 0.004})
    renamed = PlateMotion.from_dict({**LINE_SINK_X.to_dict(), "name": "same motion, other name"})
    ks, back = CorrectionStore(tmp_path).load("ppod-A", renamed)
    assert ks.tolist() == [1, 2, 3]
    np.testing.assert_array_equal(back, corr)
    assert CorrectionStore(tmp_path).load("ppod-A", LINE_SINK_X.scaled(0.5)) is None
    relaid = CorrectionStore(tmp_path).initial_for("ppod-A", LINE_SINK_X, np.arange(1, 5))
    np.testing.assert_array_equal(relaid[:3], corr)
    np.testing.assert_array_equal(relaid[3], 0)
    memory = CorrectionStore()
    memory.save("ppod-A", LINE_SINK_X, [1, 2, 3], corr)
    assert memory.load("ppod-A", LINE_SINK_X) is not None and memory.load("ppod-B", LINE_SINK_X) is None


def test_a_cached_correction_starts_the_loop_converged():
    plate = _true_plate(third=0.03)
    first = LearningController(LINE_SINK_X, NOMINAL, LIMITS)
    rig = Rig(plate, first.feedforward_a, seed=3)
    run_learning(first, rig.measure, max_iterations=8)
    store = CorrectionStore()
    store.save("ppod-A", LINE_SINK_X, first.k, first.correction_a)
    second = LearningController(
        LINE_SINK_X, NOMINAL, LIMITS, initial_correction_a=store.initial_for("ppod-A", LINE_SINK_X, first.k)
    )
    step = second.update(rig.measure(second.correction_a))
    assert step.converged and step.iteration == 1


def test_estimation_and_control_replay_from_a_recorded_session_gives_the_live_decisions(tmp_path):
    plate = _true_plate(third=0.03)
    live = LearningController(LINE_SINK_X, NOMINAL, LIMITS)
    rig = Rig(plate, live.feedforward_a, seed=4)
    applied = []

    def measure(correction):
        applied.append(live.feedforward_a + correction)
        return rig.measure(correction)

    result = run_learning(live, measure, max_iterations=4, stop_when_converged=False)
    t = np.concatenate([rec[0] for rec in rig.records])
    r = np.concatenate([rec[1] for rec in rig.records])
    seg = np.concatenate([np.full(rec[0].size, i) for i, rec in enumerate(rig.records)])
    rec = AccelRecording(
        30.0, LAYOUT.names, t, r, seg, command_k=live.k, commands_a=np.array(applied), goal=LINE_SINK_X
    )
    back = read_recording(write_recording(rec, tmp_path / "session.npz"))
    replayed = replay_recording(
        back, AccelEstimator(LAYOUT), LearningController(LINE_SINK_X, NOMINAL, LIMITS)
    )
    assert len(replayed) == 4
    for (est, step), live_step in zip(replayed, result.steps):
        assert not est.dropped and est.cycles == pytest.approx(10, abs=0.01)
        np.testing.assert_allclose(step.correction_a, live_step.correction_a, atol=1e-9)
        assert step.error_relative == pytest.approx(live_step.error_relative, rel=1e-9)
    with pytest.raises(ConfigError, match="goal differs"):
        replay_recording(
            back, AccelEstimator(LAYOUT), LearningController(LINE_SINK_X.scaled(0.5), NOMINAL, LIMITS)
        )

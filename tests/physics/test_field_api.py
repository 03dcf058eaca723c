"""solve_field's contract: shapes, JSON layout, grid order, cache, skipping, input checks."""

import json
import math

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion
from ppod_ros.parts import PointPart
from ppod_ros.physics import PRESETS, FieldCache, SolverSettings, grid_configs, preset, solve_field
from tests.physics.physics_suite import suite_motion


def test_results_have_the_documented_shapes_and_are_read_only(point_part, rigid_part, line_sink_x):
    r = solve_field(line_sink_x, point_part, grid_configs([0.0, 0.05, 0.1], [0.0]))
    assert r.configs.shape == r.velocity.shape == r.cycle_start.shape == (3, 2)
    assert r.valid.shape == r.reason_code.shape == r.periods.shape == r.stick_fraction.shape == (3,)
    assert r.seconds >= 0 and r.setup_seconds >= 0 and len(r) == 3
    with pytest.raises(ValueError):
        r.velocity[0, 0] = 1.0
    rr = solve_field(suite_motion("RigidU1"), rigid_part, [[0.0, 0.0, 1.0]])
    assert rr.velocity.shape == (1, 3) and rr.part_kind == "rigid"


def test_json_follows_the_formats_layout(point_part, line_sink_x):
    r = solve_field(line_sink_x, point_part, grid_configs([0.0, 0.1], [0.0]))
    d = json.loads(r.to_json())
    assert {"configs", "velocity", "valid", "reason", "seconds"} <= set(d)
    assert d["configs"] == [[0.0, 0.0], [0.1, 0.0]]
    assert d["velocity"][1] is None and d["valid"] == [True, False]
    assert d["reason"] == [None, "contact lost"]
    assert isinstance(d["velocity"][0], list) and len(d["velocity"][0]) == 2


def test_grids_vary_x_fastest_then_y_then_theta():
    g = grid_configs([1, 2], [3, 4], [5, 6])
    assert g[:4].tolist() == [[1, 3, 5], [2, 3, 5], [1, 4, 5], [2, 4, 5]]
    assert g[4, 2] == 6


def test_the_cache_answers_repeated_configurations_with_identical_results(point_part):
    m = suite_motion("Sink")
    cache = FieldCache()
    cfg = grid_configs([-0.02, 0.0, 0.02], [0.01])
    a = solve_field(m, point_part, cfg, cache=cache)
    b = solve_field(m, point_part, np.vstack([cfg, [[0.03, 0.03]]]), cache=cache)
    assert a.cache_hits == 0 and b.cache_hits == 3
    assert np.array_equal(a.velocity, b.velocity[:3])
    c = solve_field(m, PointPart(0.31), cfg, cache=cache)  # another part is another key
    assert c.cache_hits == 0


def test_the_cache_forgets_whole_groups_beyond_its_size(point_part):
    cache = FieldCache(max_entries=4)
    for name in ("Sink", "LineSinkX"):
        solve_field(suite_motion(name), point_part, grid_configs([0.0, 0.01, 0.02], [0.0]), cache=cache)
    assert len(cache) == 3


def test_zero_amplitude_harmonics_change_nothing_and_pruning_them_is_the_default(point_part):
    m = suite_motion("Sink")
    padded = PlateMotion(m.frequency_hz, np.arange(1, 11), np.vstack([m.amplitude, np.zeros((9, 6))]),
                         np.vstack([m.phase, np.ones((9, 6))]))
    cfg = [[0.02, -0.01], [0.05, 0.04]]
    a = solve_field(m, point_part, cfg, SolverSettings(cache=False))
    b = solve_field(padded, point_part, cfg, SolverSettings(cache=False))
    c = solve_field(padded, point_part, cfg, SolverSettings(cache=False, prune_harmonics=False))
    assert np.array_equal(a.velocity, b.velocity)
    assert np.abs(a.velocity - c.velocity).max() < 1e-7


def test_skipping_impossible_sticking_changes_nothing(point_part, rigid_part):
    cfg = [[0.02, -0.01], [0.05, 0.04]]
    for m in (suite_motion("Sink"), suite_motion("LineSinkX")):
        a = solve_field(m, point_part, cfg, SolverSettings(cache=False))
        b = solve_field(m, point_part, cfg, SolverSettings(cache=False, skip_sticking=False))
        assert np.abs(a.velocity - b.velocity).max() < 1e-9
    rc = [[0.02, 0.0, 0.4]]
    a = solve_field(suite_motion("RigidU1"), rigid_part, rc, SolverSettings(cache=False))
    b = solve_field(suite_motion("RigidU1"), rigid_part, rc, SolverSettings(cache=False, skip_sticking=False))
    assert np.abs(a.velocity - b.velocity).max() < 1e-9


def test_threads_and_progress_do_not_change_the_result(point_part):
    m = suite_motion("Swirl3H")
    cfg = grid_configs(np.linspace(-0.05, 0.05, 9), np.linspace(-0.05, 0.05, 9))
    seen = []
    a = solve_field(m, point_part, cfg, SolverSettings(cache=False))
    b = solve_field(m, point_part, cfg, SolverSettings(cache=False, threads=1),
                    progress=lambda done, total: seen.append(done))
    assert np.array_equal(a.velocity, b.velocity, equal_nan=True)
    assert seen[-1] == len(cfg) and seen == sorted(seen)


def test_invalid_configurations_are_not_integrated(point_part):
    r = solve_field(suite_motion("NearContactLoss"), point_part, [[0.09, 0.0], [0.0, 0.0]])
    assert r.periods[0] == 0 and r.reason[0] == "contact lost" and r.valid[1]


@pytest.mark.parametrize(("configs", "match"), [
    ([[0.0, math.nan]], "configs: row 0 is not finite"),
    ([[0.0, 0.0, 0.0]], r"configs: expected shape \(N, 2\)"),
    ("abc", "configs"),
])
def test_bad_configurations_are_errors_naming_the_argument(point_part, line_sink_x, configs, match):
    with pytest.raises(ConfigError, match=match):
        solve_field(line_sink_x, point_part, configs)


def test_bad_inputs_are_errors_naming_the_field(point_part, line_sink_x):
    with pytest.raises(ConfigError, match="motion"):
        solve_field("LineSinkX", point_part, [[0, 0]])
    with pytest.raises(ConfigError, match="part"):
        solve_field(line_sink_x, 0.3, [[0, 0]])
    with pytest.raises(ConfigError, match="mu"):
        PointPart(-0.1)
    with pytest.raises(ConfigError, match="frequency_hz"):
        PlateMotion.single(0.0, [1, 0, 0, 0, 0, 0])
    with pytest.raises(ConfigError, match="frequency_hz"):
        PlateMotion.from_yaml_text("frequency_hz: -3\nharmonics: []\n")
    with pytest.raises(ConfigError, match="colour"):
        PlateMotion.from_yaml_text("frequency_hz: 3\ncolour: red\n")
    with pytest.raises(ConfigError, match="initial"):
        solve_field(line_sink_x, point_part, [[0, 0]], initial=[[0, 0], [1, 1]])


def test_settings_are_validated_and_methods_chosen_by_name():
    with pytest.raises(ConfigError, match="integrator"):
        SolverSettings(integrator="euler")
    with pytest.raises(ConfigError, match="fixed_point"):
        SolverSettings(fixed_point="newtonish")
    with pytest.raises(ConfigError, match="rtol"):
        SolverSettings(rtol=-1.0)
    with pytest.raises(ConfigError, match="max_periods"):
        SolverSettings(max_periods=0)
    with pytest.raises(ConfigError, match="preset"):
        preset("fastest")
    with pytest.raises(ConfigError, match="unknown option"):
        SolverSettings().replace(speed=3)
    assert set(PRESETS) == {"fast", "default", "accurate", "reference"}
    assert SolverSettings().cache_key() != SolverSettings(rtol=1e-7).cache_key()
    assert SolverSettings(threads=1).cache_key() == SolverSettings().cache_key()


def test_calls_that_differ_only_in_their_work_caps_share_warm_starts():
    """A converged limit cycle does not depend on max_periods / max_steps_per_period: a capped
    call (the planner's budgeted probes) starts from the cycle an uncapped call found, converges in
    one period, to within the tolerance of the cold answer, and adds no second warm-start entry
    per configuration."""
    from ppod_ros.physics import WarmStarts, solve_fields

    base = PRESETS["fast"].replace(cache=False, threads=1)
    capped = base.replace(max_periods=12, max_steps_per_period=200)
    assert capped.cache_key() != base.cache_key() and capped.warm_key() == base.warm_key()
    assert base.replace(rtol=1e-7).warm_key() != base.warm_key()
    motion, part, cfg = suite_motion("Sink"), PointPart(0.3), np.array([[0.03, 0.01], [-0.02, 0.04]])
    warm = WarmStarts()
    cold = solve_fields([motion], part, cfg, settings=base, warm=warm)
    again = solve_fields([motion], part, cfg, settings=capped, warm=warm)
    assert cold.periods.min() >= 2 and again.periods.max() == 1
    assert np.abs(again.velocity - cold.velocity).max() <= 1e-5 * np.abs(cold.velocity).max()
    assert len(warm) == len(cfg)

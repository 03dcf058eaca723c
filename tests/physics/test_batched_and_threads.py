"""solve_fields (many motions x configurations in one call), the serial/parallel choice, warm
starts from previous calls, and one StickingHeavy preset."""

from pathlib import Path

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion
from ppod_ros.physics import (
    PRESETS,
    PartDynamics,
    SolverSettings,
    WarmStarts,
    _threads,
    grid_configs,
    solve_field,
    solve_fields,
)
from tests.physics.physics_suite import CONFIG, suite_motion

NOCACHE = SolverSettings(cache=False)


@pytest.fixture
def forced(monkeypatch):
    """Force the parallel kernels (threshold 0) or the serial ones (threshold infinite)."""
    def force(parallel: bool):
        if parallel:  # loaded: an unloaded parallel kernel also needs PARALLEL_LOAD_S of expected work
            from ppod_ros.physics._params import ALL_KERNELS, ensure_compiled

            ensure_compiled(*[k for k in ALL_KERNELS if k[2]])
        monkeypatch.setattr(_threads, "PARALLEL_MIN_SECONDS", 0.0 if parallel else float("inf"))
    return force


def test_serial_and_parallel_kernels_give_identical_fields(point_part, forced):
    m = suite_motion("Sink")
    cfg = grid_configs(np.linspace(-0.08, 0.08, 9), np.linspace(-0.08, 0.08, 9))
    forced(False)
    a = solve_field(m, point_part, cfg, NOCACHE)
    forced(True)
    b = solve_field(m, point_part, cfg, NOCACHE.replace(threads=2))
    assert np.array_equal(a.velocity, b.velocity, equal_nan=True)
    assert np.array_equal(a.periods, b.periods)


def test_serial_and_parallel_dynamics_give_identical_trajectories(point_part, rigid_part, forced):
    m = suite_motion("Sink")
    cfg = [[0.05, 0.0, 0.0], [-0.03, 0.02, 0.0], [0.0, 0.04, 0.5]]
    out = []
    for parallel in (False, True):
        forced(parallel)
        sim = PartDynamics([point_part, point_part, rigid_part], cfg)
        for k in range(3):
            sim.advance(m, k * 0.05, 0.05)
        out.append(sim.state.configurations)
    assert np.array_equal(out[0], out[1])


def test_small_calls_plan_serial_and_large_ones_parallel_by_learnt_cost(monkeypatch):
    monkeypatch.setattr(_threads, "_cost", dict(_threads.SEED_COST_S))
    monkeypatch.setattr(_threads, "available_threads", lambda: 2)
    assert _threads.plan("field0", 37, None) == 1
    assert _threads.plan("field0", 100_000, None) == 2
    assert _threads.plan("field0", 100_000, 1) == 1  # threads=1: always serial
    _threads.learn("dyn0", 10, 10.0, 1)  # a very slow call raises the learnt cost
    assert _threads.plan("dyn0", 10, None) == 2


def test_stalled_parallel_calls_never_turn_small_calls_parallel(monkeypatch):
    # On a busy 2-core machine each parallel call waits ~16 ms for its second thread whatever the
    # work; learnt as cost, that kept 10-part dynamics cycles parallel (and stalling) for good.
    monkeypatch.setattr(_threads, "_cost", dict(_threads.SEED_COST_S))
    monkeypatch.setattr(_threads, "available_threads", lambda: 2)
    for _ in range(20):
        _threads.learn("dyn0", 10, 0.016, 2)
    assert _threads.plan("dyn0", 10, None) == 1
    assert _threads.COST_SMOOTHING > 0.0
    _threads.learn("dyn0", 1000, 1e-4, 2)  # a fast parallel call does lower the estimate
    assert _threads._cost["dyn0"] < _threads.SEED_COST_S["dyn0"]


def test_serial_calls_learn_their_cost_from_the_threads_cpu_time_not_the_wall_time(monkeypatch):
    # A serial call preempted for 50 ms by another process did 0.5 ms of work.
    monkeypatch.setattr(_threads, "_cost", dict(_threads.SEED_COST_S))
    monkeypatch.setattr(_threads, "available_threads", lambda: 2)
    for _ in range(20):
        _threads.learn("dyn0", 10, 0.05, 1, cpu_seconds=0.0005)
    assert abs(_threads._cost["dyn0"] - 5e-5) < 1e-6
    assert _threads.plan("dyn0", 10, None) == 1


def test_small_dynamics_stay_serial_after_parallel_calls_that_stalled(monkeypatch, point_part):
    import time

    from ppod_ros.physics import dynamics
    from ppod_ros.physics._params import ensure_compiled

    ensure_compiled(("dyn", 0, True))  # loaded: the forced calls below do run in parallel
    monkeypatch.setattr(_threads, "_cost", dict(_threads.SEED_COST_S))
    monkeypatch.setattr(_threads, "available_threads", lambda: 2)
    real_parallel, real_plan = dynamics.advance_group, _threads.plan

    def stalled(*args):  # the second thread's wake-up on a busy core: waiting, no work
        real_parallel(*args)
        time.sleep(0.02)

    chosen = []
    monkeypatch.setattr(dynamics, "advance_group", stalled)
    monkeypatch.setattr(_threads, "plan", lambda *a, **k: chosen.append(real_plan(*a, **k)) or chosen[-1])
    m = suite_motion("Sink")
    sim = PartDynamics([point_part] * 10, np.column_stack([np.linspace(-0.05, 0.05, 10), np.zeros(10)]))
    with monkeypatch.context() as forced:
        forced.setattr(_threads, "PARALLEL_MIN_SECONDS", 0.0)
        for k in range(8):
            sim.advance(m, k * m.period_s, m.period_s)
    auto = len(chosen)
    for k in range(8, 11):
        sim.advance(m, k * m.period_s, m.period_s)
    assert chosen[:auto] == [2] * auto
    assert chosen[auto:] == [1, 1, 1]


def test_a_process_without_the_parallel_kernel_loads_it_only_for_larger_work(monkeypatch):
    monkeypatch.setattr(_threads, "_cost", dict(_threads.SEED_COST_S))
    monkeypatch.setattr(_threads, "available_threads", lambda: 2)
    units = 441  # ppod field's default 21 x 21 grid: about 0.09 s expected serially
    assert _threads.plan("field0", units, None, parallel_ready=True) == 2
    assert _threads.plan("field0", units, None, parallel_ready=False) == 1
    assert _threads.plan("field0", 100_000, None, parallel_ready=False) == 2


def test_solve_fields_matches_solve_field_per_motion_with_shared_and_per_motion_configs(point_part):
    motions = [suite_motion("LineSinkX"), suite_motion("Sink"), suite_motion("Swirl3H")]
    cfg = grid_configs(np.linspace(-0.06, 0.06, 4), np.linspace(-0.06, 0.06, 3))
    r = solve_fields(motions, point_part, cfg, NOCACHE, warm=False)
    assert r.velocity.shape == (3, 12, 2) and r.valid.shape == (3, 12) and r.periods.shape == (3, 12)
    assert r.reason.shape == (3, 12) and len(r) == 3 and r.motion_names == ("LineSinkX", "Sink", "Swirl3H")
    for m, motion in enumerate(motions):
        one = solve_field(motion, point_part, cfg, NOCACHE)
        assert np.array_equal(one.velocity, r.velocity[m], equal_nan=True)
        assert np.array_equal(one.valid, r.valid[m])
        assert r.field(m).motion_name == motion.name
    per = np.stack([cfg, cfg[::-1], cfg + 0.001])
    rp = solve_fields(motions, point_part, per, NOCACHE, warm=False)
    assert np.allclose(rp.velocity[1], solve_field(motions[1], point_part, cfg[::-1], NOCACHE).velocity,
                       equal_nan=True, atol=1e-9)
    with pytest.raises(ConfigError, match="configs"):
        solve_fields(motions, point_part, np.zeros((2, 4, 2)))
    with pytest.raises(ConfigError, match="motions"):
        solve_fields([], point_part, cfg)
    with pytest.raises(ConfigError, match=r"motions\[1\]"):
        solve_fields([motions[0], "Sink"], point_part, cfg)


def test_solve_fields_rigid_part_and_cache_hits(rigid_part):
    u1 = suite_motion("RigidU1")
    cfg = grid_configs([0.0, 0.02], [0.0], [0.0, 1.0])
    r = solve_fields([u1, u1], rigid_part, cfg, SolverSettings(), warm=False)
    assert r.velocity.shape == (2, 4, 3)
    assert np.allclose(r.velocity[0], r.velocity[1], equal_nan=True)
    again = solve_fields([u1], rigid_part, cfg, SolverSettings(), warm=False)
    assert again.cache_hits == 4 and np.all(again.periods == 0)


def test_warm_starts_from_a_previous_call_cost_about_one_period_at_the_same_accuracy(point_part):
    sink = suite_motion("Sink")
    cfg = np.random.default_rng(3).uniform(-0.06, 0.06, (30, 2))
    warm = WarmStarts()
    cold = solve_fields([sink], point_part, cfg, NOCACHE, warm=warm)
    # A design Jacobian's perturbed motion: the amplitudes changed by 1e-4.
    near = PlateMotion(sink.frequency_hz, sink.k, sink.amplitude * 1.0001, sink.phase)
    fresh = solve_fields([near], point_part, cfg, NOCACHE, warm=False)
    again = solve_fields([near], point_part, cfg, NOCACHE, warm=warm)
    ok = fresh.valid[0]
    assert again.periods[0][ok].mean() < 0.7 * fresh.periods[0][ok].mean()
    # The same accuracy: both within the fixed-point tolerance (fixed_point_rtol x this motion's
    # velocity scale, 0.075 m/s) of the accurate preset (each may sit on either side of it).
    ref = solve_fields([near], point_part, cfg, PRESETS["accurate"].replace(cache=False), warm=False)
    tol = 1e-5 * 0.075
    for r in (fresh, again):
        assert np.abs(r.velocity[0][ok] - ref.velocity[0][ok]).max() < tol
    assert len(warm) == int(cold.valid.sum())


def _candidates(sink, calls, seed=2):
    """A planner's candidates: the motion's amplitudes changed by about 1 % from call to call."""
    rng = np.random.default_rng(seed)
    scale = 1.0 + 0.01 * rng.standard_normal((calls,) + sink.amplitude.shape)
    return [PlateMotion(sink.frequency_hz, sink.k, sink.amplitude * f, sink.phase) for f in scale]


def test_warm_starts_carry_each_configurations_own_secant_differences_to_the_next_call(point_part, monkeypatch):
    sink = suite_motion("Sink")
    cfg = np.random.default_rng(1).uniform(-0.06, 0.06, (37, 2))
    motions = _candidates(sink, 5)
    own = WarmStarts()
    runs = [solve_fields([m], point_part, cfg, NOCACHE, warm=own) for m in motions]
    # The same calls with the stored differences withheld: the first step uses the previous
    # configuration's (a point elsewhere on the plate), as it did before.
    real = WarmStarts.secants
    monkeypatch.setattr(WarmStarts, "secants", lambda self, *a: tuple(np.zeros_like(x) for x in real(self, *a)))
    neighbour = WarmStarts()
    before = [solve_fields([m], point_part, cfg, NOCACHE, warm=neighbour) for m in motions]
    def mean_periods(results):
        return np.mean([r.periods[0][r.valid[0]].mean() for r in results[1:]])

    assert mean_periods(runs) < 0.85 * mean_periods(before)
    # At the accuracy of a fresh solve: within the fixed-point tolerance (1e-5 x the velocity
    # scale, about 0.075 m/s here) of the accurate preset.
    accurate = PRESETS["accurate"].replace(cache=False)
    for m, r in zip(motions[1:], runs[1:]):
        ref = solve_fields([m], point_part, cfg, accurate, warm=False)
        ok = r.valid[0]
        assert np.abs(r.velocity[0][ok] - ref.velocity[0][ok]).max() < 1e-5 * 0.075 * 1.5


def test_warm_starts_with_secant_differences_give_the_same_fields_serial_and_parallel(point_part, forced):
    from ppod_ros.physics._params import ensure_compiled

    ensure_compiled(("field", 0, True))  # loaded, so that the forced calls do run in parallel
    sink = suite_motion("Sink")
    cfg = np.random.default_rng(4).uniform(-0.06, 0.06, (20, 2))
    out = []
    for parallel in (False, True):
        forced(parallel)
        warm = WarmStarts()
        settings = NOCACHE.replace(threads=2) if parallel else NOCACHE
        out.append([solve_fields([m], point_part, cfg, settings, warm=warm) for m in _candidates(sink, 3, seed=5)])
    for a, b in zip(*out):
        assert np.array_equal(a.velocity, b.velocity, equal_nan=True)
        assert np.array_equal(a.periods, b.periods)
    assert out[1][-1].threads == 2 and out[0][-1].threads == 1


def test_warm_starts_keep_a_configurations_secant_differences_until_new_ones_come():
    warm = WarmStarts()
    cfg = np.array([[0.01, 0.02], [0.03, 0.04]])
    dx = np.arange(8.0).reshape(2, 2, 2)
    warm.store(("p", "s"), cfg, np.ones((2, 2)), np.full(2, 0.1), np.array([True, True]),
               (dx, -dx, np.array([2, 1])))
    sx, sf, sn = warm.secants(("p", "s"), cfg, 2, 2)
    assert sn.tolist() == [2, 1]
    assert np.array_equal(sx[0], dx[0]) and np.array_equal(sf[0], -dx[0]) and np.array_equal(sx[1, 0], dx[1, 0])
    warm.store(("p", "s"), cfg, np.zeros((2, 2)), np.full(2, 0.2), np.array([True, True]),
               (dx * 0, dx * 0, np.array([0, 0])))  # converged without new differences: the old ones stay
    assert np.array_equal(warm.secants(("p", "s"), cfg, 2, 2)[0], sx)
    assert warm.secants(("p", "s"), cfg, 2, 1)[2].tolist() == [1, 1]  # the newest rows when fewer fit
    assert np.array_equal(warm.secants(("p", "s"), cfg, 2, 1)[0][0, 0], dx[0, 1])
    assert warm.lookup(("p", "s"), cfg, 2)[1].tolist() == [0.2, 0.2]


def test_one_sticking_heavy_motion_for_the_benchmark_and_the_goal_presets():
    data = Path(__file__).resolve().parents[2] / "ppod_ros" / "data" / "motions"
    for path in sorted(data.glob("*.yaml")):
        twin = CONFIG / "motions" / path.name
        if twin.exists():
            assert twin.read_text() == path.read_text(), f"{path.name} differs between the preset and config copies"
    assert PlateMotion.from_yaml(data / "StickingHeavy.yaml").key == suite_motion("StickingHeavy").key


def test_grid_neighbours_converge_in_about_two_periods_at_the_same_accuracy(point_part):
    """Along a grid row each configuration starts from its neighbours' limit cycles and takes its
    first step with the neighbour's secant differences: after a chunk's first two configurations,
    two or three periods each (two: the convergence test's minimum), within the tolerance of a tight
    solve."""
    sink = suite_motion("Sink")
    xs = np.linspace(-0.06, 0.06, 41)
    cfg = grid_configs(xs, np.array([-0.02, 0.01]))
    r = solve_field(sink, point_part, cfg, NOCACHE)
    assert r.valid.all()
    later = np.arange(len(cfg)) % NOCACHE.chunk_for(len(cfg)) >= 2
    assert r.periods[later].mean() <= 2.5  # about 3 with the plain first step (3.04 on Sink 101 x 101)
    tight = solve_field(sink, point_part, cfg[::7], NOCACHE.replace(fixed_point_rtol=1e-8, warm_start=False))
    tol = 1e-5 * 0.06  # fixed_point_rtol x a velocity scale of this motion
    assert np.abs(r.velocity[::7] - tight.velocity).max() < tol


def test_large_grids_take_long_chunks_and_converge_in_under_two_periods_at_the_same_accuracy(point_part):
    """From 1024 configurations per motion chunks are 32 long: each configuration after the fourth
    of a chunk starts from the cubic through its neighbours' limit cycles, with the neighbour's rate
    as the first period's prior, so one period often proves convergence."""
    sink = suite_motion("Sink")
    xs = np.linspace(-0.1, 0.1, 101)
    cfg = grid_configs(xs, xs)
    assert NOCACHE.chunk_for(len(cfg)) == 32 and NOCACHE.chunk_for(1023) == 8
    r = solve_field(sink, point_part, cfg, NOCACHE)
    integrated = r.periods > 0
    assert r.periods[integrated].mean() <= 1.8  # 2.68 with chunks of 8 and no prior
    short = solve_field(sink, point_part, cfg, NOCACHE.replace(chunk=8))
    assert short.periods[integrated].mean() >= 2.5
    # The same accuracy: a sample within the fixed-point tolerance of a tight solve.
    pick = np.flatnonzero(r.valid)[::97]
    tight = solve_field(sink, point_part, cfg[pick], NOCACHE.replace(fixed_point_rtol=1e-8, warm_start=False))
    ok = tight.valid
    assert ok.mean() > 0.9
    tol = 1e-5 * 0.075  # fixed_point_rtol x this motion's velocity scale
    assert np.abs(r.velocity[pick][ok] - tight.velocity[ok]).max() < tol
    assert np.abs(short.velocity[pick][ok] - tight.velocity[ok]).max() < tol


def test_small_calls_keep_chunks_of_eight_bit_for_bit(point_part):
    sink = suite_motion("Sink")
    cfg = grid_configs(np.linspace(-0.06, 0.06, 21), np.linspace(-0.06, 0.06, 21))
    auto = solve_field(sink, point_part, cfg, NOCACHE)
    eight = solve_field(sink, point_part, cfg, NOCACHE.replace(chunk=8))
    assert np.array_equal(auto.velocity, eight.velocity, equal_nan=True)
    assert np.array_equal(auto.periods, eight.periods)


def test_chunk_setting_accepts_none_or_a_positive_integer():
    assert SolverSettings().chunk is None and SolverSettings(chunk=16).chunk_for(10**6) == 16
    with pytest.raises(ConfigError, match="chunk"):
        SolverSettings(chunk=0)

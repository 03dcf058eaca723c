"""Starting guesses of the stepped fixed point (issue 13, eighth pass): nearly-collinear motions on
large grids start from the closed form plus their neighbours' extrapolated departures from theirs,
so they take fewer periods at the same accuracy against the independent fixed-step reference."""

import numpy as np

from ppod_bench.fixed_step_reference import reference_average
from ppod_ros.physics import SolverSettings, grid_configs, solve_field
from tests.physics.physics_suite import suite_motion


def test_nearly_collinear_long_chunks_start_from_the_extrapolated_departure(point_part):
    """LineSinkXPlant (a_h nearly collinear, above the expansion's threshold: the stepped path) on a
    33 x 33 grid (long chunks): 2.21 periods per integrated configuration from the closed-form start
    alone (51 x 51, before), at most 1.9 now; the answers stay within 1.5e-6 m/s of the reference."""
    m = suite_motion("LineSinkXPlant")
    xs = np.linspace(-0.1, 0.1, 33)
    cfg = grid_configs(xs, xs)
    r = solve_field(m, point_part, cfg, SolverSettings(cache=False))
    integrated = r.periods > 0
    assert integrated.sum() > 900
    assert r.periods[integrated].mean() <= 1.9
    ok = np.flatnonzero(r.valid)
    for i in ok[:: ok.size // 4][:4]:
        ref, _ = reference_average(m, point_part.mu, cfg[i, 0], cfg[i, 1], start=r.cycle_start[i])
        assert np.abs(ref - r.velocity[i]).max() < 1.5e-6, cfg[i]


def test_scattered_cold_configurations_start_from_the_plane_through_their_nearest(point_part):
    """37 scattered configurations from cold (the planner's and the simulator's small calls): each
    starts from the plane through the nearest three converged ones of its chunk and takes its first
    steps with the nearest's secant differences: 5.16 periods per configuration before (each from
    the previous configuration's start), at most 4.5 now, within 1.5e-6 m/s of the reference."""
    m = suite_motion("Sink")
    cfg = np.random.default_rng(1).uniform(-0.06, 0.06, (37, 2))
    r = solve_field(m, point_part, cfg, SolverSettings(cache=False))
    assert r.valid.all()
    assert r.periods.mean() <= 4.5
    for i in (3, 11, 20, 30, 36):
        ref, _ = reference_average(m, point_part.mu, cfg[i, 0], cfg[i, 1], start=r.cycle_start[i])
        assert np.abs(ref - r.velocity[i]).max() < 1.5e-6, cfg[i]
    # The order of the configurations changes the starts, not the answers beyond the tolerance.
    back = solve_field(m, point_part, cfg[::-1], SolverSettings(cache=False))
    assert np.abs(back.velocity[::-1] - r.velocity).max() < 2e-6


def test_one_harmonic_minimum_normal_acceleration_is_exact():
    """The contact-loss check's minimum of g + a_n over the cycle: exact for one harmonic, equal to
    a dense sampling to 1e-9 (and never above it); several harmonics keep the refined scan."""
    from ppod_ros.physics.plate import G, min_normal_accel, motion_table

    rng = np.random.default_rng(3)
    for name in ("Sink", "LineSinkXPlant", "Swirl3H"):
        m = suite_motion(name)
        mc = motion_table(m)
        t = np.linspace(0.0, m.period_s, 200001)
        for x, y in rng.uniform(-0.1, 0.1, (5, 2)):
            n = np.full_like(t, G)
            for r in mc:
                ph = r[0] * t
                n += (r[3] + r[4] * y - r[5] * x) * np.sin(ph) + (r[9] + r[10] * y - r[11] * x) * np.cos(ph)
            got = min_normal_accel(mc, x, y, m.period_s, 64 * mc.shape[0])
            assert got <= n.min() + 1e-9 * abs(n.min())
            assert abs(got - n.min()) < 1e-6, (name, x, y)


def test_repeated_and_collinear_scattered_configurations_stay_finite():
    """No plane through repeated or collinear configurations (hypothesis found four copies of
    (0, 0) answered NaN yet flagged valid): they start from the nearest's cycle start."""
    from ppod_ros.motion import PlateMotion
    from ppod_ros.parts import PointPart

    m = PlateMotion(frequency_hz=10.0, k=np.array([1]), amplitude=np.array([[1.0, 1.0, 0, 0, 0, 0]]),
                    phase=np.array([[0.0, 1.0, 0, 0, 0, 0]]))
    for cfg in ([(0.0, 0.0)] * 4, [(0.0, 0.0), (0.01, 0.0), (0.02, 0.0), (0.0, 0.0), (0.035, 0.0)]):
        r = solve_field(m, PointPart(1.0), cfg, SolverSettings(cache=False))
        assert r.valid.all() and np.isfinite(r.velocity).all()
        one = solve_field(m, PointPart(1.0), cfg[:1], SolverSettings(cache=False))
        assert np.abs(r.velocity - one.velocity[0]).max() < 1e-6
    sink = suite_motion("Sink")
    cfg = [(0.01, 0.02), (0.03, 0.02), (0.01, 0.02), (0.01, 0.02), (-0.02, 0.04), (0.01, 0.02)]
    r = solve_field(sink, PointPart(0.3), cfg, SolverSettings(cache=False))
    assert r.valid.all() and np.isfinite(r.velocity).all()
    same = r.velocity[[0, 2, 3, 5]]
    assert np.abs(same - same[0]).max() < 2e-6


def test_warm_starts_of_many_motions_at_shared_configurations_store_as_motion_by_motion():
    """WarmStarts.store_all (solve_fields with one set of configurations for every motion) leaves the
    entries, counts and group order that storing each motion's results in turn leaves."""
    from ppod_ros.physics.field import WarmStarts

    rng = np.random.default_rng(7)
    for trial in range(40):
        M, N, rows, dim = int(rng.integers(1, 6)), int(rng.integers(1, 5)), 3, 2 + trial % 2
        cfg = rng.normal(size=(N, dim))
        starts, rates = rng.normal(size=(M, N, dim)), rng.uniform(0, 1, (M, N))
        ok = rng.uniform(size=(M, N)) < 0.6
        sec = (rng.normal(size=(M, N, rows, dim)), rng.normal(size=(M, N, rows, dim)),
               rng.integers(0, rows + 1, (M, N)) * (rng.uniform(size=(M, N)) < 0.7))
        cap, seed = int(rng.integers(3, 12)), int(rng.integers(1 << 30))
        one, many = WarmStarts(max_entries=cap), WarmStarts(max_entries=cap)
        for w in (one, many):   # earlier calls: another group, entries with and without secants here
            r = np.random.default_rng(seed)
            w.store(("other",), r.normal(size=(4, dim)), r.normal(size=(4, dim)), np.ones(4), np.ones(4, bool))
            prev = np.concatenate([cfg[: N // 2 + 1], r.normal(size=(1, dim))])
            w.store(("p",), prev, r.normal(size=(len(prev), dim)), np.ones(len(prev)), np.ones(len(prev), bool),
                    (r.normal(size=(len(prev), rows, dim)), r.normal(size=(len(prev), rows, dim)),
                     r.integers(0, 2, len(prev)) * rows))
        for m in range(M):
            one.store(("p",), cfg, starts[m], rates[m], ok[m], (sec[0][m], sec[1][m], sec[2][m]))
        many.store_all(("p",), cfg, starts, rates, ok, sec)
        assert len(one) == len(many) and list(one._groups) == list(many._groups)
        for prefix, group in one._groups.items():
            other = many._groups[prefix]
            assert list(group) == list(other)
            for key, entry in group.items():
                got = other[key]
                assert len(entry) == len(got) and entry[1] == got[1]
                assert all(a.tobytes() == b.tobytes() and a.shape == b.shape
                           for a, b in zip(entry[:1] + entry[2:], got[:1] + got[2:]))

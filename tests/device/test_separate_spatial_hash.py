"""Part separation with a cell list: exactly the all-pairs sweep's result (the same pairs in the
same order), no overlap left, and only parts near each other compared."""

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_sim.scene import separate
from ppod_sim.separation import pack_circles


def _overlaps(xy, r, active):
    d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    both = active[:, None] & active[None, :]
    return (d < 2 * r - 1e-12) & both


def _random_scene(rng, n):
    """Crowded parts of 1-3 circles (a pushed part often lands in another cell), random masses."""
    r = rng.uniform(0.0005, 0.004)
    span = rng.uniform(0.005, 0.08)
    circles = []
    for _ in range(n):
        k = int(rng.integers(1, 4))
        c = np.zeros((k, 3))
        c[:, 0] = np.linspace(-r * (k - 1), r * (k - 1), k)
        c[:, 2] = r * rng.uniform(0.5, 1.5)
        circles.append(c)
    return (rng.uniform(-span, span, (n, 2)), rng.normal(0.0, 0.01, (n, 2)), rng.uniform(-3, 3, n), circles,
            rng.uniform(0.5, 3.0, n), rng.random(n) > 0.1)


def test_separation_leaves_no_overlap_among_many_disks_and_ignores_inactive_ones():
    rng = np.random.default_rng(4)
    n, r = 150, 0.002
    xy = rng.uniform(-0.05, 0.05, (n, 2))
    active = rng.random(n) > 0.1
    before = xy.copy()
    circles = [np.array([[0.0, 0.0, r]])] * n
    moved = separate(xy, np.zeros((n, 2)), np.zeros(n), circles, np.ones(n), active, iterations=50)
    assert not _overlaps(xy, r, active).any()
    assert np.array_equal(xy[~active], before[~active])
    assert set(moved.tolist()) <= set(np.flatnonzero(active).tolist())


def test_far_apart_parts_are_not_moved_and_touching_pairs_are_pushed_apart_along_their_centres():
    r = 0.002
    xy = np.array([[0.0, 0.0], [0.003, 0.0], [0.08, 0.08], [-1e6, 1e6]])
    circles = [np.array([[0.0, 0.0, r]])] * 4
    moved = separate(xy, np.zeros((4, 2)), np.zeros(4), circles, np.ones(4), np.ones(4, bool))
    assert sorted(moved.tolist()) == [0, 1]
    assert np.isclose(xy[1, 0] - xy[0, 0], 2 * r) and np.allclose(xy[:2, 1], 0.0)
    assert np.array_equal(xy[2:], [[0.08, 0.08], [-1e6, 1e6]])


@pytest.mark.parametrize("seed", range(6))
def test_the_cell_list_gives_bit_for_bit_the_all_pairs_result_on_crowded_scenes(seed):
    rng = np.random.default_rng(seed)
    pushed = 0
    for _ in range(20):
        xy, v, theta, circles, masses, active = _random_scene(rng, int(rng.integers(2, 250)))
        gap, iterations = rng.uniform(0.0, 0.001), int(rng.integers(1, 8))
        cells_xy, cells_v, ref_xy, ref_v = xy.copy(), v.copy(), xy.copy(), v.copy()
        moved = separate(cells_xy, cells_v, theta, pack_circles(circles), masses, active, gap, iterations)
        ref_moved = separate(ref_xy, ref_v, theta, circles, masses, active, gap, iterations, method="all_pairs")
        assert np.array_equal(moved, ref_moved)
        assert np.array_equal(cells_xy, ref_xy) and np.array_equal(cells_v, ref_v)
        pushed += ref_moved.size > 0
    assert pushed >= 15  # the scenes are crowded: most have overlaps to resolve


def test_parts_far_off_the_plate_or_at_no_finite_position_match_the_all_pairs_result():
    r = 0.002
    xy = np.array([[0.0, 0.0], [0.003, 0.0], [3e9, -3e9], [3e9 + 0.001, -3e9], [np.nan, 0.0], [0.001, 0.001]])
    circles = [np.array([[0.0, 0.0, r]])] * len(xy)
    results = []
    for method in ("cells", "all_pairs"):
        p, v = xy.copy(), np.zeros_like(xy)
        results.append((separate(p, v, np.zeros(len(p)), circles, np.ones(len(p)), np.ones(len(p), bool),
                                 method=method), p, v))
    (m1, p1, v1), (m2, p2, v2) = results
    assert np.array_equal(m1, m2) and np.array_equal(p1, p2, equal_nan=True) and np.array_equal(v1, v2)
    assert {2, 3} <= set(m1.tolist()) and 4 not in m1


def test_an_unknown_method_or_mismatched_shapes_are_one_line_config_errors():
    circles = [np.array([[0.0, 0.0, 0.002]])] * 2
    with pytest.raises(ConfigError, match="method"):
        separate(np.zeros((2, 2)), np.zeros((2, 2)), np.zeros(2), circles, np.ones(2), np.ones(2, bool),
                 method="octree")
    with pytest.raises(ConfigError, match=r"xy, v: expected shape \(2, 2\)"):
        separate(np.zeros((3, 2)), np.zeros((3, 2)), np.zeros(3), circles, np.ones(3), np.ones(3, bool))


def test_the_separation_benchmark_times_both_methods_on_the_same_cycles_and_they_agree():
    from ppod_bench.solver_separation import measure

    rows = measure(n=300, cycles=5)
    assert [r[0] for r in rows] == ["cells", "all_pairs"]
    assert all(int(r[3]) > 0 for r in rows)  # disks were pushed apart every cycle on average

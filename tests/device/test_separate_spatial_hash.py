"""Part separation with a spatial hash: the same outcome as checking every pair (no overlap left),
and only parts near each other are compared."""

import numpy as np

from ppod_sim.scene import separate


def _overlaps(xy, r, active):
    d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    both = active[:, None] & active[None, :]
    return (d < 2 * r - 1e-12) & both


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

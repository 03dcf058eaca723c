"""Keeping parts out of each other: after each plate cycle, overlapping outlines are pushed apart.

Model (stated in :mod:`ppod_sim.scene`): each outline is covered by a few body-frame circles; a
pair of parts overlaps when any of their circles do; the deepest circle overlap is pushed apart
along its normal, shared in inverse proportion to the masses, and the approaching normal velocity
is removed with the same shares. Pairs are visited in index order (``a`` ascending, then ``b > a``
ascending), each with the positions left by the pushes before it, for up to ``iterations`` sweeps
or until a sweep finds no overlap.

Two methods, chosen by name (:data:`SEPARATION_METHODS`), give bit-for-bit the same result:

- ``cells`` (the default): a cell list. Cells are as wide as the largest possible contact distance
  (2 x the largest bounding radius + the gap), so a part can only touch the parts of its own and
  the 8 neighbouring cells. Cells live in an open-addressing hash table (no Python dict; parts far
  off the plate cost nothing) with a doubly linked list of parts per cell, and a part that is
  pushed into another cell is moved to it at once, so the candidate set is always exact for the
  current positions. For part ``a``, the candidates ``b > a`` of its 9 cells are visited in index
  order, and gathered again whenever a push moves ``a`` to another cell: exactly the pairs, in
  exactly the order, that the all-pairs sweep finds overlapping. O(N) per sweep.
- ``all_pairs``: the reference, every pair in index order. O(N^2): 1000 parts take tens of ms.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from ppod_ros.errors import ConfigError

#: Cell width over the largest contact distance: a hair wider, so that rounding in x / cell never
#: puts two touching parts two cells apart (relative error of the division about 1e-15 here).
CELL_MARGIN = 1.0 + 1e-6
#: Cell index limit along each axis (cells beyond are merged: extra candidates, never lost ones).
CELL_INDEX_LIMIT = 2**30
#: Hash-table slots per active part (the table is rebuilt when half of it is in use).
SLOTS_PER_PART = 4


@dataclass(frozen=True, eq=False)
class CircleCovers:
    """The circle covers of N parts packed once for :func:`separate` (the simulator packs them at
    start-up instead of every cycle).

    Attributes
    ----------
    flat : (K, 3) body-frame circles (x, y, r) (m) of all parts, part after part.
    offsets : (N + 1,) part i's circles are ``flat[offsets[i]:offsets[i + 1]]``.
    """

    flat: np.ndarray
    offsets: np.ndarray

    def __len__(self) -> int:
        return len(self.offsets) - 1


def pack_circles(circles: Sequence[np.ndarray]) -> CircleCovers:
    """Pack N arrays (K_i, 3) of body-frame circles (x, y, r) (m) into one :class:`CircleCovers`."""
    arrays = [np.asarray(cc, dtype=float).reshape(-1, 3) for cc in circles]
    if not arrays:
        return CircleCovers(np.zeros((0, 3)), np.zeros(1, np.int64))
    counts = np.array([len(a) for a in arrays], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return CircleCovers(np.ascontiguousarray(np.concatenate(arrays)), offsets)


def separate(xy: np.ndarray, v: np.ndarray, theta: np.ndarray, circles: Sequence[np.ndarray] | CircleCovers,
             masses: np.ndarray, active: np.ndarray, gap_m: float = 0.0, iterations: int = 4,
             method: str = "cells") -> np.ndarray:
    """Push overlapping parts apart in place; returns the indices that were moved.

    Parameters
    ----------
    xy : (N, 2) positions (m), modified in place.
    v : (N, 2) velocities (m/s), modified in place: the approaching normal component is removed.
    theta : (N,) orientations (rad), to place each part's circles.
    circles : N arrays (K_i, 3) of body-frame circles (x, y, r) covering each outline, or the same
        packed once with :func:`pack_circles`.
    masses : (N,) masses (kg): the push is shared in inverse proportion to them.
    active : (N,) bool, parts still on the plate (others are ignored).
    gap_m : extra clearance kept between outlines (m).
    iterations : sweeps over all pairs at most.
    method : ``cells`` or ``all_pairs`` (:data:`SEPARATION_METHODS`; the same result).
    """
    try:
        kernel = SEPARATION_METHODS[method]
    except KeyError:
        raise ConfigError(f"method: unknown separation method {method!r} (one of {sorted(SEPARATION_METHODS)})") \
            from None
    covers = circles if isinstance(circles, CircleCovers) else pack_circles(circles)
    n = len(covers)
    if xy.shape != (n, 2) or v.shape != (n, 2):
        raise ConfigError(f"xy, v: expected shape ({n}, 2) (m, m/s) for {n} circle covers, "
                          f"got {xy.shape} and {v.shape}")
    act = np.asarray(active, dtype=bool)
    if int(act.sum()) < 2:
        return np.array([], dtype=int)
    inv_mass = 1.0 / np.maximum(np.asarray(masses, dtype=float), 1e-9)
    moved = np.zeros(n, dtype=np.bool_)
    kernel(xy, v, np.asarray(theta, dtype=float), covers.flat, covers.offsets, inv_mass, act, float(gap_m),
           int(iterations), moved)
    return np.flatnonzero(moved)


@njit(cache=True)
def _reach(flat, offsets):
    """(N,) bounding radius of each part's circles about its pose point (m)."""
    n = offsets.shape[0] - 1
    reach = np.zeros(n)
    for i in range(n):
        for k in range(offsets[i], offsets[i + 1]):
            reach[i] = max(reach[i], math.hypot(flat[k, 0], flat[k, 1]) + flat[k, 2])
    return reach


@njit(cache=True)
def _place_circles(xy, theta, flat, offsets, world):
    for i in range(xy.shape[0]):
        c, s = math.cos(theta[i]), math.sin(theta[i])
        for k in range(offsets[i], offsets[i + 1]):
            world[k, 0] = xy[i, 0] + c * flat[k, 0] - s * flat[k, 1]
            world[k, 1] = xy[i, 1] + s * flat[k, 0] + c * flat[k, 1]


@njit(cache=True)
def _separate_all_pairs(xy, v, theta, flat, offsets, inv_mass, active, gap, iterations, moved):
    """The reference sweep: every pair of active parts in index order."""
    n = xy.shape[0]
    reach = _reach(flat, offsets)
    world = np.zeros((flat.shape[0], 2))
    for _ in range(iterations):
        _place_circles(xy, theta, flat, offsets, world)
        any_overlap = False
        for a in range(n):
            if not active[a]:
                continue
            for b in range(a + 1, n):
                if active[b] and _push_pair(a, b, xy, v, flat, offsets, inv_mass, reach, world, gap):
                    any_overlap = True
                    moved[a] = True
                    moved[b] = True
        if not any_overlap:
            break


@njit(cache=True)
def _separate_cells(xy, v, theta, flat, offsets, inv_mass, active, gap, iterations, moved):
    """The cell-list sweep (module docstring): the all-pairs sweep's pairs, in its order."""
    n = xy.shape[0]
    reach = _reach(flat, offsets)
    rmax = 0.0
    for i in range(n):
        if active[i]:
            rmax = max(rmax, reach[i])
    cell = max((2.0 * rmax + gap) * CELL_MARGIN, 1e-9)
    world = np.zeros((flat.shape[0], 2))
    size = 16
    while size < SLOTS_PER_PART * n:
        size *= 2
    # The cell list: hash slots (cell key, first part, or _EMPTY / -1), per part its slot, the
    # next and previous part of its cell and its cell indices; grid[0] counts the slots in use.
    slot_key = np.empty(size, np.int64)
    slot_head = np.empty(size, np.int64)
    slot_of = np.empty(n, np.int64)
    nxt = np.empty(n, np.int64)
    prv = np.empty(n, np.int64)
    cx = np.zeros(n, np.int64)
    cy = np.zeros(n, np.int64)
    used = np.zeros(1, np.int64)
    candidates = np.empty(n, np.int64)
    for _ in range(iterations):
        _place_circles(xy, theta, flat, offsets, world)
        _rebuild(xy, active, cell, slot_key, slot_head, slot_of, nxt, prv, cx, cy, used)
        any_overlap = False
        for a in range(n):
            if slot_of[a] < 0:  # inactive, or not at a finite position (never overlaps)
                continue
            last = a
            again = True
            while again:
                again = False
                m = _gather(a, last, slot_key, slot_head, nxt, cx, cy, candidates)
                for q in range(m):
                    b = candidates[q]
                    if not _push_pair(a, b, xy, v, flat, offsets, inv_mass, reach, world, gap):
                        continue
                    any_overlap = True
                    moved[a] = True
                    moved[b] = True
                    ax, ay = cx[a], cy[a]
                    _relocate(b, xy, active, cell, slot_key, slot_head, slot_of, nxt, prv, cx, cy, used)
                    _relocate(a, xy, active, cell, slot_key, slot_head, slot_of, nxt, prv, cx, cy, used)
                    if cx[a] != ax or cy[a] != ay:
                        last = b  # a's neighbourhood changed: gather the parts after b again
                        again = True
                        break
        if not any_overlap:
            break


#: Key of an empty hash slot (cell keys are >= 0).
_EMPTY = -1


@njit(cache=True, inline="always")
def _cell_index(x, cell):
    return int(min(max(math.floor(x / cell), -CELL_INDEX_LIMIT), CELL_INDEX_LIMIT))


@njit(cache=True, inline="always")
def _cell_key(ix, iy):
    return (ix + CELL_INDEX_LIMIT) * (2 * CELL_INDEX_LIMIT + 1) + (iy + CELL_INDEX_LIMIT)


@njit(cache=True)
def _find_slot(key, ix, iy, slot_key):
    """The slot holding cell key, or the empty slot where it would go (linear probing)."""
    mask = slot_key.shape[0] - 1
    h = ((ix * 73856093) ^ (iy * 19349663)) & mask
    while slot_key[h] != key and slot_key[h] != _EMPTY:
        h = (h + 1) & mask
    return h


@njit(cache=True)
def _link(i, key, slot_key, slot_head, slot_of, nxt, prv, cx, cy, used):
    h = _find_slot(key, cx[i], cy[i], slot_key)
    if slot_key[h] == _EMPTY:
        slot_key[h] = key
        slot_head[h] = -1
        used[0] += 1
    head = slot_head[h]
    nxt[i] = head
    prv[i] = -1
    if head >= 0:
        prv[head] = i
    slot_head[h] = i
    slot_of[i] = h


@njit(cache=True)
def _rebuild(xy, active, cell, slot_key, slot_head, slot_of, nxt, prv, cx, cy, used):
    """Every active part at a finite position into the cell of its current position."""
    slot_key[:] = _EMPTY
    slot_of[:] = -1
    used[0] = 0
    for i in range(xy.shape[0]):
        if active[i] and math.isfinite(xy[i, 0]) and math.isfinite(xy[i, 1]):
            cx[i] = _cell_index(xy[i, 0], cell)
            cy[i] = _cell_index(xy[i, 1], cell)
            _link(i, _cell_key(cx[i], cy[i]), slot_key, slot_head, slot_of, nxt, prv, cx, cy, used)


@njit(cache=True)
def _relocate(i, xy, active, cell, slot_key, slot_head, slot_of, nxt, prv, cx, cy, used):
    """Move part i to the cell of its current position."""
    ix, iy = _cell_index(xy[i, 0], cell), _cell_index(xy[i, 1], cell)
    if ix == cx[i] and iy == cy[i]:
        return
    if 2 * (used[0] + 1) > slot_key.shape[0]:  # half full of cells met on the way: start afresh
        _rebuild(xy, active, cell, slot_key, slot_head, slot_of, nxt, prv, cx, cy, used)
        return
    if prv[i] >= 0:
        nxt[prv[i]] = nxt[i]
    else:
        slot_head[slot_of[i]] = nxt[i]
    if nxt[i] >= 0:
        prv[nxt[i]] = prv[i]
    cx[i], cy[i] = ix, iy
    _link(i, _cell_key(ix, iy), slot_key, slot_head, slot_of, nxt, prv, cx, cy, used)


@njit(cache=True)
def _gather(a, last, slot_key, slot_head, nxt, cx, cy, out):
    """The parts b > last in the 9 cells around a's, in ascending order, into out; their count."""
    m = 0
    for ddx in range(-1, 2):
        for ddy in range(-1, 2):
            ix = min(max(cx[a] + ddx, -CELL_INDEX_LIMIT), CELL_INDEX_LIMIT)
            iy = min(max(cy[a] + ddy, -CELL_INDEX_LIMIT), CELL_INDEX_LIMIT)
            if (ddx != 0 and ix == cx[a]) or (ddy != 0 and iy == cy[a]):
                continue  # a clamped edge cell, already visited
            h = _find_slot(_cell_key(ix, iy), ix, iy, slot_key)
            if slot_key[h] == _EMPTY:
                continue
            b = slot_head[h]
            while b >= 0:
                if b > last:
                    # insertion into the sorted run (a handful of parts per neighbourhood)
                    j = m
                    while j > 0 and out[j - 1] > b:
                        out[j] = out[j - 1]
                        j -= 1
                    out[j] = b
                    m += 1
                b = nxt[b]
    return m


@njit(cache=True)
def _push_pair(a, b, xy, v, flat, offsets, inv_mass, reach, world, gap):
    """Push parts a and b apart along their deepest circle overlap; True if they overlapped."""
    if math.hypot(xy[b, 0] - xy[a, 0], xy[b, 1] - xy[a, 1]) >= reach[a] + reach[b] + gap:
        return False
    best, bx, by, bd = 0.0, 0.0, 0.0, 0.0
    for ka in range(offsets[a], offsets[a + 1]):
        for kb in range(offsets[b], offsets[b + 1]):
            dx = world[kb, 0] - world[ka, 0]
            dy = world[kb, 1] - world[ka, 1]
            dist = math.hypot(dx, dy)
            depth = flat[ka, 2] + flat[kb, 2] + gap - dist
            if depth > best:
                best, bx, by, bd = depth, dx, dy, dist
    if best <= 0.0:
        return False
    if bd > 1e-12:
        nx, ny = bx / bd, by / bd
    else:
        nx, ny = 1.0, 0.0
    wa = inv_mass[a] / (inv_mass[a] + inv_mass[b])
    pa, pb = wa * best, (1.0 - wa) * best
    xy[a, 0] -= pa * nx
    xy[a, 1] -= pa * ny
    xy[b, 0] += pb * nx
    xy[b, 1] += pb * ny
    for k in range(offsets[a], offsets[a + 1]):
        world[k, 0] -= pa * nx
        world[k, 1] -= pa * ny
    for k in range(offsets[b], offsets[b + 1]):
        world[k, 0] += pb * nx
        world[k, 1] += pb * ny
    rel = (v[b, 0] - v[a, 0]) * nx + (v[b, 1] - v[a, 1]) * ny
    if rel < 0.0:  # approaching: remove the normal component, shared like the push
        v[a, 0] += wa * rel * nx
        v[a, 1] += wa * rel * ny
        v[b, 0] -= (1.0 - wa) * rel * nx
        v[b, 1] -= (1.0 - wa) * rel * ny
    return True


#: Separation methods by name (the same result; ``all_pairs`` is the reference the tests and
#: ``ppod bench solver --separation`` compare with).
SEPARATION_METHODS = {"cells": _separate_cells, "all_pairs": _separate_all_pairs}

__all__ = ["CELL_MARGIN", "SEPARATION_METHODS", "CircleCovers", "pack_circles", "separate"]

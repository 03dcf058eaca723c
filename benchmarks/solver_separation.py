"""Time per plate cycle of the simulator's part separation (``ppod bench solver --separation``).

N disks of radius 2 mm (the default footprint) on random sites of a hexagonal lattice (4.2 mm
pitch) inside r = 0.09 m, no overlap at the start. Each cycle every disk moves by a random step
(normal, 0.2 mm rms: a part at about 6 mm/s over a 30 Hz cycle), which makes neighbours overlap,
and :func:`ppod_sim.separation.separate` pushes them apart, as the simulated device does after each
cycle. The same cycles are timed with the cell list and with the all-pairs reference (fewer cycles:
it is slow), and the two must give bit-for-bit the same positions.
"""

from __future__ import annotations

import time

import numpy as np

#: Disk radius (m): the default footprint of a point part.
DISK_RADIUS_M = 0.002
#: Radius of the region the disks start in (m).
REGION_RADIUS_M = 0.09
#: Lattice pitch (m): a little over a diameter, so the start has no overlap.
PITCH_M = 0.0042
#: Random step per cycle (m rms per axis).
STEP_M = 0.0002
#: Cycles timed with the all-pairs reference (each takes tens of ms at 1000 parts).
REFERENCE_CYCLES = 20


def _start(n: int, rng: np.random.Generator) -> np.ndarray:
    k = int(REGION_RADIUS_M / PITCH_M) + 2
    i, j = np.meshgrid(np.arange(-k, k + 1), np.arange(-k, k + 1))
    sites = np.column_stack([(i + 0.5 * (j % 2)).ravel() * PITCH_M, j.ravel() * PITCH_M * np.sqrt(3) / 2])
    sites = sites[np.hypot(*sites.T) <= REGION_RADIUS_M - DISK_RADIUS_M]
    if n > len(sites):
        raise ValueError(f"--separation-parts: at most {len(sites)} disks fit within r = {REGION_RADIUS_M} m")
    return sites[rng.choice(len(sites), n, replace=False)]


def _cycles(method: str, xy0: np.ndarray, cycles: int, seed: int):
    from ppod_sim.separation import pack_circles, separate

    n = len(xy0)
    covers = pack_circles([np.array([[0.0, 0.0, DISK_RADIUS_M]])] * n)
    masses, active, theta = np.ones(n), np.ones(n, bool), np.zeros(n)
    rng = np.random.default_rng(seed)
    xy, v = xy0.copy(), np.zeros((n, 2))
    separate(xy.copy(), v.copy(), theta, covers, masses, active, method=method)  # compiled / loaded
    times, pushed = [], 0
    for _ in range(cycles):
        xy += rng.normal(0.0, STEP_M, xy.shape)
        t0 = time.perf_counter()
        moved = separate(xy, v, theta, covers, masses, active, method=method)
        times.append(time.perf_counter() - t0)
        pushed += moved.size
    return np.asarray(times) * 1e3, pushed / cycles, xy


def measure(n: int = 1000, cycles: int = 200, seed: int = 3) -> list[list[str]]:
    """Rows [method, parts, cycles, parts moved per cycle, p50 ms, p90 ms, max ms]."""
    xy0 = _start(n, np.random.default_rng(seed))
    rows, finals = [], {}
    for method, count in (("cells", cycles), ("all_pairs", min(cycles, REFERENCE_CYCLES))):
        ms, moved, finals[method] = _cycles(method, xy0, count, seed)
        p50, p90, mx = np.percentile(ms, 50), np.percentile(ms, 90), ms.max()
        rows.append([method, str(n), str(count), f"{moved:.0f}", f"{p50:.3f}", f"{p90:.3f}", f"{mx:.2f}"])
        print(f"{method:10s} {n} disks, {count} cycles, {moved:.0f} moved per cycle: p50 {p50:.3f} ms  "
              f"p90 {p90:.3f} ms  max {mx:.2f} ms", flush=True)
    reference_count = min(cycles, REFERENCE_CYCLES)
    if not np.array_equal(_cycles("cells", xy0, reference_count, seed)[2], finals["all_pairs"]):
        raise RuntimeError("the cell list and the all-pairs separation differ after the same cycles")
    print(f"cell list == all pairs after {reference_count} cycles: bit-for-bit", flush=True)
    return rows


__all__ = ["measure"]

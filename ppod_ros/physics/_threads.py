"""Serial or parallel, chosen per call by the work's expected size.

On a 2-core machine whose other core is busy (the ROS stack's normal state) a numba parallel call
waits for its second thread to be scheduled: about one scheduler time slice (~8 ms, p90 12 ms) per
call, whatever the work. Small calls therefore run a serial variant of the kernel on the calling
thread (same chunks, same results); only work expected to take longer than
``PARALLEL_MIN_SECONDS`` serially goes parallel, where the stall is small beside the gain.

The expected time is the number of work units times a per-unit cost learnt from this process's
previous calls (an exponential average per kind of work, seeded with ``SEED_COST_S``). It is learnt
from the work, not from the waiting: a serial call reports the calling thread's CPU time (wall time
counts the scheduler slices another process took from it), and a parallel call's wall time, a wake-
up stall included, only ever lowers the estimate (it bounds the serial cost from above). Learning
from stalled parallel calls' wall time raised the estimate until small calls went parallel, stalled
again and kept it there: on a busy machine, 10-part ``PartDynamics.advance`` cycles at 16 ms instead
of 0.2 ms after one parallel call in the process. Nothing here
changes numba's global state: the thread count of a parallel call is set with
``numba.set_num_threads`` (thread-local in numba) and restored after the call.
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

#: Expected serial time (s) above which a call runs in parallel.
PARALLEL_MIN_SECONDS = 0.03
#: Extra expected serial time (s) a call must reach to go parallel while the parallel kernel is not
#: loaded yet in this process: loading it and starting numba's threading layer costs about 0.1 s of
#: CPU once (measured for the point field kernel), more than a 21 x 21 grid's whole serial solve,
#: so a short-lived process (``ppod field``) with a small grid never pays it.
PARALLEL_LOAD_S = 0.15
#: Starting per-unit costs (s) before anything was measured: a point / rigid configuration of the
#: field solver, a point / rigid part per period of full dynamics.
SEED_COST_S = {"field0": 2e-4, "field1": 3e-3, "dyn0": 2e-5, "dyn1": 2e-4}
#: Weight of the newest measurement in the per-unit cost's exponential average.
COST_SMOOTHING = 0.3

_lock = threading.Lock()
_cost = dict(SEED_COST_S)


def plan(kind: str, units: float, threads: int | None, parallel_ready: bool = True) -> int:
    """Threads to use for ``units`` of work of ``kind`` (1: run the serial kernel).

    ``threads`` is the caller's setting (None: choose by size; 1: always serial; n > 1: parallel on
    up to n threads when the work is large enough to pay for the wake-up). ``parallel_ready``:
    whether the parallel kernel is already loaded (if not, ``PARALLEL_LOAD_S`` more is needed).
    """
    avail = available_threads()
    want = avail if threads is None else min(int(threads), avail)
    if want <= 1:
        return 1
    with _lock:
        expected = units * _cost[kind]
    need = PARALLEL_MIN_SECONDS + (0.0 if parallel_ready else PARALLEL_LOAD_S)
    return want if expected >= need else 1


def learn(kind: str, units: float, seconds: float, nthreads: int, cpu_seconds: float | None = None) -> None:
    """Update the per-unit cost of ``kind`` from a call that took ``seconds`` (wall) on ``nthreads``.

    ``cpu_seconds``: the calling thread's CPU time over a serial call (``time.thread_time``), used
    instead of the wall time when given. A parallel call's ``seconds * nthreads`` is only an upper
    bound on the serial cost (its wake-up stall included): it may lower the estimate, never raise it.
    """
    serial = nthreads <= 1
    spent = cpu_seconds if (serial and cpu_seconds is not None and cpu_seconds > 0) else seconds
    if units <= 0 or spent <= 0:
        return
    per_unit = spent * max(1, nthreads) / units
    with _lock:
        blended = (1.0 - COST_SMOOTHING) * _cost[kind] + COST_SMOOTHING * per_unit
        _cost[kind] = blended if serial else min(_cost[kind], blended)


def available_threads() -> int:
    """numba's ``NUMBA_NUM_THREADS`` without importing numba when it is not imported yet.

    Numba's default: the ``NUMBA_NUM_THREADS`` environment variable, else the CPUs this process may
    run on (a serial call then needs no numba at all, see ``_aot``)."""
    numba = sys.modules.get("numba")
    if numba is not None and hasattr(numba, "config"):
        return int(numba.config.NUMBA_NUM_THREADS)
    raw = os.environ.get("NUMBA_NUM_THREADS", "").strip()
    if raw:
        try:
            return max(1, int(raw))
        except ValueError:
            pass  # numba itself reports the bad value when it is imported
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


@contextmanager
def thread_count(nthreads: int) -> Iterator[None]:
    """numba's thread count for parallel kernels called inside (this thread only), restored after."""
    if nthreads <= 1:
        yield
        return
    import numba

    old = numba.get_num_threads()
    numba.set_num_threads(nthreads)
    try:
        yield
    finally:
        numba.set_num_threads(old)


__all__ = ["PARALLEL_LOAD_S", "PARALLEL_MIN_SECONDS", "SEED_COST_S", "available_threads", "learn", "plan",
           "thread_count"]

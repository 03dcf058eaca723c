"""Per-call latency of small solver calls while the other core is busy (``ppod bench solver --stalls``).

A bounded busy loop runs in a child process (at most ``BUSY_MAX_S`` seconds; it stops by itself and
is also ended by pid when the measurement is done), so that the second core is taken, as it is by
the rest of the ROS stack. Then, for each case, many calls are timed one by one and p50 / p90 / max
reported: ``PartDynamics.advance`` over one cycle for 1, 10 and 100 point parts, ``solve_field``
on 37 scattered configurations from cold and again repeated with warm starts from the previous
call (``warm=``, cache off), and ``solve_fields`` on the same 37 under a motion that
changes by about 1 % from call to call (a planner's candidates; warm starts from the previous
call), each with the automatic choice (serial for small work) and with the parallel
kernel forced (what every call paid before).
"""

from __future__ import annotations

import subprocess
import sys
import time
from contextlib import contextmanager

import numpy as np

#: Hard bound on the busy loop's life (s): it ends by itself even if this process dies.
BUSY_MAX_S = 120.0


@contextmanager
def busy_core(enabled: bool = True, count: int = 1):
    """``count`` child processes, each spinning on a core for at most BUSY_MAX_S seconds; yields the
    first (None when not enabled or none)."""
    if not enabled or count < 1:
        yield None
        return
    code = f"import time\nend = time.time() + {BUSY_MAX_S}\nwhile time.time() < end:\n    pass\n"
    procs = [subprocess.Popen([sys.executable, "-c", code]) for _ in range(count)]
    time.sleep(0.2)
    try:
        yield procs[0]
    finally:
        for proc in procs:
            proc.terminate()
        for proc in procs:
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()


@contextmanager
def forced_parallel():
    """The parallel kernels for every call, whatever its size (the behaviour before this choice)."""
    from ppod_ros.physics import _threads

    old = _threads.PARALLEL_MIN_SECONDS
    _threads.PARALLEL_MIN_SECONDS = 0.0
    try:
        yield
    finally:
        _threads.PARALLEL_MIN_SECONDS = old


def _timed(fn):
    """(wall s, CPU s of the calling thread, result of fn()): the thread's CPU time does not count
    the time the machine's other load held the thread off its core (serial calls only)."""
    c0 = time.thread_time()
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, time.thread_time() - c0, out


def _periods(result):
    """Mean periods per integrated configuration of a field result (NaN for other results)."""
    p = getattr(result, "periods", None)
    if p is None:
        return float("nan")
    p = np.asarray(p)
    return float(p[p > 0].mean()) if (p > 0).any() else 0.0


def _percentiles(samples):
    a = np.asarray(samples) * 1e3
    return float(np.percentile(a, 50)), float(np.percentile(a, 90)), float(a.max())


def measure(calls: int = 200, busy: bool = True) -> list[list[str]]:
    """Rows [case, mode, calls, p50 ms, p90 ms, max ms, thread CPU p50 ms, periods per configuration]."""
    from ppod_bench.solver import CONFIG
    from ppod_ros.motion import PlateMotion
    from ppod_ros.parts import PointPart
    from ppod_ros.physics import PartDynamics, SolverSettings, solve_field
    from ppod_ros.physics._params import ensure_compiled

    ensure_compiled()
    sink = PlateMotion.from_yaml(CONFIG / "motions" / "Sink.yaml")
    part = PointPart(0.3)
    rng = np.random.default_rng(1)
    rows = []
    cfg37 = rng.uniform(-0.06, 0.06, (37, 2))
    nocache = SolverSettings(cache=False)

    def dyn_case(nparts):
        xy = np.column_stack([np.linspace(-0.05, 0.05, nparts), np.linspace(-0.03, 0.03, nparts)])
        sim = PartDynamics([part] * nparts, xy)
        T = sink.period_s

        def one():
            t = sim.time_s
            return _timed(lambda: sim.advance(sink, t, T))
        return one

    def field_case():
        def one():
            return _timed(lambda: solve_field(sink, part, cfg37, nocache))
        return one

    def field_warm_case():
        from ppod_ros.physics import WarmStarts

        warm = WarmStarts()

        def one():
            # Replanning: the same motion at the same configurations, call after call, with warm starts
            # (the result cache is off: every call integrates; one period each proves convergence).
            return _timed(lambda: solve_field(sink, part, cfg37, nocache, warm=warm))
        return one

    def fields_case():
        from ppod_ros.physics import WarmStarts, solve_fields

        warm = WarmStarts()
        perturb = np.random.default_rng(2)

        def one():
            # A planner's candidate: the motion changes by ~1 % from call to call, the
            # configurations stay (warm starts from the previous call).
            amp = sink.amplitude * (1.0 + 0.01 * perturb.standard_normal(sink.amplitude.shape))
            cand = PlateMotion(sink.frequency_hz, sink.k, amp, sink.phase)
            return _timed(lambda: solve_fields([cand], part, cfg37, nocache, warm=warm))
        return one

    cases = [(f"PartDynamics.advance, {n} point parts, one cycle", lambda n=n: dyn_case(n)) for n in (1, 10, 100)]
    cases.append(("solve_field, 37 configurations (Sink, cache off)", field_case))
    cases.append(("solve_field, 37 configurations, repeated, warm", field_warm_case))
    cases.append(("solve_fields, 37 configurations, motion +-1 % per call, warm", fields_case))
    with busy_core(busy):
        for label, make in cases:
            for mode in ("auto (serial when small)", "parallel forced"):
                ctx = forced_parallel() if mode.startswith("parallel") else _null()
                with ctx:
                    one = make()
                    for _ in range(5):
                        one()
                    samples = [one() for _ in range(calls)]
                p50, p90, mx = _percentiles([w for w, _, _ in samples])
                cpu50 = float(np.percentile([c for _, c, _ in samples], 50)) * 1e3
                periods = float(np.mean([_periods(r) for _, _, r in samples]))
                per = "-" if not np.isfinite(periods) else f"{periods:.2f}"
                rows.append([label, mode, str(calls), f"{p50:.3f}", f"{p90:.3f}", f"{mx:.2f}", f"{cpu50:.3f}", per])
                print(f"{label:52s} {mode:26s} p50 {p50:8.3f} ms  p90 {p90:8.3f} ms  max {mx:7.2f} ms  "
                      f"thread CPU p50 {cpu50:7.3f} ms  periods {per}", flush=True)
    return rows


@contextmanager
def _null():
    yield


__all__ = ["BUSY_MAX_S", "busy_core", "forced_parallel", "measure"]

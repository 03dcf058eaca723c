"""The latency benchmark's section runs and reports periods per configuration (no timing assertions)."""

from ppod_bench.solver_stalls import measure


def test_the_stall_section_reports_one_period_for_a_warm_repeat_and_five_from_cold():
    rows = measure(calls=2, busy=False)
    assert len(rows) == 12 and all(len(r) == 8 for r in rows)
    by_case = {(r[0], r[1]): r for r in rows}
    warm = by_case[("solve_field, 37 configurations, repeated, warm", "auto (serial when small)")]
    cold = by_case[("solve_field, 37 configurations (Sink, cache off)", "auto (serial when small)")]
    assert float(warm[7]) == 1.0
    assert float(cold[7]) > 3.0
    assert all(r[7] == "-" for r in rows if r[0].startswith("PartDynamics"))
    assert all(float(r[6]) >= 0.0 for r in rows)

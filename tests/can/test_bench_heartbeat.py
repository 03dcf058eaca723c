"""`ppod bench can --sections heartbeat` runs both arms and says what each process got (no timing
assertions: the figures are the benchmark's, in the README)."""

import argparse

from ppod_bench.can import bench_heartbeat


def test_the_heartbeat_section_measures_both_schedulings_and_reports_whether_real_time_was_granted():
    rows = bench_heartbeat(argparse.Namespace(quick=True, seconds=2.0, busy=1))
    assert [r["priority"] for r in rows] == [0, 10]
    for r in rows:
        assert r["n"] >= 10                      # 2 s of 50 ms heartbeats, each arm
        assert 0 < r["median_ms"] <= r["p99_ms"] <= r["max_ms"]
        assert r["busy_processes"] == 1
    normal, realtime = rows
    assert normal["granted"] and normal["scheduling"] == "normal scheduling"
    # Granted where the process may take SCHED_FIFO (CAP_SYS_NICE or an rtprio limit), and said otherwise.
    assert normal["node_said"] == ""
    if realtime["granted"]:
        assert realtime["scheduling"] == "SCHED_FIFO 10 (ppod up's waveform_generator)"
        assert "real-time priority 10 (SCHED_FIFO)" in realtime["node_said"]
    else:
        assert realtime["scheduling"].endswith("not granted, normal")
        assert "not granted" in realtime["node_said"]


def test_the_stalls_section_holds_the_gil_and_measures_the_heartbeats_at_the_device_for_both_arms():
    from ppod_bench.can import bench_stalls

    rows = bench_stalls(argparse.Namespace(quick=True, stalls=20, stall_ms=330.0))
    assert [r["heartbeats_from"] for r in rows] == ["the node's thread", "keeper process (lease 0.5 s)"]
    thread, keeper = rows
    assert thread["stalls"] == keeper["stalls"] == 2            # --quick
    assert thread["over_150_ms"] == 2 and thread["max_ms"] >= 330.0   # no heartbeat while the GIL is held
    assert keeper["max_ms"] < 330.0                              # the keeper beat through every stall
    assert keeper["keeper"].startswith("sent ") and thread["keeper"] == ""

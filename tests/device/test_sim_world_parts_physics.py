"""The simulated world's parts physics: cheaper settings than the solver's defaults on the rigid
parts' stick-slip, the ground truth no less accurate than the tracker can tell (issue 16)."""

from pathlib import Path

import numpy as np

from ppod_ros.device import default_device_config
from ppod_ros.physics import PartDynamics, SolverSettings
from ppod_sim.ros_node import default_scene_path
from ppod_sim.scene import load_scene
from ppod_sim.truth import load_cycles, save_cycles
from ppod_sim.world import SIM_SOLVER, SimWorld

#: 1.1 s of a recorded demo run (cycles 267-299 of 30 Hz, 8.9-10.0 s of device time): the planner's
#: pivot turns the bracket about a point off it, one contact pivoting under the regularised law;
#: with the bracket's state (pose, twist) at its start.
PIVOT = Path(__file__).resolve().parents[1] / "data" / "sim_pivot_cycles.npz"


def _bracket_at_the_pivot(settings, cycles):
    """The demo's bracket in its recorded state at the start of ``cycles``, on its own dynamics."""
    with np.load(PIVOT) as d:
        q0, v0 = d["bracket_configuration"], d["bracket_twist"]
    bracket = load_scene(default_scene_path()).parts[0].part
    return PartDynamics([bracket], [q0], [v0], time_s=cycles[0].start_time_s, settings=settings)


def _pivot(settings):
    cycles = load_cycles(PIVOT)
    dyn = _bracket_at_the_pivot(settings, cycles)
    poses = []
    for c in cycles:
        state = dyn.advance(c.motion(absolute_time=True), c.start_time_s, 1.0 / c.frequency_hz)
        assert state.status[0] == 0, state.reason
        poses.append(state.configurations[0].copy())
    return np.array(poses), dyn.steps


def test_the_solver_defaults_the_planner_uses_are_unchanged():
    base = SolverSettings()
    assert (base.friction_eps_mps, base.stick_capture, base.rigid_rtol, base.rtol) == (1e-6, 10.0, 1e-8, 1e-6)
    assert base.integrator == "dopri5"
    changed = {k for k, v in SIM_SOLVER.to_dict().items() if v != base.to_dict()[k]}
    assert changed == {"threads", "friction_eps_mps", "stick_capture"}


def test_the_world_integrates_its_parts_with_the_simulator_settings():
    config = default_device_config().with_can(interface="virtual", channel="test-sim-parts-settings")
    world = SimWorld(config, load_scene(default_scene_path()), None)
    try:
        assert world.dynamics.settings is SIM_SOLVER
    finally:
        world.close()


def test_a_pivoting_bracket_takes_far_fewer_steps_and_stays_on_the_tight_reference():
    # The reference: the solver's defaults (the world's settings before issue 16) 100x tighter.
    ref, ref_steps = _pivot(SolverSettings(threads=1, rtol=1e-9, rigid_rtol=1e-10, max_steps_per_period=10**7))
    old, old_steps = _pivot(SolverSettings(threads=1))
    new, new_steps = _pivot(SIM_SOLVER)
    assert ref.shape == (33, 3)
    assert np.ptp(ref[:, 2]) > np.radians(5.0)  # the bracket really turns over this stretch
    for poses in (old, new):
        err = poses - ref
        assert 1e3 * np.hypot(err[:, 0], err[:, 1]).max() < 0.005  # mm; tracker noise ~0.1 mm
        assert np.degrees(np.abs(err[:, 2])).max() < 0.01
    # Work in integration steps (deterministic, not wall time): 241 220 -> 91 347 when measured.
    assert new_steps < 0.5 * old_steps, (new_steps, old_steps)


def test_recorded_cycles_round_trip(tmp_path):
    cycles = load_cycles(PIVOT)[:3]
    save_cycles(tmp_path / "c.npz", cycles)
    back = load_cycles(tmp_path / "c.npz")
    assert [c.start_time_s for c in back] == [c.start_time_s for c in cycles]
    for a, b in zip(back, cycles, strict=True):
        np.testing.assert_array_equal(a.accel, b.accel)
        assert a.motion(absolute_time=True).period_s == b.motion(absolute_time=True).period_s


def test_the_benchmark_replays_a_recording_and_refuses_a_bad_file_in_one_line(tmp_path, capsys):
    import argparse

    from ppod_bench import sim_parts

    def run(*argv):
        parser = argparse.ArgumentParser()
        sim_parts.add_arguments(parser)
        return sim_parts.run(parser.parse_args(list(argv)))

    assert run("--cycles", str(PIVOT), "--cycles-limit", "3", "--repeats", "1", "--settings", "world", "default") == 0
    out = capsys.readouterr().out
    assert "3 cycles" in out and "friction_eps_mps=3e-06" in out
    bad = tmp_path / "bad.npz"
    bad.write_text("not a recording")
    for path in (bad, tmp_path / "missing.npz"):
        assert run("--cycles", str(path)) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "not a recording of plate cycles" in err


def test_the_parts_physics_kernels_release_the_gil_and_readers_wait_for_a_whole_step():
    # The simulated device's clock, camera and ROS threads share the process with the parts
    # physics: a kernel holding the GIL for a stick-slip stretch (up to a second of CPU per second of
    # device time before issue 16's settings) stalled them all.
    import threading

    from ppod_ros.physics import _dynamics_kernel as kernels
    from ppod_ros.physics._jit import materialise

    materialise()
    for kernel in (kernels.advance_group_serial, kernels.advance_group):
        assert getattr(kernel, "dispatcher", kernel).targetoptions.get("nogil") is True
    cycles = load_cycles(PIVOT)[:6]
    serial = _bracket_at_the_pivot(SIM_SOLVER, cycles)
    expected = {serial.state.time_s: serial.state.configurations.tobytes()}
    for c in cycles:
        st = serial.advance(c.motion(absolute_time=True), c.start_time_s, 1.0 / c.frequency_hz)
        expected[st.time_s] = st.configurations.tobytes()
    dyn = _bracket_at_the_pivot(SIM_SOLVER, cycles)
    reads, stop = [], threading.Event()

    def read():
        while not stop.is_set():
            st = dyn.state
            reads.append((st.time_s, st.configurations.tobytes()))

    reader = threading.Thread(target=read)
    reader.start()
    try:
        for c in cycles:
            dyn.advance(c.motion(absolute_time=True), c.start_time_s, 1.0 / c.frequency_hz)
    finally:
        stop.set()
        reader.join()
    # Every read saw the state at a cycle boundary, whole (pose and time together), as the serial run.
    assert reads and all(expected.get(t) == cfg for t, cfg in reads)

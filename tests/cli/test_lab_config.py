"""config/lab.example.yaml starts the real-hardware stack on SocketCAN can0, placeholders filled."""

from pathlib import Path

from ppod_nodes.launch.ros_launch import launch_entries
from ppod_nodes.launch.spec import load_launch_spec

LAB = Path(__file__).parents[2] / "config" / "lab.example.yaml"


def test_the_lab_example_runs_every_node_on_can0_without_the_simulator(tmp_path):
    spec = load_launch_spec(LAB)
    assert [n.name for n in spec.selected(sim=False)] == ["waveform_generator", "accel_feedback", "part_tracker",
                                                          "field_planner", "viz"]
    entries = {e.name: e for e in launch_entries(LAB, sim=False, out_dir=tmp_path)}
    for name in ("waveform_generator", "accel_feedback"):
        assert entries[name].parameters["can_interface"] == "socketcan"
        assert entries[name].parameters["can_channel"] == "can0"
    assert Path(entries["part_tracker"].parameters["camera_config"]).exists()
    # The generator asks for real-time scheduling on the real device as in the simulated stack.
    assert entries["waveform_generator"].env == {"PPOD_REALTIME_PRIORITY": "10", "OPENBLAS_NUM_THREADS": "1"}
    assert all(not e.env for name, e in entries.items() if name != "waveform_generator")

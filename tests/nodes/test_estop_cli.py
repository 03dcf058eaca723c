"""`ppod estop` writes the emergency-stop frame straight to the bus, whatever runs."""

import time

from tests.support.sim_thread import SimThread


def test_estop_command_latches_the_device_in_estop():
    from ppod_nodes.cli.main import main
    from ppod_ros.can import DeviceState

    with SimThread() as sim:
        assert main(["estop", "--interface", "virtual", "--channel", sim.channel]) == 0
        deadline = time.monotonic() + 3
        while sim.device.state != DeviceState.ESTOP and time.monotonic() < deadline:
            time.sleep(0.02)
        assert sim.device.state == DeviceState.ESTOP


def test_estop_without_a_channel_stops_the_simulator_of_its_own_domains_stack(tmp_path, monkeypatch):
    """Two `ppod up --sim` stacks in two ROS domains: each shell's `ppod estop` stops its own
    simulator. (One run file served every domain: the second stack's overwrote the first's, and
    the first domain's estop went to the second's simulator.)"""
    import os

    from ppod_nodes.cli.main import main
    from ppod_nodes.launch import runfile
    from ppod_ros.can import DeviceState

    monkeypatch.setenv("PPOD_RUN_DIR", str(tmp_path))
    mine = os.environ.get("ROS_DOMAIN_ID", "0")
    other = str(int(mine) + 1)
    with SimThread() as ours, SimThread() as theirs:
        runfile.write({"sim": True, "domain": mine, "sim_bridge": ours.sim.url})
        runfile.write({"sim": True, "domain": other, "sim_bridge": theirs.sim.url})
        assert main(["estop"]) == 0
        deadline = time.monotonic() + 3
        while ours.device.state != DeviceState.ESTOP and time.monotonic() < deadline:
            time.sleep(0.02)
        assert ours.device.state == DeviceState.ESTOP
        assert theirs.device.state != DeviceState.ESTOP


def test_estop_on_a_bus_that_cannot_open_is_one_clear_error(capsys):
    from ppod_nodes.cli.main import main

    assert main(["estop", "--interface", "remote", "--channel", "ws://127.0.0.1:9/"]) == 2
    assert "estop: error" in capsys.readouterr().err

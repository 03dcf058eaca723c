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


def test_estop_on_a_bus_that_cannot_open_is_one_clear_error(capsys):
    from ppod_nodes.cli.main import main

    assert main(["estop", "--interface", "remote", "--channel", "ws://127.0.0.1:9/"]) == 2
    assert "estop: error" in capsys.readouterr().err

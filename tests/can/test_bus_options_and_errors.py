"""Real hardware by configuration: can.options reach python-can, a backend failure is one line."""

import copy

import can
import pytest
import yaml

from ppod_ros.can.bus import open_bus
from ppod_ros.device.config import default_device_config_path, device_config_from_dict
from ppod_ros.errors import ConfigError, DeviceError


def _device_dict(**can_changes):
    data = yaml.safe_load(default_device_config_path().read_text())
    data = copy.deepcopy(data)
    data["can"].update(can_changes)
    return data


def test_can_options_are_passed_to_python_can():
    # receive_own_messages is a python-can keyword the bus factory never sets itself for "virtual".
    cfg = device_config_from_dict(_device_dict(interface="virtual", channel="opts-test",
                                               options={"receive_own_messages": True}))
    assert dict(cfg.can.options) == {"receive_own_messages": True}
    bus = open_bus(cfg.can)
    try:
        bus.send(can.Message(arbitration_id=0x31, data=b"\x01\x00", is_extended_id=False))
        echoed = bus.recv(timeout=2.0)
    finally:
        bus.shutdown()
    assert echoed is not None and echoed.arbitration_id == 0x31


@pytest.mark.parametrize("options, words", [
    ({"bitrate": 500000}, "belong in can.bitrate"),
    (["tty_baudrate"], "expected a mapping"),
    ({"tty_baudrate": {"nested": 1}}, "can.options.tty_baudrate"),
])
def test_malformed_can_options_are_one_line_config_errors(options, words):
    with pytest.raises(ConfigError, match=words) as info:
        device_config_from_dict(_device_dict(options=options))
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("interface, channel", [
    ("kvaser", "0"),        # no canlib here: python-can raises NameError from inside the backend
    ("pcan", "PCAN_USBBUS1"),
    ("socketcan", "can0"),  # no SocketCAN in this container
    ("slcan", "/dev/ttyACM0"),
])
def test_a_backend_that_cannot_open_is_one_device_error_line(interface, channel):
    with pytest.raises(DeviceError) as info:
        open_bus(interface=interface, channel=channel, bitrate=1_000_000)
    text = str(info.value)
    assert text.startswith(f"cannot open the {interface} bus on {channel!r}: ")
    assert "\n" not in text

"""The PPOD CAN protocol (docs/can_protocol.md): frame codec, bus factory, fault injection, host link.

- :mod:`ppod_ros.can.protocol`: identifiers, enumerations, scalings, frame timing and bus load
- :mod:`ppod_ros.can.codec`: ``encode``/``decode`` of every frame, error counting (records in
  :mod:`ppod_ros.can.commands` and :mod:`ppod_ros.can.reports`, field packing in ``packing``)
- :mod:`ppod_ros.can.assembly`: harmonic summaries and raw captures from their frames
- :mod:`ppod_ros.can.bus`: ``open_bus`` chooses the backend by name (virtual, remote, socketcan, ...)
- :mod:`ppod_ros.can.faults`: ``FaultInjectingBus`` (lost, delayed, corrupted frames, bus-off)
- :mod:`ppod_ros.can.host`: ``DeviceLink``, the host side used by the waveform generator and scripts
"""

from ppod_ros.can.assembly import AccelSummary, RawAssembler, RawCapture, SummaryAssembler
from ppod_ros.can.bus import open_bus, open_bus_waiting
from ppod_ros.can.faults import FaultInjectingBus
from ppod_ros.can.host import DeviceLink, DeviceSnapshot, send_estop
from ppod_ros.can.protocol import PROTOCOL_VERSION, AckResult, Command, DeviceState, Fault

__all__ = [
    "PROTOCOL_VERSION",
    "AccelSummary",
    "AckResult",
    "Command",
    "DeviceLink",
    "DeviceSnapshot",
    "DeviceState",
    "Fault",
    "FaultInjectingBus",
    "RawAssembler",
    "RawCapture",
    "SummaryAssembler",
    "open_bus",
    "open_bus_waiting",
    "send_estop",
]

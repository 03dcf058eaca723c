"""The simulated device process: device, virtual bus, localhost bridge and clock, wired together.

:class:`SimProcess` is what ``python -m ppod_sim`` runs; the simulator's ROS side (camera, /clock,
ground truth) and the parts simulation can build on it in the same process: ``device.cycle_callbacks``
delivers each completed cycle's true plate motion, ``on_step`` runs after every device step.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable

import can

from ppod_ros.device.config import DeviceConfig
from ppod_sim.bridge import Bridge
from ppod_sim.clock import Pacer
from ppod_sim.device import SimDevice

log = logging.getLogger(__name__)


class SimProcess:
    """One simulated device reachable over a localhost CAN bridge.

    Parameters
    ----------
    config : DeviceConfig
    port : int
        Bridge TCP port on 127.0.0.1 (0: any free port).
    rate : float
        Device seconds per wall second (``math.inf``: free-running).
    seed : int, optional
    channel : str, optional
        Name of the virtual channel (default: unique per process).
    """

    def __init__(
        self,
        config: DeviceConfig,
        *,
        port: int = 0,
        rate: float = 1.0,
        seed: int | None = None,
        channel: str | None = None,
    ):
        self.config = config
        self.channel = channel or f"ppod-sim-{os.getpid()}-{id(self):x}"
        self.device_bus = can.Bus(interface="virtual", channel=self.channel, receive_own_messages=False)
        self.device = SimDevice(config, self.device_bus, seed)
        self.bridge = Bridge(self.channel, port)
        self.pacer = Pacer(rate)
        self.on_step: list[Callable[[SimDevice], None]] = []
        self.wall_s = 0.0

    @property
    def url(self) -> str:
        return self.bridge.url

    def run(self, stop: threading.Event | None = None, duration_s: float | None = None) -> None:
        """Run until ``stop`` is set or ``duration_s`` of device time has passed."""
        stop = stop or threading.Event()
        dev = self.device
        end = None if duration_s is None else dev.time_s + duration_s
        batch = self.pacer.chunks_per_step()
        t0 = time.monotonic()
        self.pacer.start(dev.time_s)
        while not stop.is_set() and (end is None or dev.time_s < end - 1e-12):
            dev.step(batch)
            for callback in self.on_step:
                callback(dev)
            self.pacer.wait(dev.time_s, stop)
        self.wall_s += time.monotonic() - t0

    def close(self) -> None:
        self.bridge.close()
        self.device_bus.shutdown()


__all__ = ["SimProcess"]

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
        self.deliver_wait_s = 0.005
        self.deliver_waits = 0
        self.deliver_waited_s = 0.0
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
            self._deliver()
            dev.step(batch)
            for callback in self.on_step:
                callback(dev)
            self.pacer.wait(dev.time_s, stop, catch_up=self._may_catch_up())
        self.wall_s += time.monotonic() - t0

    def _deliver(self) -> None:
        """Once a heartbeat is due (the watchdog armed, the last one a heartbeat period old), let the
        bridge read what the host has sent before the device steps on: a real device has its frames
        when they are sent. The bridge's reading threads share this process's GIL with the device, the
        camera and the parts; on a loaded machine a heartbeat waited in the socket up to 120 ms of wall
        time while the device ran on (its watchdog saw the host's 50 ms heartbeats up to 152 ms
        apart). At most ``deliver_wait_s`` per step, so a socket that stays readable cannot hold the
        device (tests/device/test_sim_pacing.py)."""
        dev = self.device
        if not (self.deliver_wait_s and dev.watchdog_armed):
            return
        if dev.heartbeat_age_s() < self.config.can.heartbeat_period_s:
            return  # no heartbeat due yet: the other frames can wait for the reading thread's turn
        if not self.bridge.pending():
            return
        t0 = time.monotonic()
        while time.monotonic() - t0 < self.deliver_wait_s and self.bridge.pending():
            time.sleep(0.0002)  # gives the GIL to the reading thread
        self.deliver_waits += 1
        self.deliver_waited_s += time.monotonic() - t0

    def _may_catch_up(self) -> bool:
        """Whether a device behind the wall clock may run faster than the rate now.

        Catching up stretches the host's heartbeat intervals in device time. While the watchdog is
        armed the last heartbeat's age in device time is held to at most the catch-up rate times its
        age in wall time since it reached the device's bus (the catch-up's credit would otherwise
        spend a burst of device time on one interval): an interval of w at the bus is at most
        ``catch_up_rate`` x w of device time, one step more, whatever the steps' unevenness.
        """
        dev = self.device
        if not dev.watchdog_armed or dev.last_heartbeat_wall_s is None:
            return True
        wall_age = time.time() - dev.last_heartbeat_wall_s
        return dev.heartbeat_age_s() <= self.pacer.rate * self.pacer.catch_up_rate * wall_age

    def close(self) -> None:
        self.bridge.close()
        self.device_bus.shutdown()


__all__ = ["SimProcess"]

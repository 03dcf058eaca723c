"""The simulated device's clock: device time paced against the wall clock by a rate factor.

The device keeps its own time (:attr:`ppod_sim.device.SimDevice.time_s`), advanced chunk by chunk.
:class:`Pacer` sleeps so that device time runs ``rate`` times as fast as the wall clock (1: real
time; 10: ten times faster; ``math.inf``: as fast as the computer allows). When the simulation
cannot keep up it runs late and reports the lag rather than skipping device time: the device's own
timing (ramps, watchdog) is always exact in device time.

A stall (a starved process, a garbage collection) is not caught up by racing: device time would
then run faster than the wall clock while the host's heartbeats keep arriving at wall-clock pace,
and the device's watchdog would trip on a host that did nothing wrong (a real device never
stalls). Lag beyond ``max_catch_up_s`` (50 ms: with heartbeats every 50 ms, a catch-up then leaves
gaps of at most 100 ms of device time, under the 150 ms watchdog) is given up instead: the device
clock slips behind the wall clock by that much (counted in :attr:`Pacer.slipped_s`) and then runs
at the rate again.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

from ppod_ros.errors import ConfigError


class Pacer:
    """Keeps device time at ``rate`` x wall time.

    Parameters
    ----------
    rate : float
        Device seconds per wall second, > 0 (``math.inf``: free-running).
    max_catch_up_s : float
        Largest lag (wall seconds) made up by running faster than the rate; beyond it the device
        clock slips.
    clock, sleep : callables, optional
        Wall clock and sleep (for tests).
    """

    def __init__(
        self,
        rate: float = 1.0,
        max_catch_up_s: float = 0.05,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ):
        if not (rate > 0):
            raise ConfigError(f"rate: must be > 0 (inf: as fast as possible), got {rate}")
        if not (max_catch_up_s >= 0):
            raise ConfigError(f"max_catch_up_s: must be >= 0, got {max_catch_up_s}")
        self.rate = float(rate)
        self.max_catch_up_s = float(max_catch_up_s)
        self.clock = clock
        self.sleep = sleep
        self._wall0: float | None = None
        self._dev0 = 0.0
        self.lag_s = 0.0
        self.max_lag_s = 0.0
        self.slipped_s = 0.0
        self.slips = 0

    def start(self, device_time_s: float) -> None:
        self._wall0 = self.clock()
        self._dev0 = device_time_s

    def wait(self, device_time_s: float, stop: threading.Event | None = None) -> None:
        """Sleep until the wall clock reaches ``device_time_s`` (scaled by the rate)."""
        if self._wall0 is None:
            self.start(device_time_s)
            return
        if math.isinf(self.rate):
            return
        due = self._wall0 + (device_time_s - self._dev0) / self.rate
        delay = due - self.clock()
        self.lag_s = max(0.0, -delay)
        self.max_lag_s = max(self.max_lag_s, self.lag_s)
        if self.lag_s > self.max_catch_up_s:
            # Give the lag up: from now on device time is due relative to this moment.
            self._wall0 += self.lag_s
            self.slipped_s += self.lag_s
            self.slips += 1
            return
        if delay > 0:
            if stop is not None:
                stop.wait(delay)
            else:
                self.sleep(delay)

    def chunks_per_step(self) -> int:
        """Firmware periods a device step may batch: 1 in real time, more when running faster."""
        return 1 if self.rate <= 1 else (1 << 30 if math.isinf(self.rate) else max(1, int(self.rate)))

    def elapsed_wall_s(self) -> float:
        return 0.0 if self._wall0 is None else self.clock() - self._wall0


__all__ = ["Pacer"]

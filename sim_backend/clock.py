"""The simulated device's clock: device time paced against the wall clock by a rate factor.

The device keeps its own time (:attr:`ppod_sim.device.SimDevice.time_s`), advanced chunk by chunk.
:class:`Pacer` sleeps so that device time runs ``rate`` times as fast as the wall clock (1: real
time; 10: ten times faster; ``math.inf``: as fast as the computer allows). When the simulation
cannot keep up it runs late and reports the lag rather than skipping device time: the device's own
timing (ramps, watchdog) is always exact in device time.

Behind the wall clock (a starved process, a garbage collection), the device makes the lag up, but
never by racing: device time then runs at most ``catch_up_rate`` (1.25) times the rate. The host's
heartbeats arrive every 50 ms of wall time, so while catching up they arrive at most 63 ms of device
time apart, well inside the device's 150 ms watchdog (a real device never stalls, and a watchdog
tripped by the simulator's own stall would blame a host that did nothing wrong). A lag beyond
``max_catch_up_s`` (1 s: a suspended process, a debugger) is given up instead: the device clock
slips behind the wall clock by that much (counted in :attr:`Pacer.slipped_s`) and then runs at the
rate again. Before, any lag over 50 ms was given up (the catch-up then ran as fast as the computer
allowed, which only a small lag kept inside the watchdog): a demo on an idle machine slipped 0.2 s
in three stalls of the stack's own bursts, and ran at 0.99x real time instead of 1x.

The catch-up rate holds over the steps together, not step by step: the simulated device's steps are
uneven (the one that simulates a cycle ahead costs several cheap ones), and a step that overran the
catch-up line leaves its overrun, up to ``catch_up_credit_s`` (25 ms of wall time), for the steps after
it to make up. Over any wall interval w device time then runs at most ``catch_up_rate`` x (w + credit);
the device holds each heartbeat interval to ``catch_up_rate`` x its wall length by passing
``catch_up=False`` while the last heartbeat's device age is ahead of that (``SimProcess``).
Applied step by step from each step's end, an expensive step's overrun was lost and the cheap steps
were held to 1.25x: in ``ppod demo`` the device clock ran at 0.88x of the wall clock with the
simulator's main thread asleep a third of the time (tests/device/test_sim_clock.py).
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
    catch_up_rate : float
        Device time per wall time while behind, times the rate (1-2).
    catch_up_credit_s : float
        Wall time (0-0.05 s) by which a step that overran the catch-up line may leave the line behind
        it, for the cheaper steps after it to make up.
    """

    def __init__(
        self,
        rate: float = 1.0,
        max_catch_up_s: float = 1.0,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        catch_up_rate: float = 1.25,
        catch_up_credit_s: float = 0.025,
    ):
        if not (rate > 0):
            raise ConfigError(f"rate: must be > 0 (inf: as fast as possible), got {rate}")
        if not (max_catch_up_s >= 0):
            raise ConfigError(f"max_catch_up_s: must be >= 0, got {max_catch_up_s}")
        if not (1.0 <= catch_up_rate <= 2.0):
            raise ConfigError(f"catch_up_rate: must be in [1, 2] (device time per wall time while behind, "
                              f"times the rate), got {catch_up_rate}")
        if not (0.0 <= catch_up_credit_s <= 0.05):
            raise ConfigError(f"catch_up_credit_s: must be in [0, 0.05] (wall time an overrun step leaves to the "
                              f"steps after it), got {catch_up_credit_s}")
        self.rate = float(rate)
        self.max_catch_up_s = float(max_catch_up_s)
        self.catch_up_rate = float(catch_up_rate)
        self.catch_up_credit_s = float(catch_up_credit_s)
        self.clock = clock
        self.sleep = sleep
        self._wall0: float | None = None
        self._dev0 = 0.0
        self._released: tuple[float, float] = (0.0, 0.0)  # (wall, device) time of the last release
        self.lag_s = 0.0
        self.max_lag_s = 0.0
        self.slipped_s = 0.0
        self.slips = 0

    def start(self, device_time_s: float) -> None:
        self._wall0 = self.clock()
        self._dev0 = device_time_s
        self._released = (self._wall0, device_time_s)

    def wait(self, device_time_s: float, stop: threading.Event | None = None, catch_up: bool = True) -> None:
        """Sleep until the wall clock reaches ``device_time_s`` (scaled by the rate); behind it, until
        device time has run at most ``catch_up_rate`` times the rate since the last release.

        ``catch_up`` False: behind, device time runs at the rate and no faster, without credit (the
        device's heartbeat is overdue: a catch-up would stretch its age in device time)."""
        if self._wall0 is None:
            self.start(device_time_s)
            return
        if math.isinf(self.rate):
            return
        now = self.clock()
        delay = self._wall0 + (device_time_s - self._dev0) / self.rate - now
        self.lag_s = max(0.0, -delay)
        self.max_lag_s = max(self.max_lag_s, self.lag_s)
        if self.lag_s > self.max_catch_up_s:
            # Give the lag up: from now on device time is due relative to this moment.
            self._wall0 += self.lag_s
            self.slipped_s += self.lag_s
            self.slips += 1
            delay = 0.0
        elif delay < 0:
            # Behind: hold device time to catch_up_rate x the rate along the line from the last release;
            # a step past the line keeps it, at most catch_up_credit_s behind now.
            wall, dev = self._released
            due = wall + (device_time_s - dev) / (self.rate * (self.catch_up_rate if catch_up else 1.0))
            delay = due - now
            if delay < 0:
                self._released = (max(due, now - (self.catch_up_credit_s if catch_up else 0.0)), device_time_s)
                return
        if delay > 0:
            if stop is not None:
                stop.wait(delay)
            else:
                self.sleep(delay)
        self._released = (now + max(delay, 0.0), device_time_s)

    def chunks_per_step(self) -> int:
        """Firmware periods a device step may batch: 1 in real time, more when running faster."""
        return 1 if self.rate <= 1 else (1 << 30 if math.isinf(self.rate) else max(1, int(self.rate)))

    def elapsed_wall_s(self) -> float:
        return 0.0 if self._wall0 is None else self.clock() - self._wall0


__all__ = ["Pacer"]

"""Bus load measured from the frames a host sees: ``DeviceStatus.bus_load``.

:class:`BusLoadMeter` keeps the wire time of each frame (:func:`~ppod_ros.can.protocol.frame_bits`,
worst-case stuffing) over a sliding window and reports the fraction of the bit rate they used.
:class:`MeteredBus` wraps any ``can.BusABC`` and feeds it every frame received and every frame this
host sent (a socket does not receive its own frames, but they occupy the wire all the same)::

    bus = MeteredBus(open_bus(config.can), bitrate=config.can.bitrate)
    link = DeviceLink(bus, config)
    ...
    bus.load()          # 0.154: 15.4 % of 1 Mbit/s over the last second

What it cannot see: frames that other hosts exchange with each other when the backend filters them
out. On SocketCAN and the simulator's bridge every frame on the bus reaches every socket.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable

import can

from ppod_ros.can.protocol import frame_bits
from ppod_ros.errors import ConfigError

#: Window of the measurement (s): the documented "over the last second" of DeviceStatus.bus_load.
LOAD_WINDOW_S = 1.0


class BusLoadMeter:
    """Fraction of ``bitrate`` used by the frames added in the last ``window_s`` seconds."""

    def __init__(self, bitrate: int, window_s: float = LOAD_WINDOW_S, clock: Callable[[], float] = time.monotonic):
        if not bitrate > 0:
            raise ConfigError(f"bitrate: must be > 0 bit/s, got {bitrate}")
        if not window_s > 0:
            raise ConfigError(f"window_s: must be > 0 s, got {window_s}")
        self.bitrate = int(bitrate)
        self.window_s = float(window_s)
        self.clock = clock
        self._frames: deque[tuple[float, int]] = deque()
        self._bits = 0
        self._started = clock()
        self._lock = threading.Lock()

    def add(self, data_bytes: int, t: float | None = None) -> None:
        """Count one classic data frame of ``data_bytes`` (0..8) seen at time ``t`` (default: now)."""
        bits = frame_bits(min(max(int(data_bytes), 0), 8))
        now = self.clock() if t is None else t
        with self._lock:
            self._frames.append((now, bits))
            self._bits += bits
            self._expire(now)

    def _expire(self, now: float) -> None:
        while self._frames and self._frames[0][0] <= now - self.window_s:
            self._bits -= self._frames.popleft()[1]

    def load(self, now: float | None = None) -> float:
        """0..1 (more when frames arrive faster than the wire allows, e.g. a bridge catching up)."""
        now = self.clock() if now is None else now
        with self._lock:
            self._expire(now)
            # Before a whole window has passed, divide by the time observed so far (at least 0.1 s).
            span = min(self.window_s, max(now - self._started, 0.1 * self.window_s))
            return self._bits / (span * self.bitrate)


class MeteredBus(can.BusABC):
    """``inner`` with every frame it sends or receives counted in ``meter`` (see the module docstring)."""

    def __init__(self, inner: can.BusABC, bitrate: int, window_s: float = LOAD_WINDOW_S, **kwargs):
        self.inner = inner
        self.meter = BusLoadMeter(bitrate, window_s)
        self.channel_info = f"metered {getattr(inner, 'channel_info', inner)}"
        super().__init__(channel=getattr(inner, "channel", None), **kwargs)

    def load(self) -> float:
        return self.meter.load()

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.inner.send(msg, timeout)
        if not (msg.is_error_frame or msg.is_remote_frame):
            self.meter.add(len(msg.data))

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        msg = self.inner.recv(timeout)
        if msg is not None and not msg.is_error_frame:
            self.meter.add(0 if msg.is_remote_frame else len(msg.data))
        return msg, False

    def shutdown(self) -> None:
        self.inner.shutdown()
        super().shutdown()


__all__ = ["LOAD_WINDOW_S", "BusLoadMeter", "MeteredBus"]

"""A bus wrapper that injects faults, for tests: lost, delayed and corrupted frames, bus-off.

``FaultInjectingBus(inner, ...)`` behaves like ``inner`` (any ``can.BusABC``; shutting the wrapper down
shuts ``inner`` down) except that:

* each sent and each received frame is lost with probability ``drop``;
* each surviving frame is corrupted with probability ``corrupt``: a flipped payload bit, a
  truncated payload or an identifier moved to an unused function code (what a faulty node or a
  broken transceiver produces; a real bus's CRC would catch most, not all);
* sent frames are held back ``delay_s`` (wall clock, by a worker thread) before they reach ``inner``;
* :meth:`FaultInjectingBus.go_bus_off` makes the bus refuse every send with ``can.CanOperationError``
  and lose every frame until :meth:`recover` or until ``bus_off_s`` has passed.

All random choices come from ``seed``; counts of what was done are in :attr:`stats`.
"""

from __future__ import annotations

import heapq
import itertools
import threading
import time
from collections import Counter
from typing import Any

import can
import numpy as np


class FaultInjectingBus(can.BusABC):
    """Wraps a bus and injects faults (see the module docstring)."""

    def __init__(
        self,
        inner: can.BusABC,
        *,
        drop: float = 0.0,
        corrupt: float = 0.0,
        delay_s: float = 0.0,
        seed: int = 0,
        affect: str = "both",
        **kwargs: Any,
    ):
        if affect not in ("both", "send", "receive"):
            raise ValueError(f"affect: expected both, send or receive, got {affect!r}")
        self.inner = inner
        self.drop = float(drop)
        self.corrupt = float(corrupt)
        self.delay_s = float(delay_s)
        self.affect = affect
        self.rng = np.random.default_rng(seed)
        self.stats: Counter = Counter()
        self._bus_off_until: float | None = None
        self._queue: list[tuple[float, int, can.Message]] = []
        self._counter = itertools.count()
        self._cv = threading.Condition()
        self._worker: threading.Thread | None = None
        self._closing = False
        self.channel_info = f"fault-injecting wrapper of {getattr(inner, 'channel_info', inner)}"
        super().__init__(channel=getattr(inner, "channel", None), **kwargs)

    # ------------------------------------------------------------------ bus-off
    def go_bus_off(self, duration_s: float | None = None) -> None:
        """Enter bus-off: sends fail and frames are lost, for ``duration_s`` (None: until recover())."""
        self._bus_off_until = time.monotonic() + duration_s if duration_s is not None else float("inf")
        self.stats["bus_off"] += 1

    def recover(self) -> None:
        self._bus_off_until = None

    @property
    def is_bus_off(self) -> bool:
        if self._bus_off_until is None:
            return False
        if time.monotonic() >= self._bus_off_until:
            self._bus_off_until = None
            return False
        return True

    # ------------------------------------------------------------------ faults
    def _mangle(self, msg: can.Message, direction: str) -> can.Message | None:
        if self.affect not in ("both", direction):
            return msg
        if self.drop and self.rng.random() < self.drop:
            self.stats[f"dropped_{direction}"] += 1
            return None
        if self.corrupt and self.rng.random() < self.corrupt:
            self.stats[f"corrupted_{direction}"] += 1
            data = bytearray(msg.data)
            mode = self.rng.integers(3)
            arb = msg.arbitration_id
            if mode == 0 and data:
                bit = int(self.rng.integers(8 * len(data)))
                data[bit // 8] ^= 1 << (bit % 8)
            elif mode == 1 and data:
                data = data[: int(self.rng.integers(len(data)))]
            else:
                arb = (0x7F << 4) | (arb & 0xF)  # function 127: not in the protocol
            return can.Message(
                arbitration_id=arb,
                data=bytes(data),
                is_extended_id=msg.is_extended_id,
                timestamp=msg.timestamp,
            )
        return msg

    # ------------------------------------------------------------------ BusABC
    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.is_bus_off:
            self.stats["refused_bus_off"] += 1
            raise can.CanOperationError("bus off (injected)")
        out = self._mangle(msg, "send")
        if out is None:
            return
        if self.delay_s > 0:
            with self._cv:
                heapq.heappush(self._queue, (time.monotonic() + self.delay_s, next(self._counter), out))
                self.stats["delayed"] += 1
                if self._worker is None:
                    self._worker = threading.Thread(target=self._deliver, name="fault-bus-delay", daemon=True)
                    self._worker.start()
                self._cv.notify()
            return
        self.inner.send(out, timeout)

    def _deliver(self) -> None:
        while True:
            with self._cv:
                while not self._closing and (not self._queue or self._queue[0][0] > time.monotonic()):
                    wait = None if not self._queue else max(0.0, self._queue[0][0] - time.monotonic())
                    self._cv.wait(wait)
                if self._closing:
                    return
                _, _, msg = heapq.heappop(self._queue)
            if self.is_bus_off:
                self.stats["lost_bus_off"] += 1
                continue
            try:
                self.inner.send(msg)
            except can.CanError:
                self.stats["delayed_send_failed"] += 1

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            msg = self.inner.recv(remaining)
            if msg is None:
                return None, False
            if self.is_bus_off:
                self.stats["lost_bus_off"] += 1
            else:
                out = self._mangle(msg, "receive")
                if out is not None:
                    return out, False
            if deadline is not None and time.monotonic() >= deadline:
                return None, False

    def shutdown(self) -> None:
        with self._cv:
            self._closing = True
            self._cv.notify_all()
        if self._worker is not None:
            self._worker.join(timeout=1.0)
        self.inner.shutdown()  # the wrapper owns the bus it wraps, as MeteredBus does
        super().shutdown()


__all__ = ["FaultInjectingBus"]

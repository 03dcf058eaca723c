"""What the simulated device reports over CAN: harmonic summaries, raw captures and status.

* Harmonic summaries (live, low load): the device computes each cycle's phasors of every channel
  at harmonics 1..H from the cycle's N samples (``X_k = (2i/N) sum_n y_n e^{-i k 2 pi n / N}``,
  sample n at ``n T / N`` after the cycle start), averages ``n_cycles`` consecutive cycles and
  sends one SUMMARY_HEADER (first cycle index, cycle count, samples per cycle, table sequence) and
  C x H SUMMARY_DATA frames. H = max(can.summary_harmonics, the active table's top harmonic, the
  harmonics the host asked for with CONTROL SUMMARY_HARMONICS), at most 10 and below N / 2;
  ``n_cycles`` keeps the summary frames within their budget (:meth:`Telemetry.summary_plan`).
* Raw captures (bounded): on RAW_REQUEST the device records the masked channels over the next
  n whole cycles (at most 4096 samples per channel), then sends RAW_HEADER and the samples,
  three per frame, paced at ``can.raw_frame_rate_hz``. Summaries pause while a capture is sent, so
  the bus load stays bounded.
* Status: STATUS and STATUS_EXT at ``can.status_rate_hz`` (the device's heartbeat), COIL_TEMP and
  COIL_RMS once a second; a FAULT frame on every change of state or fault flags.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import can
import numpy as np

from ppod_ros.can.codec import RawData, RawHeader, SummaryHeader, encode_summary
from ppod_ros.can.protocol import MAX_RAW_SAMPLES, MAX_SUMMARY_CYCLES, MAX_TABLE_HARMONIC


@dataclass
class _Group:
    first_cycle: int
    n_cycles: int
    harmonics: int
    samples_per_cycle: int
    table_seq: int
    frequency_hz: float
    total: np.ndarray
    count: int = 0


@dataclass
class _Capture:
    capture_id: int
    mask: int
    n_cycles: int
    channels: list[int]
    samples_per_cycle: int = 0
    start_cycle: int = -1
    data: list[np.ndarray] = field(default_factory=list)
    frames: list[can.Message] = field(default_factory=list)
    sent: int = 0
    credit: float = 0.0


class Telemetry:
    """Builds the device's outgoing data frames (see the module docstring).

    Parameters
    ----------
    n_channels : int
    node : int
        The device's node id.
    summary_max_rate_hz, summary_harmonics, raw_frame_rate_hz : from CanSettings.
    send : callable(can.Message)
    """

    def __init__(
        self,
        n_channels: int,
        node: int,
        summary_max_rate_hz: float,
        summary_harmonics: int,
        raw_frame_rate_hz: float,
        send: Callable[[can.Message], None],
    ):
        self.n_channels = n_channels
        self.node = node
        self.summary_max_rate_hz = summary_max_rate_hz
        self.summary_harmonics = summary_harmonics
        self.raw_frame_rate_hz = raw_frame_rate_hz
        self.send = send
        #: Harmonics the host asked the summaries to carry (CONTROL SUMMARY_HARMONICS).
        self.requested_harmonics = 0
        self._group: _Group | None = None
        self._seq = 0
        self._capture: _Capture | None = None
        self.summaries_sent = 0
        self.captures_sent = 0

    # ------------------------------------------------------------------ summaries
    def summary_harmonics_for(self, samples_per_cycle: int, table_top: int) -> int:
        return int(
            min(max(self.summary_harmonics, table_top, self.requested_harmonics), MAX_TABLE_HARMONIC,
                samples_per_cycle // 2 - 1)
        )

    def summary_plan(self, frequency_hz: float, samples_per_cycle: int, table_top: int) -> tuple[int, int]:
        """(H, cycles per summary) within the frame budget (docs/can_protocol.md, "Bus load").

        Summary frames per second never exceed ``(C summary_harmonics + 1) summary_max_rate_hz``:
        more harmonics are averaged over more cycles, and where even 16 cycles would not do, the
        summaries carry fewer harmonics (never fewer than ``summary_harmonics``).
        """
        C = self.n_channels
        budget = (C * self.summary_harmonics + 1) * self.summary_max_rate_hz  # frames/s
        H = self.summary_harmonics_for(samples_per_cycle, table_top)
        fit = int(((MAX_SUMMARY_CYCLES * budget / frequency_hz) - 1) // C)
        H = max(min(H, fit), min(self.summary_harmonics, H))
        n = math.ceil(frequency_hz * (C * H + 1) / budget - 1e-9)
        return H, min(MAX_SUMMARY_CYCLES, max(1, n))

    def end_of_cycle(
        self, cycle_index: int, samples: np.ndarray, frequency_hz: float, table_seq: int, table_top: int
    ) -> None:
        """Feed one whole cycle's samples (N, C); sends a summary when a group is complete."""
        spc = samples.shape[0]
        if self._capture is not None and self._capture.start_cycle >= 0 and not self._capture.frames:
            self._record(samples)
        if self._capture is not None and self._capture.frames:
            self._group = None  # summaries pause while a raw capture is on the bus
            return
        H, n = self.summary_plan(frequency_hz, spc, table_top)
        g = self._group
        if (
            g is None
            or g.samples_per_cycle != spc
            or g.frequency_hz != frequency_hz
            or g.harmonics != H
            or g.table_seq != table_seq
        ):
            g = self._group = _Group(
                cycle_index, n, H, spc, table_seq, frequency_hz, np.zeros((H, self.n_channels), complex)
            )
        spectrum = np.fft.rfft(samples, axis=0)[1 : H + 1]
        g.total += (2j / spc) * spectrum
        g.count += 1
        if g.count == g.n_cycles:
            self._send_summary(g)
            self._group = None

    def _send_summary(self, g: _Group) -> None:
        seq = self._seq
        self._seq = (self._seq + 1) % 256
        header = SummaryHeader(seq, g.n_cycles, g.harmonics, g.first_cycle, g.samples_per_cycle, g.table_seq)
        for msg in encode_summary(header, g.total / g.count, self.node):
            self.send(msg)
        self.summaries_sent += 1

    # ------------------------------------------------------------------ raw captures
    def request_raw(self, capture_id: int, channel_mask: int, n_cycles: int) -> None:
        """Arm a capture; it starts at the next cycle start (a running capture is replaced)."""
        channels = [c for c in range(self.n_channels) if channel_mask >> c & 1]
        if not channels:
            return
        self._capture = _Capture(capture_id, channel_mask & ((1 << self.n_channels) - 1), n_cycles, channels)

    def start_of_cycle(self, cycle_index: int, samples_per_cycle: int) -> None:
        cap = self._capture
        if cap is not None and cap.start_cycle < 0:
            cap.start_cycle = cycle_index
            cap.samples_per_cycle = samples_per_cycle
            cap.n_cycles = max(1, min(cap.n_cycles, MAX_RAW_SAMPLES // samples_per_cycle))

    def _record(self, samples: np.ndarray) -> None:
        cap = self._capture
        if samples.shape[0] != cap.samples_per_cycle:  # the frequency changed mid-capture: start over
            cap.start_cycle, cap.data = -1, []
            return
        cap.data.append(samples[:, cap.channels])
        if len(cap.data) == cap.n_cycles:
            data = np.concatenate(cap.data)
            frames = [
                RawHeader(
                    cap.capture_id, cap.n_cycles, cap.mask, cap.start_cycle, cap.samples_per_cycle
                ).encode(self.node)
            ]
            for col, ch in enumerate(cap.channels):
                for i in range(0, data.shape[0], 3):
                    vals = np.zeros(3)
                    chunk = data[i : i + 3, col]
                    vals[: chunk.size] = np.clip(chunk, -63.99, 63.99)
                    frames.append(RawData(ch, i, tuple(float(v) for v in vals)).encode(self.node))
            cap.frames = frames

    def pump(self, dt_s: float) -> None:
        """Send the raw frames due in the next ``dt_s`` of device time (paced)."""
        cap = self._capture
        if cap is None or not cap.frames:
            return
        cap.credit += self.raw_frame_rate_hz * dt_s
        n = int(cap.credit)
        cap.credit -= n
        for msg in cap.frames[cap.sent : cap.sent + n]:
            self.send(msg)
        cap.sent += n
        if cap.sent >= len(cap.frames):
            self._capture = None
            self.captures_sent += 1

    @property
    def capture_busy(self) -> bool:
        return self._capture is not None


__all__ = ["Telemetry"]

"""Reassembly of the device's multi-frame data: harmonic summaries and raw captures.

A summary is a SUMMARY_HEADER and C x H SUMMARY_DATA frames with the same sequence number; a raw
capture is a RAW_HEADER and the RAW_DATA frames of every masked channel. Frames may be lost: an
incomplete summary or capture is dropped (and counted) when the next header arrives; data frames
that belong to no open header are counted as orphans. A listen-only receiver (for example the
feedback side) can use these classes directly on decoded frames.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ppod_ros.can.protocol import MAX_CHANNELS
from ppod_ros.can.reports import RawData, RawHeader, SummaryData, SummaryHeader


@dataclass(frozen=True, eq=False)
class AccelSummary:
    """One harmonic summary of every accelerometer channel.

    Attributes
    ----------
    seq : int
    first_cycle : int
        Device cycle index (mod 2^24) of the first averaged cycle; phases refer to cycle starts.
    n_cycles : int
        Whole cycles averaged.
    samples_per_cycle : int
        Samples per cycle: sample n of a cycle was taken n T / N after its start.
    table_seq : int
        The device's active table when the summary was computed.
    frequency_hz : float
        The fundamental of that table (NaN when the receiver does not know the table).
    k : ndarray, shape (H,)
        Harmonics 1..H.
    phasors : complex ndarray, shape (H, C)
        Channel phasors (m/s^2), ``y_c(t) = sum_k Im(X_kc e^{i k Omega t})``.
    received_at : float
        Receiver time of the last frame (the clock the receiver passed in).
    """

    seq: int
    first_cycle: int
    n_cycles: int
    samples_per_cycle: int
    table_seq: int
    frequency_hz: float
    k: np.ndarray
    phasors: np.ndarray
    received_at: float


@dataclass(frozen=True, eq=False)
class RawCapture:
    """Raw accelerometer samples of whole cycles: ``samples[n, j]`` of channel ``channels[j]``.

    Sample n was taken ``(n % samples_per_cycle) T / N`` after the start of cycle
    ``start_cycle + n // samples_per_cycle``.
    """

    capture_id: int
    start_cycle: int
    n_cycles: int
    samples_per_cycle: int
    channels: tuple[int, ...]
    samples: np.ndarray


class SummaryAssembler:
    """Builds :class:`AccelSummary` records from decoded SUMMARY_HEADER / SUMMARY_DATA frames.

    Parameters
    ----------
    n_channels : int
        Channels per summary (the device's accelerometer channel count).
    frequency_of : callable(table_seq) -> float, optional
        Looks up the fundamental of a table sequence number (default: NaN).
    """

    def __init__(self, n_channels: int, frequency_of: Callable[[int], float] | None = None):
        self.n_channels = int(n_channels)
        self.frequency_of = frequency_of or (lambda seq: math.nan)
        self.completed = 0
        self.incomplete = 0
        self.orphans = 0
        self._header: SummaryHeader | None = None
        self._values = np.zeros((0, 0), complex)
        self._filled = np.zeros((0, 0), bool)

    def header(self, rec: SummaryHeader) -> None:
        if self._header is not None:
            self.incomplete += 1
        self._header = rec
        self._values = np.zeros((rec.harmonics, self.n_channels), complex)
        self._filled = np.zeros((rec.harmonics, self.n_channels), bool)

    def data(self, rec: SummaryData, now: float) -> AccelSummary | None:
        """Add one data frame; returns the summary when it is complete."""
        h = self._header
        if h is None or rec.seq != h.seq or rec.k > h.harmonics or rec.channel >= self.n_channels:
            self.orphans += 1
            return None
        self._values[rec.k - 1, rec.channel] = rec.value_mps2
        self._filled[rec.k - 1, rec.channel] = True
        if not self._filled.all():
            return None
        self._header = None
        self.completed += 1
        return AccelSummary(
            h.seq,
            h.cycle_index,
            h.n_cycles,
            h.samples_per_cycle,
            h.table_seq,
            self.frequency_of(h.table_seq),
            np.arange(1, h.harmonics + 1),
            self._values,
            now,
        )


class RawAssembler:
    """Builds :class:`RawCapture` records from decoded RAW_HEADER / RAW_DATA frames."""

    def __init__(self) -> None:
        self.completed = 0
        self.incomplete = 0
        self.orphans = 0
        self._header: RawHeader | None = None
        self._channels: tuple[int, ...] = ()
        self._samples = np.zeros((0, 0))
        self._filled = np.zeros((0, 0), bool)

    def header(self, rec: RawHeader) -> None:
        if self._header is not None:
            self.incomplete += 1
        self._header = rec
        self._channels = tuple(c for c in range(MAX_CHANNELS) if rec.channel_mask >> c & 1)
        n = rec.n_cycles * rec.samples_per_cycle
        self._samples = np.zeros((n, len(self._channels)))
        self._filled = np.zeros((n, len(self._channels)), bool)

    def data(self, rec: RawData) -> RawCapture | None:
        """Add one data frame; returns the capture when every sample has arrived."""
        h = self._header
        if h is None or rec.channel not in self._channels:
            self.orphans += 1
            return None
        col = self._channels.index(rec.channel)
        n = self._samples.shape[0]
        for i, v in enumerate(rec.samples_mps2):
            if rec.index + i < n:  # the last frame of a channel is padded
                self._samples[rec.index + i, col] = v
                self._filled[rec.index + i, col] = True
        if not self._filled.all():
            return None
        self._header = None
        self.completed += 1
        return RawCapture(
            h.capture_id, h.start_cycle, h.n_cycles, h.samples_per_cycle, self._channels, self._samples
        )


__all__ = ["AccelSummary", "RawAssembler", "RawCapture", "SummaryAssembler"]

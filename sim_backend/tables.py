"""The device's back buffer: a table arrives frame by frame and is checked before it may play.

TABLE_HEADER opens the buffer for one sequence number, TABLE_ENTRY frames fill it, TABLE_COMMIT
closes it (docs/can_protocol.md). :class:`TableReceiver` answers a commit with the table to queue
for the next cycle start, or the reason to reject it: entries missing or duplicated, a checksum
mismatch, or the device's own limit check (peak current of each coil, highest harmonic, every
harmonic's frequency). The host checks much more before sending; this is the device's last line.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ppod_ros.actuation.harmonics import peak_abs
from ppod_ros.can.codec import TableCommit, TableEntry, TableHeader, table_checksum
from ppod_ros.can.protocol import AckResult
from ppod_ros.device.config import Limits
from ppod_ros.motion import MAX_HARMONIC
from ppod_sim.player import Table


@dataclass
class _Buffer:
    header: TableHeader
    entries: dict[tuple[int, int], TableEntry] = field(default_factory=dict)
    duplicates: int = 0


class TableReceiver:
    """Assembles and validates committed tables (see the module docstring).

    Parameters
    ----------
    limits : Limits
    min_ramp_s : float
        Tables ramp in over at least this long, whatever their header says.
    """

    def __init__(self, limits: Limits, min_ramp_s: float):
        self.limits = limits
        self.min_ramp_s = min_ramp_s
        self._buffer: _Buffer | None = None
        self.orphans = 0

    def header(self, rec: TableHeader) -> None:
        self._buffer = _Buffer(rec)

    def entry(self, rec: TableEntry) -> None:
        b = self._buffer
        if b is None or rec.seq != b.header.seq:
            self.orphans += 1
            return
        key = (rec.k, rec.actuator)
        b.duplicates += key in b.entries
        b.entries[key] = rec

    def discard(self) -> None:
        self._buffer = None

    def commit(self, rec: TableCommit) -> tuple[Table | None, AckResult | None]:
        """(the table, None) when it may be queued, else (None, the rejection)."""
        b, self._buffer = self._buffer, None
        if (
            b is None
            or b.header.seq != rec.seq
            or b.duplicates
            or len(b.entries) != rec.n_entries
            or b.header.n_entries != rec.n_entries
        ):
            return None, AckResult.INCOMPLETE
        if table_checksum(list(b.entries.values())) != rec.checksum:
            return None, AckResult.CHECKSUM
        K = max((k for k, _ in b.entries), default=1)
        currents = np.zeros((K, 6), complex)
        for (k, a), e in b.entries.items():
            currents[k - 1, a] = e.current_a
        if not self.within_limits(b.header.frequency_hz, currents):
            return None, AckResult.OVER_LIMIT
        return Table(rec.seq, b.header.frequency_hz, currents, max(b.header.ramp_s, self.min_ramp_s)), None

    def within_limits(self, frequency_hz: float, currents: np.ndarray) -> bool:
        """The device's own check of a dense (K, 6) table: harmonics, frequencies, peak currents."""
        lim = self.limits
        rows = np.flatnonzero(np.any(currents != 0, axis=1))
        if rows.size == 0:
            return True
        if int(rows[-1] + 1) > min(lim.max_table_harmonic, MAX_HARMONIC):
            return False
        freqs = frequency_hz * (rows + 1)
        if np.any(freqs < lim.frequency_range_hz[0]) or np.any(freqs > lim.frequency_range_hz[1]):
            return False
        peak = peak_abs(currents, np.arange(1, currents.shape[0] + 1))
        return bool(np.all(peak <= lim.coil_current_a))


__all__ = ["TableReceiver"]

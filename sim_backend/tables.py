"""The device's back buffer: a table arrives frame by frame and is checked before it may play.

TABLE_HEADER opens the buffer for one sequence number, TABLE_ENTRY frames fill it, TABLE_CRC
protects it, TABLE_COMMIT closes it (docs/can_protocol.md, protocol 2.0). :class:`TableReceiver`
answers a commit with the table to queue for the next cycle start, or the reason to reject it:
entries missing or duplicated or no TABLE_CRC (INCOMPLETE), a checksum or CRC mismatch (CHECKSUM),
or the device's own limit check (OVER_LIMIT): highest harmonic, every row's frequency inside the
band and outside every excluded band, peak current of each coil, and the leg stroke its own model
of the plant predicts. The device's limits are its own (its configuration, never the host's), and
it rejects only beyond :data:`DEVICE_LIMIT_TOLERANCE` of them, wider than the host's guard band, so
a table the host accepted is never rejected on the nominal plant. The host checks much more before
sending; this is the device's last line.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ppod_ros.actuation.harmonics import peak_abs
from ppod_ros.actuation.plant import NominalPlant
from ppod_ros.can.codec import TableCommit, TableCrc, TableEntry, TableHeader, table_checksum, table_crc
from ppod_ros.can.protocol import AckResult
from ppod_ros.device.config import DeviceConfig, Limits
from ppod_ros.motion import MAX_HARMONIC
from ppod_sim.player import Table

#: The device rejects a table only when its own check exceeds a limit by more than this factor: wider
#: than the host's guard band and its model error, so the host's accepted tables always pass.
DEVICE_LIMIT_TOLERANCE = 1.05


@dataclass
class _Buffer:
    header: TableHeader
    entries: dict[tuple[int, int], TableEntry] = field(default_factory=dict)
    duplicates: int = 0
    crc: TableCrc | None = None


class TableReceiver:
    """Assembles and validates committed tables (see the module docstring).

    Parameters
    ----------
    limits : Limits
    min_ramp_s : float
        Tables ramp in over at least this long, whatever their header says.
    plant : NominalPlant, optional
        The device's own model, for the predicted leg stroke (without it, stroke is not checked).
    """

    def __init__(self, limits: Limits, min_ramp_s: float, plant: NominalPlant | None = None):
        self.limits = limits
        self.min_ramp_s = min_ramp_s
        self.plant = plant
        self._buffer: _Buffer | None = None
        self.orphans = 0
        #: Why the last OVER_LIMIT was answered (the device's own limit name).
        self.last_reason = ""

    @classmethod
    def for_device(cls, config: DeviceConfig) -> TableReceiver:
        return cls(config.limits, config.timing.min_ramp_s, NominalPlant(config))

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

    def crc(self, rec: TableCrc) -> None:
        b = self._buffer
        if b is None or rec.seq != b.header.seq:
            self.orphans += 1
            return
        b.crc = rec

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
            or b.crc is None
            or b.crc.n_entries != rec.n_entries
        ):
            return None, AckResult.INCOMPLETE
        entries = list(b.entries.values())
        if table_checksum(entries) != rec.checksum or table_crc(b.header, entries) != b.crc.crc:
            return None, AckResult.CHECKSUM
        K = max((k for k, _ in b.entries), default=1)
        currents = np.zeros((K, 6), complex)
        for (k, a), e in b.entries.items():
            currents[k - 1, a] = e.current_a
        if not self.within_limits(b.header.frequency_hz, currents):
            return None, AckResult.OVER_LIMIT
        return Table(rec.seq, b.header.frequency_hz, currents, max(b.header.ramp_s, self.min_ramp_s)), None

    def within_limits(self, frequency_hz: float, currents: np.ndarray) -> bool:
        """The device's own check of a dense (K, 6) table (module docstring); sets ``last_reason``."""
        reason = self.violation(frequency_hz, currents)
        self.last_reason = reason or ""
        return reason is None

    def violation(self, frequency_hz: float, currents: np.ndarray) -> str | None:
        """The first of the device's own limits a table exceeds (None: it may play)."""
        lim, tol = self.limits, DEVICE_LIMIT_TOLERANCE
        rows = np.flatnonzero(np.any(currents != 0, axis=1))
        if rows.size == 0:
            return None
        if int(rows[-1] + 1) > min(lim.max_table_harmonic, MAX_HARMONIC):
            return "limits.max_table_harmonic"
        freqs = frequency_hz * (rows + 1)
        if np.any(freqs < lim.frequency_range_hz[0]) or np.any(freqs > lim.frequency_range_hz[1]):
            return "limits.frequency_range_hz"
        for lo, hi in lim.excluded_bands_hz:
            if np.any((freqs >= lo) & (freqs <= hi)):
                return "limits.excluded_bands_hz"
        k = np.arange(1, currents.shape[0] + 1)
        if np.any(peak_abs(currents, k) > tol * lim.coil_current_a):
            return "limits.coil_current_a"
        if self.plant is not None:
            legs = self.plant.predict(frequency_hz, currents, "leg")
            if np.any(peak_abs(legs, k) > tol * lim.leg_stroke_m):
                return "limits.leg_stroke_m"
        return None


__all__ = ["DEVICE_LIMIT_TOLERANCE", "TableReceiver"]

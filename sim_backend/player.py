"""The device's waveform player: committed tables, ramps and frequency changes.

The actuator controllers play ``i_ref(t) = (1 - s(t)) y_src(theta) + s(t) y_dst(theta)``: a
crossfade between two played tables (after the drive's imperfections, :mod:`ppod_sim.drive`) with
a raised-cosine ramp s from 0 to 1 over the ramp time, theta = Omega t measured from the cycle start.
Starting a new ramp freezes the current mix as the new source, so amplitude never steps.

Committed tables wait for a cycle boundary (:meth:`TablePlayer.on_cycle_boundary`). A table at
another fundamental cannot be crossfaded: the player first ramps to zero (over the new table's ramp
time), switches the frequency at the first cycle boundary where it is silent, and ramps up.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ppod_ros.actuation.harmonics import synthesize
from ppod_sim.drive import MAX_PLAYED_HARMONIC, ActuatorDrive, ramp_shape


@dataclass(frozen=True, eq=False)
class Table:
    """A committed current table: dense harmonics 1..K (complex A per actuator)."""

    seq: int
    frequency_hz: float
    currents: np.ndarray
    ramp_s: float

    @property
    def is_zero(self) -> bool:
        return not np.any(self.currents)

    @property
    def top_harmonic(self) -> int:
        rows = np.flatnonzero(np.any(self.currents != 0, axis=1))
        return int(rows[-1] + 1) if rows.size else 0


@dataclass(eq=False)
class _Played:
    table: np.ndarray = field(default_factory=lambda: np.zeros((MAX_PLAYED_HARMONIC, 6), complex))

    def trimmed(self) -> tuple[np.ndarray, np.ndarray]:
        rows = np.flatnonzero(np.any(self.table != 0, axis=1))
        top = int(rows[-1] + 1) if rows.size else 0
        return np.arange(1, top + 1), self.table[:top]


class TablePlayer:
    """Crossfading table player of the simulated device (see the module docstring)."""

    def __init__(self, drive: ActuatorDrive, frequency_hz: float):
        self.drive = drive
        self.frequency_hz = float(frequency_hz)
        self.active: Table = Table(0, self.frequency_hz, np.zeros((1, 6), complex), 0.0)
        self.pending: Table | None = None
        self._src = _Played()
        self._dst = _Played()
        self._src_trim = self._src.trimmed()
        self._dst_trim = self._dst.trimmed()
        self._t0 = 0.0
        self._duration = 0.0
        self._switching = False
        #: Incremented whenever the output changes course: a precomputed plant response is stale.
        self.version = 0

    # ------------------------------------------------------------------ ramps
    def progress(self, now: float) -> float:
        """Ramp progress s in [0, 1] (1 when no ramp is running)."""
        if self._duration <= 0:
            return 1.0
        return float(ramp_shape((now - self._t0) / self._duration))

    def ramping(self, now: float) -> bool:
        return self._duration > 0 and now < self._t0 + self._duration

    def silent(self, now: float) -> bool:
        """True when the output is zero and stays zero (no ramp, zero target)."""
        return not self.ramping(now) and not np.any(self._dst.table)

    def ramp_to(self, table: Table | None, ramp_s: float, now: float) -> None:
        """Start a crossfade from the current output to ``table`` (None: zero) over ``ramp_s``."""
        s = self.progress(now)
        self._src = _Played((1 - s) * self._src.table + s * self._dst.table)
        self._dst = _Played(
            np.zeros((MAX_PLAYED_HARMONIC, 6), complex)
            if table is None or table.is_zero
            else self.drive.played(table.currents)
        )
        self._src_trim, self._dst_trim = self._src.trimmed(), self._dst.trimmed()
        self._t0, self._duration = now, max(float(ramp_s), 0.0)
        self.version += 1
        if self._duration == 0:
            self._src = self._dst
            self._src_trim = self._dst_trim

    def stop(self, ramp_s: float, now: float) -> None:
        """Ramp to zero and forget the active and pending tables."""
        self.pending = None
        self._switching = False
        self.active = Table(0, self.frequency_hz, np.zeros((1, 6), complex), 0.0)
        self.ramp_to(None, ramp_s, now)

    def commit(self, table: Table) -> Table | None:
        """Queue a table for the next cycle boundary; returns the pending table it supersedes."""
        old, self.pending = self.pending, table
        return old

    def on_cycle_boundary(self, now: float) -> Table | None:
        """Apply the pending table where possible; returns it when it has become active."""
        table = self.pending
        if table is None:
            return None
        same = table.is_zero or abs(table.frequency_hz - self.frequency_hz) < 1e-9
        if same or self.silent(now):
            if not table.is_zero:
                self.frequency_hz = table.frequency_hz
            self.pending = None
            self._switching = False
            self.active = table
            self.ramp_to(table, table.ramp_s, now)
            return table
        if not self._switching:
            self._switching = True
            self.ramp_to(None, table.ramp_s, now)
        return None

    # ------------------------------------------------------------------ output
    def reference(self, t: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Current references (L, 6) (A) at device times ``t`` and fundamental phases ``theta``."""
        k_src, tab_src = self._src_trim
        k_dst, tab_dst = self._dst_trim
        if self._duration <= 0 or t[0] >= self._t0 + self._duration:
            return synthesize(tab_dst, k_dst, theta)
        s = ramp_shape((t - self._t0) / self._duration)[:, None]
        return (1 - s) * synthesize(tab_src, k_src, theta) + s * synthesize(tab_dst, k_dst, theta)

    def played_table(self) -> np.ndarray:
        """The played target table (MAX_PLAYED_HARMONIC, 6) (A), after the drive's imperfections."""
        return self._dst.table.copy()


__all__ = ["Table", "TablePlayer"]

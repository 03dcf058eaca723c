"""Full dynamics of many parts on the plate, advanced in chunks (what the simulated device runs).

Example
-------
>>> from ppod_ros.motion import PlateMotion
>>> from ppod_ros.parts import PointPart
>>> m = PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0])
>>> sim = PartDynamics([PointPart(0.3)], [[0.05, 0.0]])
>>> state = sim.advance(m, 0.0, 1.0)
>>> bool(state.configurations[0, 0] < 0.05)     # the line sink pulls the part towards x = 0
True

The configuration evolves (q' = velocity or twist) under the same contact model and event
handling as the asymptotic solver (stick-slip, contact loss; rigid parts with the regularised
Coulomb law). Time is absolute device time: phases are referenced to t = 0, a cycle start, and
``advance`` may be called with a different motion for each chunk (ramps, new goals). A part whose
contact is lost is flagged and kept where it was (not integrated further); the simulated device
decides what to do with it.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion
from ppod_ros.parts import PointPart, RigidPart
from ppod_ros.physics import _layout as lay
from ppod_ros.physics import _threads
from ppod_ros.physics._dynamics_kernel import AUX_READY, advance_group, advance_group_serial
from ppod_ros.physics._params import check_part, ensure_compiled, is_loaded, point_rows, rigid_rows
from ppod_ros.physics._rk import INTEGRATORS
from ppod_ros.physics.plate import motion_table, table_kmax
from ppod_ros.physics.settings import REASONS, SolverSettings


@dataclass(frozen=True, eq=False)
class DynamicsState:
    """Snapshot of all parts (arrays are copies).

    Attributes
    ----------
    time_s : float
        Absolute device time of the snapshot.
    configurations : ndarray (N, 3)
        [x, y, theta] in the plate frame (m, m, rad); theta stays constant for point parts.
    twists : ndarray (N, 3)
        [vx, vy, thetadot] (m/s, m/s, rad/s); thetadot is 0 for point parts.
    contact_lost : ndarray of bool (N,)
    status : ndarray of int (N,)
        0 while integrated, else a reason code (see :data:`~ppod_ros.physics.settings.REASONS`).
    sticking : ndarray of bool (N,)
        Whether each part is sticking to the plate now.
    stick_fraction : ndarray (N,)
        Fraction of the last ``advance`` interval each part spent sticking.
    """

    time_s: float
    configurations: np.ndarray
    twists: np.ndarray
    contact_lost: np.ndarray
    status: np.ndarray
    sticking: np.ndarray
    stick_fraction: np.ndarray

    @property
    def reason(self) -> list[str | None]:
        return [REASONS[int(c)] for c in self.status]


class _Group:
    """Parts of one kind in the arrays the kernel advances."""

    def __init__(self, kind: int, parts: list, index: np.ndarray, configs: np.ndarray, twists: np.ndarray,
                 eps: float):
        self.kind = kind
        self.index = index
        dim = 2 if kind == 0 else 3
        self.dim = dim
        n = len(parts)
        rows = [point_rows(p, configs[i:i + 1, :2], evolve=True) if kind == 0
                else rigid_rows(p, configs[i:i + 1], eps, evolve=True) for i, p in enumerate(parts)]
        self.P = np.concatenate(rows)
        self.Y = np.zeros((n, 2 * dim))
        self.Y[:, :dim] = configs[:, :dim]
        self.Y[:, dim:] = twists[:, :dim]
        self.theta = configs[:, 2].copy()
        self.AUX = np.zeros((n, lay.AX_SIZE))
        self.H = np.zeros(n)
        self.status = np.zeros(n, np.int64)
        self.stick = np.zeros(n)
        self.steps = np.zeros(n, np.int64)


class PartDynamics:
    """Parts sliding on the plate, advanced chunk by chunk.

    Parameters
    ----------
    parts : sequence of PointPart / RigidPart
    configurations : array_like (N, 2) or (N, 3)
        Initial [x, y(, theta)] per part (m, rad; theta defaults to 0).
    twists : array_like (N, 2) or (N, 3), optional
        Initial [vx, vy(, thetadot)] (default: at rest in the plate frame).
    time_s : float
        Absolute device time of the initial state.
    settings : SolverSettings, optional
        Integrator, tolerances (relative to each part's local plate-velocity scale), eps of the
        rigid parts' regularised Coulomb law, threads.
    """

    def __init__(self, parts: Sequence[PointPart | RigidPart], configurations: Any, twists: Any = None, *,
                 time_s: float = 0.0, settings: SolverSettings | None = None):
        parts = list(parts)
        for i, p in enumerate(parts):
            try:
                check_part(p)
            except ConfigError as exc:
                raise ConfigError(f"parts[{i}]: {exc}") from exc
        n = len(parts)
        cfg = _as_rows(configurations, n, "configurations", "[x, y(, theta)] (m, m, rad)")
        tw = np.zeros((n, 3)) if twists is None else \
            _as_rows(twists, n, "twists", "[vx, vy(, thetadot)] (m/s, rad/s)")
        self.settings = settings if settings is not None else SolverSettings()
        if not isinstance(self.settings, SolverSettings):
            raise ConfigError(f"settings: expected SolverSettings, got {type(self.settings).__name__}")
        self._time = _finite(time_s, "time_s")
        self.parts = parts
        # The kernels release the GIL (the simulated device's other threads run meanwhile): state and
        # set_parts take the same (reentrant) lock as advance, so no reader sees a half-advanced state.
        self._lock = threading.RLock()
        kinds = np.array([0 if isinstance(p, PointPart) else 1 for p in parts], int)
        # The serial kernels of the kinds present (the parallel ones load when first needed).
        self.setup_seconds = ensure_compiled(*sorted({("dyn", int(k), False) for k in kinds})) if kinds.size else 0.0
        self._groups = []
        for kind in (0, 1):
            idx = np.flatnonzero(kinds == kind)
            if idx.size:
                self._groups.append(_Group(kind, [parts[i] for i in idx], idx, cfg[idx], tw[idx],
                                           self.settings.friction_eps_mps))
        self._last_fraction = np.zeros(n)

    # ------------------------------------------------------------------ state
    @property
    def time_s(self) -> float:
        return self._time

    @property
    def steps(self) -> int:
        """Integration steps attempted so far, all parts together."""
        return int(sum(int(g.steps.sum()) for g in self._groups))

    @property
    def state(self) -> DynamicsState:
        with self._lock:
            return self._state()

    def _state(self) -> DynamicsState:
        n = len(self.parts)
        cfg = np.zeros((n, 3))
        tw = np.zeros((n, 3))
        status = np.zeros(n, np.int64)
        sticking = np.zeros(n, bool)
        for g in self._groups:
            d = g.dim
            cfg[g.index, :d] = g.Y[:, :d]
            tw[g.index, :d] = g.Y[:, d:]
            if g.kind == 0:
                cfg[g.index, 2] = g.theta
            status[g.index] = g.status
            sticking[g.index] = g.AUX[:, lay.AX_MODE] == lay.STICK
        lost = status == lay.CONTACT_LOST
        sticking &= status == 0
        return DynamicsState(self._time, cfg, tw, lost, status, sticking, self._last_fraction.copy())

    def set_part(self, index: int, configuration: Any, twist: Any = None) -> None:
        """Place part ``index`` at a configuration (and twist, default rest); clears its flags."""
        self.set_parts([index], [configuration], None if twist is None else [twist])

    def set_parts(self, indices: Any, configurations: Any, twists: Any = None) -> None:
        """:meth:`set_part` for several parts at once: ``configurations`` (M, 2 or 3), ``twists``
        (M, 2 or 3) or None (rest)."""
        with self._lock:
            self._set_parts(indices, configurations, twists)

    def _set_parts(self, indices: Any, configurations: Any, twists: Any) -> None:
        idx = np.asarray(indices, dtype=np.int64).reshape(-1)
        if idx.size == 0:
            return
        if idx.min() < 0 or idx.max() >= len(self.parts):
            raise ConfigError(f"index: must be in 0..{len(self.parts) - 1}, got {idx.tolist()}")
        cfg = _as_rows(configurations, idx.size, "configuration", "[x, y(, theta)]")
        tw = np.zeros((idx.size, 3)) if twists is None else \
            _as_rows(twists, idx.size, "twist", "[vx, vy(, thetadot)]")
        for g in self._groups:
            rows = np.searchsorted(g.index, idx)
            hit = (rows < g.index.size) & (g.index[np.minimum(rows, g.index.size - 1)] == idx)
            if not hit.any():
                continue
            j, c, w = rows[hit], cfg[hit], tw[hit]
            g.Y[j, :g.dim] = c[:, :g.dim]
            g.Y[j, g.dim:] = w[:, :g.dim]
            if g.kind == 0:
                g.theta[j] = c[:, 2]
            g.AUX[j] = 0.0
            g.H[j] = 0.0
            g.status[j] = lay.OK

    # ------------------------------------------------------------------ time stepping
    def advance(self, motion: PlateMotion, t_start_s: float, duration_s: float) -> DynamicsState:
        """Advance all parts from ``t_start_s`` (must equal the current time) by ``duration_s``
        under ``motion`` (phases referenced to absolute time t = 0). Returns the new state."""
        if not isinstance(motion, PlateMotion):
            raise ConfigError(f"motion: expected a PlateMotion, got {type(motion).__name__}")
        t_start = _finite(t_start_s, "t_start_s")
        duration = _finite(duration_s, "duration_s")
        if duration < 0:
            raise ConfigError(f"duration_s: must be >= 0 s, got {duration}")
        if abs(t_start - self._time) > 1e-9 * max(1.0, abs(self._time)):
            raise ConfigError(f"t_start_s: the parts' state is at t = {self._time!r} s, got {t_start!r} s "
                              f"(advance chunks must be contiguous)")
        with self._lock:
            T = motion.period_s
            base = math.floor(t_start / T) * T  # the motion is T-periodic in absolute time
            t0 = t_start - base
            t1 = t0 + duration
            mc = motion_table(motion, prune=self.settings.prune_harmonics)
            kmax = table_kmax(mc, motion.omega)
            tab = INTEGRATORS[self.settings.integrator]
            for g in self._groups:
                S = self.settings.vector("point" if g.kind == 0 else "rigid")
                g.AUX[:, AUX_READY] = 0.0  # re-derive modes: the motion may have changed
                g.stick[:] = 0.0
                if duration > 0:
                    # Serial unless the work is large enough to pay a parallel call's wake-up.
                    cost_kind = f"dyn{g.kind}"
                    units = int(np.count_nonzero(g.status == lay.OK)) * max(1.0, duration / T)
                    # A parallel kernel not loaded yet costs its loading too (a mid-run stall otherwise).
                    nthreads = _threads.plan(cost_kind, units, self.settings.threads,
                                             parallel_ready=is_loaded(("dyn", g.kind, True)))
                    kernel = advance_group if nthreads > 1 else advance_group_serial
                    self.setup_seconds += ensure_compiled(("dyn", g.kind, nthreads > 1))
                    tk, ck = time.perf_counter(), time.thread_time()
                    with _threads.thread_count(nthreads):
                        kernel(g.kind, mc, g.P, g.Y, g.AUX, g.H, t0, t1, T, kmax, tab.A, tab.B, tab.C, tab.E,
                               tab.E3, S, g.status, g.stick, g.steps)
                    _threads.learn(cost_kind, units, time.perf_counter() - tk, nthreads, time.thread_time() - ck)
                self._last_fraction[g.index] = g.stick / duration if duration > 0 else 0.0
            self._time = t_start + duration
        return self.state


def _finite(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(value):
        raise ConfigError(f"{name}: must be a finite number of seconds, got {value!r}")
    return float(value)


def _as_rows(value: Any, n: int, name: str, what: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{name}: expected rows of {what}: {exc}") from exc
    if arr.ndim != 2 or arr.shape[0] != n or arr.shape[1] not in (2, 3):
        raise ConfigError(f"{name}: expected shape ({n}, 2) or ({n}, 3), rows of {what}, "
                          f"got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"{name}: all values must be finite")
    if arr.shape[1] == 2:
        arr = np.concatenate([arr, np.zeros((n, 1))], axis=1)
    return arr


__all__ = ["DynamicsState", "PartDynamics"]

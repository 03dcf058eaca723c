"""``solve_field``: asymptotic velocity (point parts) or twist (rigid parts) at many configurations.

Example
-------
>>> from ppod_ros.motion import PlateMotion
>>> from ppod_ros.parts import PointPart
>>> m = PlateMotion.single(30, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0], name="LineSinkX")
>>> r = solve_field(m, PointPart(0.3), [[0.02, 0.0], [0.05, 0.0]])
>>> r.velocity[:, 0].round(6).tolist()
[-0.007288, -0.015315]
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion
from ppod_ros.parts import PointPart, RigidPart
from ppod_ros.physics import _layout as lay
from ppod_ros.physics._params import check_configs, check_part, ensure_compiled, point_rows, rigid_rows
from ppod_ros.physics._rk import INTEGRATORS
from ppod_ros.physics._solve import solve_batch
from ppod_ros.physics.plate import motion_table, table_kmax
from ppod_ros.physics.settings import REASONS, SolverSettings


@dataclass(frozen=True, eq=False)
class FieldResult:
    """The asymptotic field at N configurations (arrays are read-only).

    Attributes
    ----------
    configs : ndarray, shape (N, 2) or (N, 3)
        [x, y] (m) for point parts, [x, y, theta] (m, m, rad) for rigid parts.
    velocity : ndarray, shape (N, 2) or (N, 3)
        Asymptotic velocity (vx, vy) in m/s, or twist (Vx, Vy, thetadot) in m/s, m/s, rad/s;
        NaN where invalid.
    valid : ndarray of bool, shape (N,)
    reason_code : ndarray of int, shape (N,)
        0 where valid; else a key of :data:`~ppod_ros.physics.settings.REASONS`.
    periods : ndarray of int, shape (N,)
        Periods integrated (0: not integrated, e.g. contact lost, or taken from the cache).
    stick_fraction : ndarray, shape (N,)
        Fraction of the limit cycle spent sticking (NaN where invalid).
    cycle_start : ndarray, shape (N, 2) or (N, 3)
        Velocity or twist at the cycle start t = 0 on the limit cycle (a warm start for later calls).
    seconds : float
        Solver wall time of this call, without one-time compilation.
    setup_seconds : float
        Compilation / cache loading paid by this call (0 once the process is warm).
    cache_hits : int
        Configurations answered from the result cache.
    """

    configs: np.ndarray
    velocity: np.ndarray
    valid: np.ndarray
    reason_code: np.ndarray
    periods: np.ndarray
    stick_fraction: np.ndarray
    cycle_start: np.ndarray
    seconds: float
    setup_seconds: float
    part_kind: str
    settings: SolverSettings
    motion_name: str = ""
    cache_hits: int = 0

    def __post_init__(self) -> None:
        for name in ("configs", "velocity", "valid", "reason_code", "periods", "stick_fraction",
                     "cycle_start"):
            getattr(self, name).setflags(write=False)

    @property
    def reason(self) -> np.ndarray:
        """Reason text per configuration (None where valid), object array (N,)."""
        return np.array([REASONS[int(c)] for c in self.reason_code], dtype=object)

    def __len__(self) -> int:
        return int(self.configs.shape[0])

    def to_dict(self) -> dict[str, Any]:
        """The FORMATS.md JSON layout, plus ``setup_seconds``, ``periods``, ``stick_fraction`` and
        ``settings``."""
        vel = [None if not ok else [float(x) for x in row] for ok, row in zip(self.valid, self.velocity)]
        return {
            "configs": self.configs.tolist(),
            "velocity": vel,
            "valid": [bool(v) for v in self.valid],
            "reason": [REASONS[int(c)] for c in self.reason_code],
            "seconds": self.seconds,
            "setup_seconds": self.setup_seconds,
            "periods": [int(p) for p in self.periods],
            "stick_fraction": [None if not math.isfinite(s) else float(s) for s in self.stick_fraction],
            "part": self.part_kind,
            "motion": self.motion_name,
            "settings": self.settings.to_dict(),
        }

    def to_json(self, indent: int | None = None) -> str:
        return json.dumps(self.to_dict(), indent=indent)


class FieldCache:
    """Results keyed by (motion.key, part.key, settings, configuration), bounded in entries.

    Whole (motion, part, settings) groups are evicted least recently used first.
    """

    def __init__(self, max_entries: int = 1_000_000):
        self.max_entries = int(max_entries)
        self._groups: OrderedDict[tuple, dict[bytes, tuple]] = OrderedDict()
        self._count = 0
        self._lock = threading.Lock()
        self.hits = 0
        self.misses = 0

    def clear(self) -> None:
        with self._lock:
            self._groups.clear()
            self._count = 0
            self.hits = 0
            self.misses = 0

    def __len__(self) -> int:
        return self._count

    def lookup(self, prefix: tuple, configs: np.ndarray) -> tuple[np.ndarray, list[tuple | None]]:
        """(mask of misses (N,), entries or None per row)."""
        with self._lock:
            group = self._groups.get(prefix)
            if group is None:
                self.misses += len(configs)
                return np.ones(len(configs), bool), [None] * len(configs)
            self._groups.move_to_end(prefix)
            found = [group.get(row.tobytes()) for row in configs]
        miss = np.array([f is None for f in found], bool)
        with self._lock:
            self.hits += int((~miss).sum())
            self.misses += int(miss.sum())
        return miss, found

    def store(self, prefix: tuple, configs: np.ndarray, entries: list[tuple]) -> None:
        with self._lock:
            group = self._groups.setdefault(prefix, {})
            self._groups.move_to_end(prefix)
            before = len(group)
            for row, entry in zip(configs, entries):
                group[row.tobytes()] = entry
            self._count += len(group) - before
            while self._count > self.max_entries and len(self._groups) > 1:
                _, old = self._groups.popitem(last=False)
                self._count -= len(old)


#: The process-wide result cache used when ``settings.cache`` is on.
FIELD_CACHE = FieldCache()


def solve_field(motion: PlateMotion, part: PointPart | RigidPart, configs: Any,
                settings: SolverSettings | None = None, *, initial: Any = None,
                progress: Callable[[int, int], None] | None = None,
                cache: FieldCache | None = None) -> FieldResult:
    """Asymptotic velocity (point part) or twist (rigid part) at each configuration.

    Parameters
    ----------
    motion : PlateMotion
    part : PointPart or RigidPart
    configs : array_like, shape (N, 2) or (N, 3)
        [x, y] in m (point) or [x, y, theta] in m, m, rad (rigid), plate frame.
    settings : SolverSettings, optional
    initial : array_like, shape (N, 2) or (N, 3), optional
        Velocity / twist at t = 0 to start each configuration from (default: the neighbour's limit
        cycle, or rest). The result does not depend on it beyond the tolerances.
    progress : callable(done, total), optional
        Called as chunks of configurations finish (the work is then split into ~20 calls).
    cache : FieldCache, optional
        Cache to use instead of the process-wide :data:`FIELD_CACHE`.

    Returns
    -------
    FieldResult
    """
    if not isinstance(motion, PlateMotion):
        raise ConfigError(f"motion: expected a PlateMotion, got {type(motion).__name__}")
    check_part(part)
    if settings is None:
        settings = SolverSettings()
    elif not isinstance(settings, SolverSettings):
        raise ConfigError(f"settings: expected SolverSettings, got {type(settings).__name__}")
    cfg = check_configs(configs, part)
    dim = cfg.shape[1]
    x0 = None
    if initial is not None:
        x0 = check_configs(initial, part, "initial")
        if x0.shape != cfg.shape:
            raise ConfigError(f"initial: expected shape {cfg.shape} like configs, got {x0.shape}")
    setup = ensure_compiled()
    t_start = time.perf_counter()
    N = cfg.shape[0]
    velocity = np.full((N, dim), np.nan)
    start = np.full((N, dim), np.nan)
    code = np.zeros(N, np.int64)
    periods = np.zeros(N, np.int64)
    stick = np.full(N, np.nan)
    store = cache if cache is not None else FIELD_CACHE
    prefix = (motion.key, part.key, settings.cache_key())
    if settings.cache:
        miss, found = store.lookup(prefix, cfg)
        for i, entry in enumerate(found):
            if entry is not None:
                velocity[i], start[i], code[i], stick[i] = entry
    else:
        miss = np.ones(N, bool)
    idx = np.flatnonzero(miss)
    if idx.size:
        _run(motion, part, cfg[idx], None if x0 is None else x0[idx], settings, progress,
             velocity, start, code, periods, stick, idx)
        if settings.cache:
            entries = [(velocity[i].copy(), start[i].copy(), int(code[i]), float(stick[i])) for i in idx]
            store.store(prefix, cfg[idx], entries)
    seconds = time.perf_counter() - t_start
    return FieldResult(cfg, velocity, code == lay.OK, code, periods, stick, start, seconds, setup, part.kind,
                       settings, motion.name, int(N - idx.size))


def _run(motion, part, cfg, x0, settings, progress, velocity, start, code, periods, stick, idx) -> None:
    mc = motion_table(motion, prune=settings.prune_harmonics)
    kmax = table_kmax(mc, motion.omega)
    tab = INTEGRATORS[settings.integrator]
    kind = 0 if isinstance(part, PointPart) else 1
    S = settings.vector(part.kind)
    P = point_rows(part, cfg) if kind == 0 else rigid_rows(part, cfg, settings.friction_eps_mps)
    n, dim = cfg.shape
    X0 = np.zeros((n, dim)) if x0 is None else x0
    has = np.zeros(n, np.bool_) if x0 is None else np.ones(n, np.bool_)
    out_v = np.full((n, dim), np.nan)
    out_x = np.full((n, dim), np.nan)
    out_s = np.zeros(n, np.int64)
    out_p = np.zeros(n, np.int64)
    out_f = np.full(n, np.nan)
    old_threads = numba.get_num_threads()
    if settings.threads is not None:
        numba.set_num_threads(min(settings.threads, numba.config.NUMBA_NUM_THREADS))
    try:
        # Progress: split into ~20 slices aligned to the parallel chunks (same results as one call).
        step = n if progress is None else max(settings.chunk, -(-n // 20 // settings.chunk) * settings.chunk)
        for a in range(0, n, step):
            b = min(n, a + step)
            solve_batch(kind, mc, P[a:b], X0[a:b], has[a:b], motion.period_s, kmax, tab.A, tab.B, tab.C,
                        tab.E, tab.E3, S, out_v[a:b], out_x[a:b], out_s[a:b], out_p[a:b], out_f[a:b])
            if progress is not None:
                progress(b, n)
    finally:
        numba.set_num_threads(old_threads)
    velocity[idx] = out_v
    start[idx] = out_x
    code[idx] = out_s
    periods[idx] = out_p
    stick[idx] = out_f


def grid_configs(x: np.ndarray, y: np.ndarray, theta: np.ndarray | None = None) -> np.ndarray:
    """Configurations on a grid in the FORMATS.md order: x fastest, then y, then theta."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if theta is None:
        Y, X = np.meshgrid(y, x, indexing="ij")
        return np.stack([X.ravel(), Y.ravel()], axis=1)
    T, Y, X = np.meshgrid(np.asarray(theta, float), y, x, indexing="ij")
    return np.stack([X.ravel(), Y.ravel(), T.ravel()], axis=1)


__all__ = ["FIELD_CACHE", "FieldCache", "FieldResult", "grid_configs", "solve_field"]

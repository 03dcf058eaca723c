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
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion
from ppod_ros.parts import PointPart, RigidPart
from ppod_ros.physics import _aot, _threads
from ppod_ros.physics import _layout as lay
from ppod_ros.physics._params import check_configs, check_part, ensure_compiled, is_loaded, point_rows, rigid_rows
from ppod_ros.physics._rk import INTEGRATORS
from ppod_ros.physics.plate import TABLE_COLS, motion_table, table_kmax
from ppod_ros.physics.settings import CHUNK_LARGE, REASONS, SolverSettings


@dataclass(frozen=True, eq=False)
class _SolvedArrays:
    """The fields :class:`FieldResult` and :class:`FieldsResult` share (arrays made read-only)."""

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

    def __post_init__(self) -> None:
        for name in ("configs", "velocity", "valid", "reason_code", "periods", "stick_fraction",
                     "cycle_start"):
            getattr(self, name).setflags(write=False)


@dataclass(frozen=True, eq=False)
class FieldResult(_SolvedArrays):
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

    motion_name: str = ""
    cache_hits: int = 0

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


class WarmStarts:
    """Limit-cycle starts and contraction rates of configurations solved before, keyed by (part,
    settings, configuration) but not by motion: designs, Jacobians and replanning evaluate the
    same configurations under slightly different motions many times, and the previous cycle start
    with its contraction rate lets a configuration converge in about one period. With them, the
    secant differences of the configuration's own period map (:meth:`secants`): under a motion that
    changed a little its first step is then nearly Newton's. Bounded in entries (whole (part,
    settings) groups are dropped least recently used first)."""

    def __init__(self, max_entries: int = 200_000):
        self.max_entries = int(max_entries)
        self._groups: OrderedDict[tuple, dict[bytes, tuple]] = OrderedDict()
        self._count = 0
        self._lock = threading.Lock()

    def clear(self) -> None:
        with self._lock:
            self._groups.clear()
            self._count = 0

    def __len__(self) -> int:
        return self._count

    def lookup(self, prefix: tuple, configs: np.ndarray, dim: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(starts (N, dim), rates (N,), found (N,) bool)."""
        n = configs.shape[0]
        x0 = np.zeros((n, dim))
        r0 = np.ones(n)
        has = np.zeros(n, np.bool_)
        with self._lock:
            group = self._groups.get(prefix)
            if group is None:
                return x0, r0, has
            self._groups.move_to_end(prefix)
            for i, row in enumerate(configs):
                entry = group.get(row.tobytes())
                if entry is not None:
                    x0[i], r0[i] = entry[0], entry[1]
                    has[i] = True
        return x0, r0, has

    def secants(self, prefix: tuple, configs: np.ndarray, dim: int, rows: int) -> tuple[np.ndarray, ...]:
        """(dx (N, rows, dim), dF (N, rows, dim), count (N,)): the stored secant differences of each
        configuration's own period map, newest last (count 0: none stored)."""
        n = configs.shape[0]
        sx = np.zeros((n, rows, dim))
        sf = np.zeros((n, rows, dim))
        sn = np.zeros(n, np.int64)
        with self._lock:
            group = self._groups.get(prefix)
            if group is None or rows == 0:
                return sx, sf, sn
            for i, row in enumerate(configs):
                entry = group.get(row.tobytes())
                if entry is not None and len(entry) > 2:
                    pairs = entry[2]  # (2, stored rows, dim): dx rows, then dF rows
                    k = min(rows, pairs.shape[1])
                    sx[i, :k] = pairs[0, pairs.shape[1] - k:]
                    sf[i, :k] = pairs[1, pairs.shape[1] - k:]
                    sn[i] = k
        return sx, sf, sn

    def store(self, prefix: tuple, configs: np.ndarray, starts: np.ndarray, rates: np.ndarray,
              ok: np.ndarray, secants: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> None:
        """Keep the converged (``ok``) rows' starts and rates, and their own map's secant differences
        ``secants`` = (dx, dF (N, rows, dim), count (N,)) where counted (else those stored before)."""
        if secants is None:
            one = (None, None, np.zeros((1, len(configs)), np.int64))
        else:
            one = (secants[0][None], secants[1][None], np.asarray(secants[2])[None])
        self.store_all(prefix, configs, starts[None], np.asarray(rates)[None], np.asarray(ok, bool)[None], one)

    def store_all(self, prefix: tuple, configs: np.ndarray, starts: np.ndarray, rates: np.ndarray,
                  ok: np.ndarray, secants: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
        """:meth:`store` of M motions' results at the same configurations (N, dim), in motion order
        (``starts`` (M, N, dim), ``rates`` and ``ok`` (M, N), ``secants`` (dx, dF (M, N, rows, dim),
        count (M, N))), as one entry per configuration: the one the last of those calls leaves, the
        last converged motion's start and rate with the secant differences of the last converged
        motion that counted some (else those stored before)."""
        with self._lock:
            group = self._groups.setdefault(prefix, {})
            self._groups.move_to_end(prefix)
            before = len(group)
            counted = ok & (secants[2] > 0)
            for i, row in enumerate(configs):
                good = np.flatnonzero(ok[:, i])
                if not good.size:
                    continue
                key = row.tobytes()
                m = good[-1]
                entry = (starts[m, i].copy(), float(rates[m, i]))
                with_secants = np.flatnonzero(counted[:, i])
                if with_secants.size:  # one small array per entry: (2, k, dim)
                    j = with_secants[-1]
                    k = int(secants[2][j, i])
                    entry += (np.stack([secants[0][j, i, :k], secants[1][j, i, :k]]),)
                elif key in group and len(group[key]) > 2:
                    entry += group[key][2:]
                group[key] = entry
            self._count += len(group) - before
            while self._count > self.max_entries and len(self._groups) > 1:
                _, old = self._groups.popitem(last=False)
                self._count -= len(old)


#: The process-wide warm starts used by :func:`solve_fields` (and by :func:`solve_field` on request).
WARM_STARTS = WarmStarts()


@dataclass(frozen=True, eq=False)
class FieldsResult(_SolvedArrays):
    """Fields of M motions at N configurations each (:func:`solve_fields`; arrays read-only).

    Attributes are those of :class:`FieldResult` with a leading motion axis: ``configs``,
    ``velocity`` and ``cycle_start`` (M, N, dim); ``valid``, ``reason_code``, ``periods`` and
    ``stick_fraction`` (M, N); ``reason`` (M, N) object array; ``motion_names`` (M,). ``field(m)``
    gives motion m's :class:`FieldResult`.
    """

    motion_names: tuple[str, ...] = ()
    cache_hits: int = 0
    threads: int = 1

    @property
    def reason(self) -> np.ndarray:
        """Reason text per motion and configuration (None where valid), object array (M, N)."""
        out = np.empty(self.reason_code.shape, dtype=object)
        for idx, c in np.ndenumerate(self.reason_code):
            out[idx] = REASONS[int(c)]
        return out

    def __len__(self) -> int:
        return int(self.velocity.shape[0])

    def field(self, m: int) -> FieldResult:
        """Motion ``m``'s field as a :class:`FieldResult` (``seconds``: this call's share)."""
        share = self.seconds / max(1, len(self))
        return FieldResult(self.configs[m].copy(), self.velocity[m].copy(), self.valid[m].copy(),
                           self.reason_code[m].copy(), self.periods[m].copy(), self.stick_fraction[m].copy(),
                           self.cycle_start[m].copy(), share, self.setup_seconds if m == 0 else 0.0,
                           self.part_kind, self.settings, self.motion_names[m] if self.motion_names else "")


def solve_field(motion: PlateMotion, part: PointPart | RigidPart, configs: Any,
                settings: SolverSettings | None = None, *, initial: Any = None,
                progress: Callable[[int, int], None] | None = None,
                cache: FieldCache | None = None, warm: WarmStarts | bool | None = None) -> FieldResult:
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
    warm : WarmStarts or bool, optional
        Start from (and remember) the limit cycles of previous calls at the same configurations:
        ``True`` uses the process-wide :data:`WARM_STARTS`. Default: off (results do not depend on
        earlier calls).

    Returns
    -------
    FieldResult
    """
    if not isinstance(motion, PlateMotion):
        raise ConfigError(f"motion: expected a PlateMotion, got {type(motion).__name__}")
    r = solve_fields([motion], part, configs, settings, initial=initial, progress=progress, cache=cache,
                     warm=False if warm is None else warm)
    return FieldResult(
        r.configs[0].copy(), r.velocity[0].copy(), r.valid[0].copy(), r.reason_code[0].copy(),
        r.periods[0].copy(), r.stick_fraction[0].copy(), r.cycle_start[0].copy(), r.seconds, r.setup_seconds,
        part.kind, r.settings, motion.name, r.cache_hits)


def solve_fields(motions: Sequence[PlateMotion], part: PointPart | RigidPart, configs: Any,
                 settings: SolverSettings | None = None, *, initial: Any = None,
                 progress: Callable[[int, int], None] | None = None, cache: FieldCache | None = None,
                 warm: WarmStarts | bool = True) -> FieldsResult:
    """Fields of many motions at many configurations in one compiled call.

    Parameters
    ----------
    motions : sequence of PlateMotion (M of them; any periods and harmonics)
    part : PointPart or RigidPart
    configs : array_like, shape (N, dim) shared by all motions, or (M, N, dim) one set per motion
        [x, y] in m (point, dim 2) or [x, y, theta] in m, m, rad (rigid, dim 3).
    settings : SolverSettings, optional
    initial : array_like, shape (N, dim) or (M, N, dim), optional
        Velocity / twist at t = 0 to start from (overrides the warm starts).
    progress : callable(done, total), optional
        Called as slices of configurations finish (``total`` = M * N).
    cache : FieldCache, optional
        Cache to use instead of :data:`FIELD_CACHE` (when ``settings.cache``).
    warm : WarmStarts or bool
        Warm starts from previous calls at the same configurations (default: the process-wide
        :data:`WARM_STARTS`; ``False``: none). Each configuration of this call also starts from its
        neighbour's limit cycle (``settings.warm_start``).

    Small calls run serially on the calling thread (no thread wake-up stall on a busy machine),
    large ones in parallel (``settings.threads``; see docs/solver.md). Results do not depend on
    that choice.

    Returns
    -------
    FieldsResult
    """
    motions = list(motions) if not isinstance(motions, PlateMotion) else [motions]
    if not motions:
        raise ConfigError("motions: expected at least one PlateMotion, got none")
    for i, m in enumerate(motions):
        if not isinstance(m, PlateMotion):
            raise ConfigError(f"motions[{i}]: expected a PlateMotion, got {type(m).__name__}")
    check_part(part)
    if settings is None:
        settings = SolverSettings()
    elif not isinstance(settings, SolverSettings):
        raise ConfigError(f"settings: expected SolverSettings, got {type(settings).__name__}")
    M = len(motions)
    cfg = _configs_per_motion(configs, part, M, "configs")
    shared = cfg[0] if np.ndim(configs) == 2 else None   # one set of configurations for every motion
    x_init = None if initial is None else _configs_per_motion(initial, part, M, "initial")
    if x_init is not None and x_init.shape != cfg.shape:
        raise ConfigError(f"initial: expected shape {cfg.shape[1:]} or {cfg.shape} like configs, "
                          f"got {np.shape(initial)}")
    if warm is True:
        store_w: WarmStarts | None = WARM_STARTS
    elif warm is False or warm is None:
        store_w = None
    elif isinstance(warm, WarmStarts):
        store_w = warm
    else:
        raise ConfigError(f"warm: expected a WarmStarts or a bool, got {type(warm).__name__}")
    setup = 0.0
    t_start = time.perf_counter()
    N, dim = cfg.shape[1], cfg.shape[2]
    velocity = np.full((M, N, dim), np.nan)
    start = np.full((M, N, dim), np.nan)
    code = np.zeros((M, N), np.int64)
    periods = np.zeros((M, N), np.int64)
    stick = np.full((M, N), np.nan)
    rates = np.ones((M, N))
    miss = np.ones((M, N), bool)
    store = cache if cache is not None else FIELD_CACHE
    skey = settings.cache_key() if settings.cache else None
    if settings.cache:
        for m, motion in enumerate(motions):
            miss[m], found = store.lookup((motion.key, part.key, skey), cfg[m])
            for i, entry in enumerate(found):
                if entry is not None:
                    velocity[m, i], start[m, i], code[m, i], stick[m, i] = entry
    X0 = np.zeros((M, N, dim))
    R0 = np.ones((M, N))
    has = np.zeros((M, N), np.bool_)
    wkey = (part.key, settings.warm_key()) if store_w is not None else None   # the work caps do not
    # change a converged cycle
    # Each row's own secant differences travel only with warm starts from earlier calls.
    srows = settings.anderson_depth if (store_w is not None and settings.fixed_point == "anderson"
                                        and x_init is None) else 0
    SX0 = np.zeros((M, N, srows, dim))
    SF0 = np.zeros((M, N, srows, dim))
    SN0 = np.zeros((M, N), np.int64)
    if store_w is not None and shared is not None:   # the same rows for every motion: looked up once
        X0[:], R0[:], has[:] = store_w.lookup(wkey, shared, dim)
        if srows:
            SX0[:], SF0[:], SN0[:] = store_w.secants(wkey, shared, dim, srows)
    elif store_w is not None:
        for m in range(M):
            X0[m], R0[m], has[m] = store_w.lookup(wkey, cfg[m], dim)
            if srows:
                SX0[m], SF0[m], SN0[m] = store_w.secants(wkey, cfg[m], dim, srows)
    if x_init is not None:
        X0[:] = x_init
        R0[:] = 1.0
        has[:] = True
    todo = int(miss.sum())
    nthreads = 1
    if todo:
        if miss.all():
            sub = cfg
            sel = None
        else:  # only the misses: per motion, padded to the longest with repeats of a miss
            sel = _miss_rows(miss)
            sub = np.take_along_axis(cfg, sel[:, :, None], axis=1)
            X0 = np.take_along_axis(X0, sel[:, :, None], axis=1)
            R0 = np.take_along_axis(R0, sel, axis=1)
            has = np.take_along_axis(has, sel, axis=1)
            SX0 = np.ascontiguousarray(np.take_along_axis(SX0, sel[:, :, None, None], axis=1))
            SF0 = np.ascontiguousarray(np.take_along_axis(SF0, sel[:, :, None, None], axis=1))
            SN0 = np.ascontiguousarray(np.take_along_axis(SN0, sel, axis=1))
        nthreads, setup, out = _run(motions, part, sub, X0, R0, has, (SX0, SF0, SN0), settings, progress)
        ov, ox, os_, op, of, orate, osx, osf, osn = out
        if sel is None:
            velocity, start, code, periods, stick, rates = ov, ox, os_, op, of, orate
            sec_x, sec_f, sec_n = osx, osf, osn
        else:
            shape = (M, N) + SX0.shape[2:]
            sec_x, sec_f, sec_n = np.zeros(shape), np.zeros(shape), np.zeros((M, N), np.int64)
            for m in range(M):
                rows = np.flatnonzero(miss[m])
                k = rows.size
                velocity[m, rows], start[m, rows], code[m, rows] = ov[m, :k], ox[m, :k], os_[m, :k]
                periods[m, rows], stick[m, rows], rates[m, rows] = op[m, :k], of[m, :k], orate[m, :k]
                sec_x[m, rows], sec_f[m, rows], sec_n[m, rows] = osx[m, :k], osf[m, :k], osn[m, :k]
        if settings.cache:
            for m, motion in enumerate(motions):
                rows = np.flatnonzero(miss[m])
                if rows.size:
                    entries = [(velocity[m, i].copy(), start[m, i].copy(), int(code[m, i]), float(stick[m, i]))
                               for i in rows]
                    store.store((motion.key, part.key, skey), cfg[m, rows], entries)
        if store_w is not None and shared is not None and sel is None:
            store_w.store_all(wkey, shared, start, rates, code == lay.OK, (sec_x, sec_f, sec_n))
        elif store_w is not None:
            for m in range(M):
                rows = np.flatnonzero(miss[m])
                if rows.size:
                    store_w.store(wkey, cfg[m, rows], start[m, rows], rates[m, rows], code[m, rows] == lay.OK,
                                  (sec_x[m, rows], sec_f[m, rows], sec_n[m, rows]))
    seconds = time.perf_counter() - t_start - setup
    return FieldsResult(cfg, velocity, code == lay.OK, code, periods, stick, start, seconds, setup, part.kind,
                        settings, tuple(m.name for m in motions), int(M * N - todo), nthreads)


def _configs_per_motion(value: Any, part: PointPart | RigidPart, M: int, name: str) -> np.ndarray:
    """(M, N, dim) float64 from (N, dim) shared or (M, N, dim) per motion."""
    dim = 2 if isinstance(part, PointPart) else 3
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{name}: expected numbers, rows of {dim} values: {exc}") from exc
    if arr.ndim == 3:
        if arr.shape[0] != M:
            raise ConfigError(f"{name}: expected shape (N, {dim}) or ({M}, N, {dim}) for {M} motions, "
                              f"got {arr.shape}")
        rows = [check_configs(a, part, name) for a in arr]
        return np.ascontiguousarray(np.stack(rows))
    one = check_configs(arr, part, name)
    return np.ascontiguousarray(np.broadcast_to(one, (M,) + one.shape))


def _miss_rows(miss: np.ndarray) -> np.ndarray:
    """(M, K) row indices of each motion's misses, padded with its last miss (or row 0)."""
    K = int(miss.sum(axis=1).max())
    sel = np.zeros((miss.shape[0], K), np.int64)
    for m in range(miss.shape[0]):
        rows = np.flatnonzero(miss[m])
        if rows.size:
            sel[m, :rows.size] = rows
            sel[m, rows.size:] = rows[-1]
    return sel


def _run(motions, part, cfg, X0, R0, has, secants, settings, progress):
    """Solve cfg (M, N, dim) for every motion; returns (threads used, set-up seconds, outputs).

    ``secants``: (dx, dF (M, N, rows, dim), count (M, N)), each row's own secant differences from
    earlier calls (rows may be 0); they come back, as they end, after the six field outputs."""
    SX0, SF0, SN0 = secants
    M, n, dim = cfg.shape
    tables = [_table(m, settings.prune_harmonics) for m in motions]
    rows = np.array([t.shape[0] for t, _ in tables], np.int64)
    MC = np.zeros((M, max(1, int(rows.max())), TABLE_COLS))
    for m, (t, _) in enumerate(tables):
        MC[m, :t.shape[0]] = t
    kmaxs = np.array([kmax for _, kmax in tables], np.int64)
    Ts = np.array([mo.period_s for mo in motions], float)
    tab = INTEGRATORS[settings.integrator]
    kind = 0 if isinstance(part, PointPart) else 1
    S = settings.vector(part.kind)
    chunk = settings.chunk_for(n)
    S[lay.S_CHUNK] = chunk
    # Long chunks (large grids) extrapolate further and take the neighbour's rate as a prior; small
    # calls (designs' finite differences, the planner) keep the short, prior-free warm starts.
    S[lay.S_LONG] = float(chunk >= CHUNK_LARGE)
    flat = cfg.reshape(M * n, dim)
    P = point_rows(part, flat) if kind == 0 else rigid_rows(part, flat, settings.friction_eps_mps)
    P = np.ascontiguousarray(P.reshape(M, n, P.shape[1]))
    out_v = np.full((M, n, dim), np.nan)
    out_x = np.full((M, n, dim), np.nan)
    out_s = np.zeros((M, n), np.int64)
    out_p = np.zeros((M, n), np.int64)
    out_f = np.full((M, n), np.nan)
    out_r = np.ones((M, n))
    out_sx = np.zeros_like(SX0)
    out_sf = np.zeros_like(SF0)
    out_sn = np.zeros((M, n), np.int64)
    cost_kind = f"field{kind}"
    nthreads = _threads.plan(cost_kind, M * n, settings.threads, is_loaded(("field", kind, True)))
    args = (kind, MC, rows, P, X0, has, R0, SX0, SF0, SN0, Ts, kmaxs, tab.A, tab.B, tab.C, tab.E, tab.E3, S,
            out_v, out_x, out_s, out_p, out_f, out_r, out_sx, out_sf, out_sn)
    kernel, setup = _kernel_for(kind, nthreads, args)
    t0, c0 = time.perf_counter(), time.thread_time()
    with _threads.thread_count(nthreads):
        # Progress: split into ~20 slices aligned to the chunks (same results as one call).
        if progress is None:
            kernel(*args)
        else:
            # ~20 slices aligned to the chunks (same results as one call), each contiguous.
            step = max(chunk, -(-n // 20 // chunk) * chunk)
            everything = (out_v, out_x, out_s, out_p, out_f, out_r, out_sx, out_sf, out_sn)
            for a in range(0, n, step):
                b = min(n, a + step)
                outs = [np.ascontiguousarray(o[:, a:b]) for o in everything]
                c = np.ascontiguousarray
                kernel(kind, MC, rows, c(P[:, a:b]), c(X0[:, a:b]), c(has[:, a:b]), c(R0[:, a:b]), c(SX0[:, a:b]),
                       c(SF0[:, a:b]), c(SN0[:, a:b]), Ts, kmaxs, tab.A, tab.B, tab.C, tab.E, tab.E3, S,
                       *outs)
                for o, part_out in zip(everything, outs):
                    o[:, a:b] = part_out
                progress(M * b, M * n)
    _threads.learn(cost_kind, M * n, time.perf_counter() - t0, nthreads, time.thread_time() - c0)
    return nthreads, setup, (out_v, out_x, out_s, out_p, out_f, out_r, out_sx, out_sf, out_sn)


def _table(motion: PlateMotion, prune: bool) -> tuple[np.ndarray, int]:
    """``motion``'s coefficient table and its highest harmonic (remembered with the motion, which is
    immutable: the planner solves each candidate once per part model)."""
    key = ("field_table", prune)
    out = motion._memo.get(key)
    if out is None:
        t = motion_table(motion, prune=prune)
        out = motion._memo[key] = (t, table_kmax(t, motion.omega))
    return out


def _kernel_for(kind: int, nthreads: int, args: tuple) -> tuple[Callable[..., None], float]:
    """The field kernel for this call and the seconds its loading took (0 when it was ready).

    Serial calls use the ahead-of-time compiled kernel when it is built for this environment (no
    numba import, identical results: ``_aot``), else numba's serial or parallel kernel."""
    if nthreads <= 1:
        t0 = time.perf_counter()
        aot = _aot.kernel()
        if aot is not None and _aot.fits(args):
            return aot, time.perf_counter() - t0
    from ppod_ros.physics import _solve  # not imported by calls the ahead-of-time kernel serves

    setup = ensure_compiled(("field", kind, nthreads > 1))
    return (_solve.solve_motions if nthreads > 1 else _solve.solve_motions_serial), setup


def grid_configs(x: np.ndarray, y: np.ndarray, theta: np.ndarray | None = None) -> np.ndarray:
    """Configurations on a grid in the FORMATS.md order: x fastest, then y, then theta."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if theta is None:
        Y, X = np.meshgrid(y, x, indexing="ij")
        return np.stack([X.ravel(), Y.ravel()], axis=1)
    T, Y, X = np.meshgrid(np.asarray(theta, float), y, x, indexing="ij")
    return np.stack([X.ravel(), Y.ravel(), T.ravel()], axis=1)


__all__ = ["FIELD_CACHE", "WARM_STARTS", "FieldCache", "FieldResult", "FieldsResult", "WarmStarts", "grid_configs",
           "solve_field", "solve_fields"]

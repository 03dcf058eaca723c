"""Parameter rows for the compiled kernels, configuration checks, and one-time compilation.

:func:`ensure_compiled` compiles (or loads from numba's on-disk cache) the kernels a call needs
(default: all) once per process by running them on a tiny problem; the time it took is the
solver's ``setup_seconds``. Numba writes its cache next to the sources (``__pycache__``) or, when
that is read-only, to its user-wide cache directory (``NUMBA_CACHE_DIR``); either way nothing here
depends on the cache being writable.
"""

from __future__ import annotations

import hashlib
import logging
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.parts import PointPart, RigidPart
from ppod_ros.physics import _layout as lay
from ppod_ros.physics._contact import frictionless_det

_log = logging.getLogger(__name__)
#: Modules whose compiled code numba caches (their digest guards the cache, see _drop_stale_cache).
KERNEL_SOURCES = ("_layout.py", "plate.py", "_contact.py", "_rk.py", "_advance.py", "_closed_form.py",
                  "_solve.py", "_dynamics_kernel.py")
_lock = threading.Lock()
_setup_seconds: float | None = None


def check_part(part: Any) -> None:
    if not isinstance(part, (PointPart, RigidPart)):
        raise ConfigError(f"part: expected a PointPart or RigidPart, got {type(part).__name__}")


def check_configs(configs: Any, part: PointPart | RigidPart, name: str = "configs") -> np.ndarray:
    """Configurations as a float64 (N, 2) array for point parts, (N, 3) for rigid parts."""
    dim = 2 if isinstance(part, PointPart) else 3
    what = "[x, y] (m)" if dim == 2 else "[x, y, theta] (m, m, rad)"
    try:
        arr = np.array(configs, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{name}: expected numbers, rows of {what}: {exc}") from exc
    if arr.ndim == 1 and arr.shape[0] == dim:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise ConfigError(f"{name}: expected shape (N, {dim}), rows of {what} for a {part.kind} part, "
                          f"got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = int(np.argwhere(~np.isfinite(arr))[0, 0])
        raise ConfigError(f"{name}: row {bad} is not finite: {arr[bad].tolist()}")
    return np.ascontiguousarray(arr)


def point_rows(part: PointPart, configs: np.ndarray, evolve: bool = False) -> np.ndarray:
    P = np.zeros((configs.shape[0], lay.PP_SIZE))
    P[:, lay.PP_MU] = part.mu
    P[:, lay.PP_MUS] = part.mu_static
    P[:, lay.PP_X] = configs[:, 0]
    P[:, lay.PP_Y] = configs[:, 1]
    P[:, lay.PP_EVOLVE] = float(evolve)
    P[:, lay.PP_CANSTICK] = 1.0
    return P


def rigid_rows(part: RigidPart, configs: np.ndarray, eps_mps: float, evolve: bool = False) -> np.ndarray:
    P = np.zeros((configs.shape[0], lay.RP_SIZE))
    P[:, lay.RP_MASS] = part.mass
    P[:, lay.RP_I:lay.RP_I + 9] = np.asarray(part.inertia, float).reshape(9)
    P[:, lay.RP_R:lay.RP_R + 9] = np.asarray(part.contacts, float).reshape(9)
    P[:, lay.RP_MU:lay.RP_MU + 3] = part.mu
    P[:, lay.RP_MUS:lay.RP_MUS + 3] = part.mu_static
    P[:, lay.RP_EPS] = eps_mps
    P[:, lay.RP_X] = configs[:, 0]
    P[:, lay.RP_Y] = configs[:, 1]
    P[:, lay.RP_TH] = configs[:, 2]
    P[:, lay.RP_EVOLVE] = float(evolve)
    P[:, lay.RP_CANSTICK] = 1.0
    P[:, lay.RP_DET0] = frictionless_det(part.contacts, part.inertia)
    return P


#: Every kernel: (family, part kind, parallel). "field": the asymptotic solver; "dyn": full dynamics.
ALL_KERNELS = tuple((fam, kind, par) for fam in ("field", "dyn") for kind in (0, 1) for par in (False, True))
_warmed: set[tuple[str, int, bool]] = set()


def ensure_compiled(*kernels: tuple[str, int, bool]) -> float:
    """Compile or load the given kernels (default: all) once per process; returns the seconds that
    took (0 when they were ready). Loading only what a call uses keeps small CLI calls short."""
    global _setup_seconds
    want = kernels or ALL_KERNELS
    with _lock:
        todo = [k for k in want if k not in _warmed]
        if not todo:
            return 0.0
        t0 = time.perf_counter()
        _warm_up(todo)   # the first kernel call materialises them, dropping stale cache entries first
        _warmed.update(todo)
        spent = time.perf_counter() - t0
        _setup_seconds = (_setup_seconds or 0.0) + spent
        return spent


def is_loaded(kernel: tuple[str, int, bool]) -> bool:
    """Whether ``kernel`` (family, part kind, parallel) is compiled or loaded in this process."""
    return kernel in _warmed


def _drop_stale_cache() -> None:
    """Delete numba's cached machine code of this package when any kernel source changed.

    Numba validates a cached function against its own source file only, but the kernels inline
    functions and constants from the other modules here (``_layout``, ``_contact``...): after an
    edit of one module, cached code of another could silently use the old version. A digest of all
    sources, kept next to the cache, catches that. (A read-only package uses numba's user-wide
    cache directory instead; installed sources do not change, so nothing is checked there.)
    """
    here = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for name in KERNEL_SOURCES:
        digest.update(name.encode())
        digest.update((here / name).read_bytes())
    stamp = digest.hexdigest()
    cache_dir = here / "__pycache__"
    stamp_file = cache_dir / "ppod_kernels.stamp"
    try:
        if stamp_file.read_text() == stamp:
            return
    except OSError:
        pass  # no stamp yet: treat the cache as stale
    try:
        for f in list(cache_dir.glob("*.nbi")) + list(cache_dir.glob("*.nbc")):
            f.unlink()
        cache_dir.mkdir(exist_ok=True)
        stamp_file.write_text(stamp)
    except OSError as exc:
        _log.debug("numba cache in %s not managed (%s); numba uses its user-wide cache", cache_dir, exc)


def setup_seconds_total() -> float:
    """Seconds spent compiling/loading kernels in this process so far (0 if not yet)."""
    return _setup_seconds or 0.0


def _warm_up(todo) -> None:
    # Import here: the kernels' modules compile lazily on first call.
    from ppod_ros.motion import PlateMotion
    from ppod_ros.parts import published_rigid_part
    from ppod_ros.physics import _dynamics_kernel, _numba_start, _solve
    from ppod_ros.physics.plate import motion_table
    from ppod_ros.physics.settings import SolverSettings

    _numba_start.prepare()
    motion = PlateMotion.single(30.0, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 4.71238898, 0])
    mc = motion_table(motion)
    settings = SolverSettings()
    S = settings.vector()
    from ppod_ros.physics._rk import INTEGRATORS

    tab = INTEGRATORS[settings.integrator]
    for kind, part, configs in ((0, PointPart(0.3), np.array([[0.02, 0.0]])),
                                (1, published_rigid_part(), np.array([[0.0, 0.0, 0.3]]))):
        dim = configs.shape[1]
        P = point_rows(part, configs) if kind == 0 else rigid_rows(part, configs, settings.friction_eps_mps)
        n = configs.shape[0]
        R = np.ones((1, n))
        for par, kernel in ((False, _solve.solve_motions_serial), (True, _solve.solve_motions)):
            if ("field", kind, par) not in todo:
                continue
            sec = np.zeros((1, n, 2, dim))
            kernel(kind, mc[None], np.array([mc.shape[0]], np.int64), P[None].copy(), np.zeros((1, n, dim)),
                   np.zeros((1, n), np.bool_), R, sec, sec.copy(), np.zeros((1, n), np.int64),
                   np.array([motion.period_s]), np.array([1], np.int64),
                   tab.A, tab.B, tab.C, tab.E, tab.E3, S, np.zeros((1, n, dim)), np.zeros((1, n, dim)),
                   np.zeros((1, n), np.int64), np.zeros((1, n), np.int64), np.zeros((1, n)), np.ones((1, n)),
                   sec.copy(), sec.copy(), np.zeros((1, n), np.int64))
        dyn = tuple(k for par, k in ((False, _dynamics_kernel.advance_group_serial),
                                     (True, _dynamics_kernel.advance_group)) if ("dyn", kind, par) in todo)
        if dyn:
            _dynamics_kernel.warm_up(kind, mc, P, dim, tab, S, motion.period_s, dyn)

"""Solver settings: a frozen, validated dataclass; integrators and fixed-point methods by name.

Tolerances are relative to the configuration's natural velocity scale (a bound on the plate's
velocity there), plus small absolute floors, so the same settings serve a 5 Hz and a 200 Hz
motion, or tiny and huge amplitudes. Named presets (``PRESETS``) span the accuracy/time trade-off
measured by ``ppod bench solver``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.physics import _advance
from ppod_ros.physics import _layout as lay
from ppod_ros.physics._rk import INTEGRATORS

#: Fixed-point methods by name: Anderson acceleration of the one-period map, or plain iteration.
FIXED_POINT_METHODS = ("anderson", "picard")

#: Reason codes of invalid configurations and their text (FieldResult.reason, JSON "reason").
REASONS: dict[int, str | None] = {
    lay.OK: None,
    lay.CONTACT_LOST: "contact lost",
    lay.FRICTIONAL_SINGULARITY: "frictional singularity",
    lay.NOT_CONVERGED: "not converged",
    lay.STEP_LIMIT: "not converged (step limit)",
    lay.STARTS_DISAGREE: "initial twists disagree",
}


#: Configurations per work item (``chunk=None``). Each chunk's first configuration starts from rest
#: (about 5.8 periods on Sink, against 1.3 once four neighbours are known), so long chunks
#: amortise it; small calls (designs' sample points, the planner's poses) keep chunks of 8, and
#: their results, as they were. From 1024 configurations per motion a call still has 32+ chunks
#: to share between threads.
CHUNK_SMALL = 8
CHUNK_LARGE = 32
CHUNK_LARGE_FROM = 1024


@dataclass(frozen=True)
class SolverSettings:
    """How the asymptotic solver and the full dynamics integrate.

    Parameters
    ----------
    integrator : str
        Embedded Runge-Kutta pair: ``"bs3"`` (3(2)), ``"dopri5"`` (5(4)), ``"dop853"`` (8(5,3)).
    fixed_point : str
        ``"anderson"`` (Anderson-accelerated iteration of the one-period map) or ``"picard"``.
    anderson_depth : int
        Differences kept by Anderson acceleration (1..5).
    rtol : float
        Local error tolerance per step for point parts, relative to the velocity scale.
    rigid_rtol : float
        The same for rigid parts. Tighter by default: where the three contacts reach zero
        relative speed nearly together (near the symmetric configurations), looser steps let the
        small asymmetry in the yaw rate jump from period to period.
    atol_mps, atol_radps : float
        Absolute floors of the local error tolerance (m/s; rad/s for the yaw rate).
    fixed_point_rtol, fixed_point_atol_mps, fixed_point_atol_radps : float
        Convergence of the limit cycle: |P(x) - x| below rtol * scale + atol.
    max_periods : int
        Periods integrated per configuration before it is reported "not converged".
    max_steps_per_period : int
        Attempted steps per period before "not converged (step limit)".
    zero_velocity_rtol : float
        A relative velocity below this (times the velocity scale) is a zero (stick or reversal).
    friction_eps_mps : float
        Rigid parts: velocity scale of the regularised Coulomb law f = -mu N u / max(|u|, eps).
    stick_capture : float
        Rigid parts: contact speeds below stick_capture * friction_eps_mps trigger the sticking test.
    scan_per_harmonic : int
        Samples per period and harmonic for event brackets and cycle minima.
    min_steps_per_period : int
        At least this many steps per period and harmonic: a longer step could hide two events
        (a relative velocity through zero and back) between its ends.
    closed_form : bool
        Point parts: use the closed form where a_h is collinear.
    warm_start : bool
        Start each configuration from its neighbour's limit cycle (same parallel chunk).
    skip_sticking : bool
        Skip sticking logic where sticking is provably impossible.
    prune_harmonics : bool
        Drop zero-amplitude harmonics before integrating.
    cache : bool
        Use the result cache keyed by (motion, part, settings, configuration).
    threads : int or None
        Worker threads (None: numba's default, all cores).
    chunk : int or None
        Configurations per work item (warm starts run along a chunk; the serial kernel uses the
        same chunks). None: :meth:`chunk_for` picks by the number of configurations per motion
        (``CHUNK_SMALL`` below ``CHUNK_LARGE_FROM``, else ``CHUNK_LARGE``).
    rigid_starts : int
        Rigid parts: number of initial twists solved and compared (1: no check).
    """

    integrator: str = "dopri5"
    fixed_point: str = "anderson"
    anderson_depth: int = 2
    rtol: float = 1e-6
    rigid_rtol: float = 1e-8
    atol_mps: float = 1e-12
    atol_radps: float = 1e-10
    fixed_point_rtol: float = 1e-5
    fixed_point_atol_mps: float = 1e-12
    fixed_point_atol_radps: float = 1e-10
    max_periods: int = 200
    max_steps_per_period: int = 50000
    zero_velocity_rtol: float = 1e-9
    friction_eps_mps: float = 1e-6
    stick_capture: float = 10.0
    scan_per_harmonic: int = 16
    min_steps_per_period: int = 12
    closed_form: bool = True
    warm_start: bool = True
    skip_sticking: bool = True
    prune_harmonics: bool = True
    cache: bool = True
    threads: int | None = None
    chunk: int | None = None
    rigid_starts: int = 1

    def __post_init__(self) -> None:
        if self.integrator not in INTEGRATORS:
            raise ConfigError(f"integrator: unknown {self.integrator!r}; choose one of {sorted(INTEGRATORS)}")
        if self.fixed_point not in FIXED_POINT_METHODS:
            raise ConfigError(f"fixed_point: unknown {self.fixed_point!r}; "
                              f"choose one of {list(FIXED_POINT_METHODS)}")
        positive = ("rtol", "rigid_rtol", "atol_mps", "atol_radps", "fixed_point_rtol",
                    "fixed_point_atol_mps", "fixed_point_atol_radps", "zero_velocity_rtol",
                    "friction_eps_mps", "stick_capture")
        for name in positive:
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val) \
                    or val <= 0:
                raise ConfigError(f"{name}: must be a finite number > 0, got {val!r}")
            object.__setattr__(self, name, float(val))
        for name in ("rtol", "rigid_rtol", "fixed_point_rtol"):
            if getattr(self, name) >= 0.1:
                raise ConfigError(f"{name}: must be < 0.1, got {getattr(self, name)}")
        ints = {"anderson_depth": (1, 5), "max_periods": (1, 100000), "max_steps_per_period": (10, 10**8),
                "scan_per_harmonic": (4, 1024), "chunk": (1, 4096), "rigid_starts": (1, 16),
                "min_steps_per_period": (4, 10000)}
        for name, (lo, hi) in ints.items():
            val = getattr(self, name)
            if name == "chunk" and val is None:
                continue
            if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or not lo <= val <= hi:
                raise ConfigError(f"{name}: must be an integer in {lo}..{hi}, got {val!r}")
        for name in ("closed_form", "warm_start", "skip_sticking", "prune_harmonics", "cache"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"{name}: must be true or false, got {getattr(self, name)!r}")
        if self.threads is not None and (isinstance(self.threads, bool) or not isinstance(self.threads, int)
                                         or self.threads < 1):
            raise ConfigError(f"threads: must be a positive integer or None, got {self.threads!r}")

    # ------------------------------------------------------------------ derived
    def replace(self, **changes: Any) -> SolverSettings:
        unknown = set(changes) - {f.name for f in dataclasses.fields(self)}
        if unknown:
            raise ConfigError(f"settings: unknown option(s) {sorted(unknown)}")
        return dataclasses.replace(self, **changes)

    def _values_but(self, *skip: str) -> tuple:
        return tuple(getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in skip)

    def _derived(self, name: str, make):
        """A value computed from the (frozen) fields once per instance."""
        memo = self.__dict__.setdefault("_memo", {})
        if name not in memo:
            memo[name] = make()
        return memo[name]

    def cache_key(self) -> tuple:
        """Everything that can change a result (not threads or the cache switch)."""
        return self._derived("cache_key", lambda: self._values_but("threads", "cache"))

    def warm_key(self) -> tuple:
        """What a converged limit cycle depends on: :meth:`cache_key` without the work caps
        (``max_periods``, ``max_steps_per_period``). A row either converges within its caps, to the
        same cycle from the same start, or is not stored as a warm start; so calls that differ only
        in their caps (the planner's budgeted probes) share their warm starts."""
        return self._derived("warm_key", lambda: self._values_but("threads", "cache", "max_periods",
                                                                   "max_steps_per_period"))

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def step_rtol(self, kind: str) -> float:
        """The step tolerance for a ``"point"`` or ``"rigid"`` part."""
        return self.rtol if kind == "point" else self.rigid_rtol

    def vector(self, kind: str = "point") -> np.ndarray:
        """The settings vector S the compiled kernels read (see ``_layout``), for a part kind (a new
        array per call)."""
        S = self._derived(("vector", kind), lambda: self._vector(kind)).copy()
        S[lay.S_EVENT_ERR_MAX] = _advance.EVENT_ERR_MAX   # module constants: read per call
        S[lay.S_KAPPA] = _advance.KAPPA_PER_STEP_TOL
        S[lay.S_KAPPA_DEPART] = _advance.KAPPA_DEPART_PER_STEP_TOL
        S[lay.S_ZERO_PER_RTOL] = _advance.ZERO_PER_RTOL
        S[lay.S_LAG_MAX] = _advance.LAG_MAX_RAD
        return S

    def _vector(self, kind: str) -> np.ndarray:
        """The part of :meth:`vector` the fields give."""
        tab = INTEGRATORS[self.integrator]
        S = np.zeros(lay.S_SIZE)
        S[lay.S_RTOL] = self.step_rtol(kind)
        S[lay.S_ATOL_V] = self.atol_mps
        S[lay.S_ATOL_W] = self.atol_radps
        S[lay.S_FP_RTOL] = self.fixed_point_rtol
        S[lay.S_FP_ATOL_V] = self.fixed_point_atol_mps
        S[lay.S_FP_ATOL_W] = self.fixed_point_atol_radps
        S[lay.S_MAX_PERIODS] = self.max_periods
        S[lay.S_MAX_STEPS] = self.max_steps_per_period
        S[lay.S_ZERO_RTOL] = self.zero_velocity_rtol
        S[lay.S_DEPTH] = self.anderson_depth if self.fixed_point == "anderson" else 0
        S[lay.S_CAPTURE] = self.stick_capture
        S[lay.S_NSCAN] = self.scan_per_harmonic
        S[lay.S_CLOSED_FORM] = float(self.closed_form)
        S[lay.S_WARM] = float(self.warm_start)
        S[lay.S_ERRKIND] = float(tab.combined_error)
        S[lay.S_EXPONENT] = tab.exponent
        S[lay.S_SKIP_STICK] = float(self.skip_sticking)
        S[lay.S_CHUNK] = self.chunk or CHUNK_SMALL
        S[lay.S_STARTS] = self.rigid_starts
        S[lay.S_MIN_STEPS] = self.min_steps_per_period
        return S

    def chunk_for(self, n_configs: int) -> int:
        """Configurations per work item for a call with ``n_configs`` configurations per motion."""
        if self.chunk is not None:
            return self.chunk
        return CHUNK_LARGE if n_configs >= CHUNK_LARGE_FROM else CHUNK_SMALL

    def describe(self) -> str:
        base = SolverSettings()
        diff = [f"{f.name}={getattr(self, f.name)}" for f in dataclasses.fields(self)
                if getattr(self, f.name) != getattr(base, f.name)]
        return ", ".join(diff) if diff else "defaults"


#: Named settings spanning the accuracy/time trade-off (see docs/solver.md and ppod bench solver).
PRESETS: dict[str, SolverSettings] = {
    "fast": SolverSettings(rtol=1e-5, rigid_rtol=1e-6, fixed_point_rtol=1e-4),
    "default": SolverSettings(),
    "accurate": SolverSettings(integrator="dop853", rtol=1e-9, rigid_rtol=1e-9, fixed_point_rtol=1e-8),
    # Tight settings: 8th order, the closed form where a_h is collinear (exact there: an independent
    # fixed-step reference agrees with it to 1e-12 where the integrated path was off by 6-8e-7 m/s
    # at heavily sticking configurations). The benchmark judges accuracy against that independent
    # reference (benchmarks/fixed_step_reference.py), not against this preset.
    # (fixed_point_rtol 1e-10: below that, rounding over a period's few hundred steps is larger.)
    "reference": SolverSettings(integrator="dop853", rtol=1e-12, rigid_rtol=1e-11, fixed_point_rtol=1e-10,
                                warm_start=False, max_periods=1000, max_steps_per_period=500000),
}


def preset(name: str) -> SolverSettings:
    """The preset called ``name`` (a clear error naming the choices otherwise)."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ConfigError(f"preset: unknown {name!r}; choose one of {sorted(PRESETS)}") from None


__all__ = ["FIXED_POINT_METHODS", "INTEGRATORS", "PRESETS", "REASONS", "SolverSettings", "preset"]

"""Physics of parts on the vibrating plate (PHYSICS.md): asymptotic fields and full dynamics.

Public API (stable; see docs/solver.md):

- :func:`solve_field` -> :class:`FieldResult`: asymptotic velocity (point part) or twist (rigid
  part) at many configurations, compiled and parallel; invalid configurations are flagged with a
  reason, never returned as numbers.
- :func:`solve_fields` -> :class:`FieldsResult`: many motions x many configurations in one compiled
  call (shared (N, d) or per-motion (M, N, d) configurations), serial or parallel by size (no
  thread wake-up stalls on a busy machine) and warm-started from previous calls
  (:data:`WARM_STARTS`).
- :class:`SolverSettings`, :data:`PRESETS`, :func:`preset`: tolerances, integrator and fixed-point
  method by name.
- :class:`PartDynamics`: full dynamics of many parts with evolving configurations, advanced in
  chunks (the simulated device).
- :func:`limit_cycle`: the limit cycle itself at one configuration; :func:`grid_configs`: grids in
  the ``ppod field`` order; :data:`FIELD_CACHE`: the result cache.

Nothing here imports rclpy or message types. :func:`limit_cycle`, :class:`PartDynamics` and
:class:`DynamicsState` are imported on first use (a small ``ppod field`` call needs neither).
"""

from typing import Any

from ppod_ros.physics.field import (
    FIELD_CACHE,
    WARM_STARTS,
    FieldCache,
    FieldResult,
    FieldsResult,
    WarmStarts,
    grid_configs,
    solve_field,
    solve_fields,
)
from ppod_ros.physics.settings import (
    FIXED_POINT_METHODS,
    INTEGRATORS,
    PRESETS,
    REASONS,
    SolverSettings,
    preset,
)

#: Names imported from their module on first use (PEP 562): name -> module.
_LAZY = {"limit_cycle": "ppod_ros.physics.cycle", "DynamicsState": "ppod_ros.physics.dynamics",
         "PartDynamics": "ppod_ros.physics.dynamics"}


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'ppod_ros.physics' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


__all__ = [
    "FIELD_CACHE",
    "FIXED_POINT_METHODS",
    "INTEGRATORS",
    "PRESETS",
    "REASONS",
    "WARM_STARTS",
    "DynamicsState",
    "FieldCache",
    "FieldResult",
    "FieldsResult",
    "PartDynamics",
    "SolverSettings",
    "WarmStarts",
    "grid_configs",
    "limit_cycle",
    "preset",
    "solve_field",
    "solve_fields",
]

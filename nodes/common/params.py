"""Declared, described and validated node parameters.

Each node lists its parameters once as :class:`Param` entries (name, default, description, and a
range or choices). :func:`declare` declares them with ROS parameter descriptors (so ``ros2 param
describe`` and our launcher show the documentation and ranges); :func:`read` returns a plain dict,
which the node hands to a core ``from_dict`` that builds a frozen, validated config. Values come from
per-node YAML files in the standard layout, passed with ``--ros-args --params-file FILE``::

    waveform_generator:
      ros__parameters:
        device_config: ""
        heartbeat_period_s: 0.05

Dotted names (``limits.coil_current_a``) map to nested YAML keys.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType

from ppod_ros.errors import ConfigError

_TYPES = {
    bool: ParameterType.PARAMETER_BOOL,
    int: ParameterType.PARAMETER_INTEGER,
    float: ParameterType.PARAMETER_DOUBLE,
    str: ParameterType.PARAMETER_STRING,
}


@dataclass(frozen=True)
class Param:
    """One node parameter: its default fixes its type (bool, int, float, str or a list of them)."""

    name: str
    default: Any
    description: str
    min_value: float | None = None
    max_value: float | None = None
    choices: tuple[str, ...] | None = None
    read_only: bool = False
    #: True: a change at run time (``ros2 param set``) is applied at once; False: the parameter is
    #: declared read-only (set it in the parameter file; it takes effect at start-up).
    runtime: bool = False

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(name=self.name, description=self.description,
                                read_only=self.read_only or not self.runtime)
        d.type = self.param_type
        if self.choices:
            d.additional_constraints = "one of: " + ", ".join(self.choices)
        if self.min_value is not None or self.max_value is not None:
            lo = self.min_value if self.min_value is not None else -1e300
            hi = self.max_value if self.max_value is not None else 1e300
            if isinstance(self.default, bool):
                pass
            elif isinstance(self.default, int):
                d.integer_range = [IntegerRange(from_value=int(max(lo, -(2**62))), to_value=int(min(hi, 2**62)),
                                                step=0)]
            elif isinstance(self.default, float):
                d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
        return d

    @property
    def param_type(self) -> int:
        if isinstance(self.default, (list, tuple)):
            inner = type(self.default[0]) if self.default else float
            return {
                bool: ParameterType.PARAMETER_BOOL_ARRAY,
                int: ParameterType.PARAMETER_INTEGER_ARRAY,
                float: ParameterType.PARAMETER_DOUBLE_ARRAY,
                str: ParameterType.PARAMETER_STRING_ARRAY,
            }[inner]
        return _TYPES[type(self.default)]


def declare(node, params: Iterable[Param]) -> None:
    """Declare every parameter on ``node`` with its default and descriptor."""
    for p in params:
        default = list(p.default) if isinstance(p.default, tuple) else p.default
        node.declare_parameter(p.name, default, p.descriptor())


def checked(p: Param, value: Any) -> Any:
    """``value`` for parameter ``p`` (sequences as lists), or ConfigError naming it, its range or choices."""
    if isinstance(value, (list, tuple)) or hasattr(value, "tolist"):
        value = list(value.tolist() if hasattr(value, "tolist") else value)
    if p.choices and value not in p.choices:
        raise ConfigError(f"parameter {p.name}: expected one of {', '.join(p.choices)}, got {value!r}")
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        if p.min_value is not None and value < p.min_value:
            raise ConfigError(f"parameter {p.name}: must be >= {p.min_value}, got {value}")
        if p.max_value is not None and value > p.max_value:
            raise ConfigError(f"parameter {p.name}: must be <= {p.max_value}, got {value}")
    return value


def read(node, params: Sequence[Param]) -> dict[str, Any]:
    """Read declared parameters into a dict keyed by name, checking choices and ranges.

    Raises :class:`ConfigError` naming the parameter (the node turns it into a failed transition).
    """
    return {p.name: checked(p, node.get_parameter(p.name).value) for p in params}


def with_runtime(params: Iterable[Param], names: Iterable[str]) -> tuple[Param, ...]:
    """``params`` with those in ``names`` marked runtime (a node's ``RUNTIME_PARAMS``); unknown names raise."""
    from dataclasses import replace

    params, names = tuple(params), set(names)
    unknown = names - {p.name for p in params}
    if unknown:
        raise ConfigError(f"RUNTIME_PARAMS: no parameter named {', '.join(sorted(unknown))}")
    return tuple(replace(p, runtime=True) if p.name in names else p for p in params)


def nest(flat: dict[str, Any]) -> dict[str, Any]:
    """Turn dotted keys into nested dicts: {"a.b": 1} -> {"a": {"b": 1}}."""
    out: dict[str, Any] = {}
    for key, value in flat.items():
        parts = key.split(".")
        d = out
        for part in parts[:-1]:
            d = d.setdefault(part, {})
        d[parts[-1]] = value
    return out


def params_file_text(node_name: str, values: dict[str, Any]) -> str:
    """The standard ``node_name: ros__parameters:`` YAML for ``values`` (nested or dotted)."""
    import yaml

    return yaml.safe_dump({node_name: {"ros__parameters": values}}, sort_keys=False)

"""Strict readers for user-written mappings (YAML files, ROS parameters, message fields).

The public file formats (docs/formats.md) are validated strictly: an unknown key, a wrong shape or a
non-finite number is an error that names the key, with its full path (``harmonics[1].amplitude``).
:class:`Fields` wraps one mapping; each accessor consumes a key, and :meth:`Fields.finish` rejects
whatever was not consumed.

Files are untrusted input: :func:`load_yaml_file` and :func:`parse_yaml_text` refuse files over
:data:`MAX_YAML_BYTES`, text that is not UTF-8, nesting deeper than :data:`MAX_YAML_DEPTH`, more than
:data:`MAX_YAML_NODES` nodes or :data:`MAX_YAML_ALIASES` aliases (an alias bomb), and duplicate keys,
each with a one-line :class:`~ppod_ros.errors.ConfigError`. Numbers in exponent form without a
dot (``1e-5``) read as numbers (YAML 1.1 would read a string); booleans are never numbers.
"""

from __future__ import annotations

import math
import re
import reprlib
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ppod_ros.errors import ConfigError

_MISSING = object()

#: Largest YAML file read (bytes): device descriptions, motions and parts are a few kB.
MAX_YAML_BYTES = 1 << 20
#: Deepest nesting of YAML collections (the formats need 3; deep nesting would exhaust the stack).
MAX_YAML_DEPTH = 32
#: Most YAML nodes in one document (a 1 MiB file of numbers has about 200 000).
MAX_YAML_NODES = 200_000
#: Most aliases (*ref) in one document: the formats need none; n aliases expand at most ~3^(n/3)-fold.
MAX_YAML_ALIASES = 16

_SHORT = reprlib.Repr()
_SHORT.maxstring, _SHORT.maxother, _SHORT.maxlist, _SHORT.maxlevel = 60, 60, 8, 3


def short_repr(value: Any) -> str:
    """A repr bounded in length, for error messages about untrusted input."""
    return _SHORT.repr(value)


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader with bounded depth, node and alias counts, no duplicate keys, ``1e-5`` as a float."""

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0
        self._nodes = 0
        self._aliases = 0

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            self._aliases += 1
            if self._aliases > MAX_YAML_ALIASES:
                raise ConfigError(f"more than {MAX_YAML_ALIASES} YAML aliases (an alias bomb?)")
        self._nodes += 1
        if self._nodes > MAX_YAML_NODES:
            raise ConfigError(f"more than {MAX_YAML_NODES} YAML nodes")
        self._depth += 1
        if self._depth > MAX_YAML_DEPTH:
            raise ConfigError(f"YAML nested deeper than {MAX_YAML_DEPTH} levels")
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                duplicate = key in seen
            except TypeError:  # an unhashable key: the base class reports it
                break
            if duplicate:
                line = key_node.start_mark.line + 1
                raise ConfigError(f"duplicate key {short_repr(key)} (line {line})")
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


_StrictLoader.add_constructor("tag:yaml.org,2002:map", _StrictLoader.construct_yaml_map)
# YAML 1.1 reads 1e-5 (no dot) as a string; YAML 1.2 and every user read it as a number.
_StrictLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"), list("-+0123456789")
)


def parse_yaml_text(text: str, origin: str) -> Mapping[str, Any]:
    """Parse YAML text that must hold a mapping; ``origin`` names it in error messages."""
    if len(text) > MAX_YAML_BYTES:
        raise ConfigError(f"{origin}: {len(text)} characters, more than the {MAX_YAML_BYTES} a YAML file may have")
    try:
        data = yaml.load(text, Loader=_StrictLoader)  # noqa: S506 - a SafeLoader subclass
    except ConfigError as exc:
        raise ConfigError(f"{origin}: {exc}") from exc
    except yaml.YAMLError as exc:
        first = " ".join(str(exc).split())
        raise ConfigError(f"{origin}: not valid YAML: {first}") from exc
    except RecursionError as exc:
        raise ConfigError(f"{origin}: YAML nested too deeply") from exc
    if not isinstance(data, Mapping):
        raise ConfigError(f"{origin}: expected a mapping of keys to values, got {type(data).__name__}")
    return data


def load_yaml_file(path: str | Path, what: str) -> Mapping[str, Any]:
    """Read and parse a YAML file holding a mapping; errors name the file and ``what`` it is."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_YAML_BYTES:
            raise ConfigError(f"{what} file {path}: {size} bytes, more than the {MAX_YAML_BYTES} a YAML file may have")
        raw = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{what} file {path}: {exc.strerror or exc}") from exc
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"{what} file {path}: not UTF-8 text (byte {exc.start}: {raw[exc.start:exc.start + 1]!r}); "
            f"save it as UTF-8"
        ) from exc
    if "\x00" in text:
        raise ConfigError(f"{what} file {path}: contains NUL bytes (a binary file, or UTF-16/32 text)")
    return parse_yaml_text(text, str(path))


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


class Fields:
    """Consume the keys of one mapping with typed, range-checked accessors.

    Example
    -------
    >>> f = Fields({"mu": 0.3}, "part")
    >>> f.number("mu", min_value=0.0)
    0.3
    >>> f.finish()
    """

    def __init__(self, data: Mapping[str, Any], path: str):
        if not isinstance(data, Mapping):
            raise ConfigError(f"{path}: expected a mapping, got {type(data).__name__}")
        self._data = data
        self._path = path
        self._used: set[str] = set()

    @property
    def path(self) -> str:
        return self._path

    def key_path(self, key: str) -> str:
        return f"{self._path}.{key}" if self._path else key

    def has(self, key: str) -> bool:
        return key in self._data

    def raw(self, key: str, default: Any = _MISSING) -> Any:
        """Return the raw value of ``key`` (marking it used); error if missing and no default."""
        self._used.add(key)
        if key in self._data:
            return self._data[key]
        if default is _MISSING:
            raise ConfigError(f"{self.key_path(key)}: required key is missing")
        return default

    def sub(self, key: str, default: Any = _MISSING) -> Fields | None:
        """A nested mapping as another :class:`Fields` (None if absent and default is None)."""
        value = self.raw(key, default)
        if value is None:
            return None
        return Fields(value, self.key_path(key))

    def number(
        self,
        key: str,
        default: Any = _MISSING,
        *,
        min_value: float | None = None,
        max_value: float | None = None,
        exclusive_min: bool = False,
        unit: str = "",
    ) -> float:
        value = self.raw(key, default)
        if value is None and default is None:
            return None  # type: ignore[return-value]
        return check_number(value, self.key_path(key), min_value=min_value, max_value=max_value,
                             exclusive_min=exclusive_min, unit=unit)

    def integer(self, key: str, default: Any = _MISSING, *, min_value: int | None = None,
                max_value: int | None = None) -> int:
        value = self.raw(key, default)
        name = self.key_path(key)
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
            if _is_number(value) and float(value).is_integer():
                value = int(value)
            else:
                raise ConfigError(f"{name}: expected an integer, got {value!r}")
        value = int(value)
        if min_value is not None and value < min_value:
            raise ConfigError(f"{name}: must be >= {min_value}, got {value}")
        if max_value is not None and value > max_value:
            raise ConfigError(f"{name}: must be <= {max_value}, got {value}")
        return value

    def string(self, key: str, default: Any = _MISSING, *, choices: Iterable[str] | None = None) -> str:
        value = self.raw(key, default)
        name = self.key_path(key)
        if value is None and default is None:
            return None  # type: ignore[return-value]
        if not isinstance(value, str):
            raise ConfigError(f"{name}: expected a string, got {value!r}")
        if choices is not None:
            choices = list(choices)
            if value not in choices:
                raise ConfigError(f"{name}: expected one of {', '.join(choices)}; got {value!r}")
        return value

    def boolean(self, key: str, default: Any = _MISSING) -> bool:
        value = self.raw(key, default)
        if not isinstance(value, (bool, np.bool_)):
            raise ConfigError(f"{self.key_path(key)}: expected true or false, got {value!r}")
        return bool(value)

    def array(self, key: str, default: Any = _MISSING, *, shape: tuple[int | None, ...] | None = None,
              min_value: float | None = None, max_value: float | None = None, unit: str = "") -> np.ndarray:
        value = self.raw(key, default)
        if value is None and default is None:
            return None  # type: ignore[return-value]
        return check_array(value, self.key_path(key), shape=shape, min_value=min_value,
                           max_value=max_value, unit=unit)

    def items(self, key: str, default: Any = _MISSING) -> list[Fields]:
        """A list of mappings, each wrapped as :class:`Fields` with an indexed path."""
        value = self.raw(key, default)
        name = self.key_path(key)
        if value is None and default is None:
            return []
        if not isinstance(value, Sequence) or isinstance(value, (str, bytes)):
            raise ConfigError(f"{name}: expected a list, got {type(value).__name__}")
        return [Fields(item, f"{name}[{i}]") for i, item in enumerate(value)]

    def finish(self) -> None:
        """Raise :class:`ConfigError` naming every key that no accessor consumed."""
        unknown = [str(k) for k in self._data if k not in self._used]
        if unknown:
            names = ", ".join(self.key_path(k) for k in sorted(unknown))
            raise ConfigError(f"unknown key{'s' if len(unknown) > 1 else ''}: {names}")


def check_number(value: Any, name: str, *, min_value: float | None = None, max_value: float | None = None,
                 exclusive_min: bool = False, unit: str = "") -> float:
    """Validate one finite real number; the message names ``name`` and the bound."""
    suffix = f" {unit}" if unit else ""
    if not _is_number(value):
        raise ConfigError(f"{name}: expected a number{(' in ' + unit) if unit else ''}, got {short_repr(value)}")
    x = float(value)
    if not math.isfinite(x):
        raise ConfigError(f"{name}: must be finite, got {x}")
    if min_value is not None:
        if exclusive_min and x <= min_value:
            raise ConfigError(f"{name}: must be > {min_value}{suffix}, got {x}")
        if not exclusive_min and x < min_value:
            raise ConfigError(f"{name}: must be >= {min_value}{suffix}, got {x}")
    if max_value is not None and x > max_value:
        raise ConfigError(f"{name}: must be <= {max_value}{suffix}, got {x}")
    return x


def _has_bool(value: Any, depth: int = 0) -> bool:
    """True if a (nested) list holds a boolean, which numpy would silently read as 0 or 1."""
    if isinstance(value, (bool, np.bool_)):
        return True
    if isinstance(value, (list, tuple)) and depth < MAX_YAML_DEPTH:
        return any(_has_bool(v, depth + 1) for v in value)
    if isinstance(value, np.ndarray):
        return value.dtype.kind == "b"
    return False


def check_array(value: Any, name: str, *, shape: tuple[int | None, ...] | None = None,
                min_value: float | None = None, max_value: float | None = None, unit: str = "",
                dtype: type = float) -> np.ndarray:
    """Validate a finite numeric array of the given shape (None in ``shape`` = any length)."""
    if isinstance(value, (str, bytes, Mapping)):
        raise ConfigError(f"{name}: expected a list of numbers, got {type(value).__name__}")
    if _has_bool(value):
        raise ConfigError(f"{name}: expected numbers, got a boolean (true/false) in {short_repr(value)}")
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{name}: expected a list of numbers, got {short_repr(value)}") from exc
    if arr.dtype == object or arr.dtype.kind not in "iuf":
        if arr.dtype.kind == "b":
            raise ConfigError(f"{name}: expected numbers, got booleans")
        raise ConfigError(f"{name}: expected numbers{(' in ' + unit) if unit else ''}, got {short_repr(value)}")
    arr = arr.astype(dtype)
    if shape is not None:
        ok = arr.ndim == len(shape) and all(s is None or s == n for s, n in zip(shape, arr.shape))
        if not ok:
            want = " x ".join("N" if s is None else str(s) for s in shape)
            got = " x ".join(str(n) for n in arr.shape) or "a scalar"
            raise ConfigError(f"{name}: expected shape {want}, got {got}")
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"{name}: all values must be finite, got {arr.tolist()}")
    suffix = f" {unit}" if unit else ""
    if min_value is not None and np.any(arr < min_value):
        raise ConfigError(f"{name}: values must be >= {min_value}{suffix}, got {arr.tolist()}")
    if max_value is not None and np.any(arr > max_value):
        raise ConfigError(f"{name}: values must be <= {max_value}{suffix}, got {arr.tolist()}")
    return arr

"""Full ROS 2 message definitions (the ``ros2msg`` schema text that MCAP and rosbag2 store).

rosbag2 stores, per topic type, the type's .msg text followed by every nested type's text, each
introduced by a separator line and ``MSG: pkg/Name``. Without rosidl_runtime_py (no wheel) we build
that from the .msg files the interface packages install under ``<prefix>/share/<pkg>/msg``.
"""

from __future__ import annotations

import os
import re
import sys
from functools import cache
from pathlib import Path

SEPARATOR = "=" * 80
_PRIMITIVES = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32",
    "int64", "uint64", "string", "wstring",
}
_FIELD = re.compile(r"^\s*(?P<type>[A-Za-z][\w/]*)(?:\[[^\]]*\])?\s+(?P<name>\w+)\s*(?P<const>=)?")


def _prefixes() -> list[Path]:
    out = [Path(sys.prefix)]
    for entry in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if entry and Path(entry) not in out:
            out.append(Path(entry))
    return out


def msg_file(type_name: str) -> Path:
    """The .msg file of ``pkg/msg/Name`` (or ``pkg/Name``)."""
    pkg, name = _split(type_name)
    for prefix in _prefixes():
        path = prefix / "share" / pkg / "msg" / f"{name}.msg"
        if path.is_file():
            return path
    raise FileNotFoundError(f"no .msg file for {type_name} under {', '.join(map(str, _prefixes()))}")


def _split(type_name: str) -> tuple[str, str]:
    parts = type_name.split("/")
    if len(parts) == 3 and parts[1] == "msg":
        return parts[0], parts[2]
    if len(parts) == 2:
        return parts[0], parts[1]
    raise ValueError(f"expected pkg/msg/Name, got {type_name!r}")


def _dependencies(pkg: str, text: str) -> list[str]:
    """Nested message types named by the fields of a .msg text (constants and primitives skipped)."""
    deps = []
    for line in text.splitlines():
        m = _FIELD.match(line.split("#", 1)[0])
        if m and not m["const"] and m["type"] not in _PRIMITIVES:
            deps.append(m["type"] if "/" in m["type"] else f"{pkg}/{m['type']}")
    return deps


@cache
def full_definition(type_name: str) -> str:
    """The rosbag2-style definition of ``pkg/msg/Name`` with all nested types, depth-first."""
    pkg, name = _split(type_name)
    text = msg_file(type_name).read_text()
    parts = [text.rstrip("\n")]
    seen = {f"{pkg}/{name}"}
    stack = list(reversed(_dependencies(pkg, text)))
    order: list[str] = []
    while stack:
        dep = stack.pop()
        dpkg, dname = _split(dep)
        key = f"{dpkg}/{dname}"
        if key in seen:
            continue
        seen.add(key)
        order.append(key)
        stack.extend(reversed(_dependencies(dpkg, msg_file(key).read_text())))
    for key in order:
        dpkg, dname = _split(key)
        parts.append(f"{SEPARATOR}\nMSG: {dpkg}/msg/{dname}\n" + msg_file(key).read_text().rstrip("\n"))
    return "\n".join(parts) + "\n"

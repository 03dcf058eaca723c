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
    if len(parts) == 3 and parts[1] in ("msg", "action"):
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


_ACTION_PART = re.compile(r"^(?P<action>\w+)_(?P<part>Goal|Result|Feedback|FeedbackMessage)$")


def _action_text(pkg: str, name: str) -> str | None:
    """Text of an action's generated types (``Name_Feedback``, ``Name_FeedbackMessage``, ...), or None.

    The sections of ``share/<pkg>/action/<Action>.action`` are goal, result and feedback; the
    feedback message that goes on the ``_action/feedback`` topic is a goal id and the feedback.
    """
    m = _ACTION_PART.match(name)
    if not m:
        return None
    for prefix in _prefixes():
        path = prefix / "share" / pkg / "action" / f"{m['action']}.action"
        if path.is_file():
            sections = re.split(r"^---\s*$", path.read_text(), flags=re.MULTILINE)
            if m["part"] == "FeedbackMessage":
                return f"unique_identifier_msgs/UUID goal_id\n{m['action']}_Feedback feedback\n"
            return sections[{"Goal": 0, "Result": 1, "Feedback": 2}[m["part"]]].strip("\n") + "\n"
    return None


def _text(type_name: str) -> str:
    pkg, name = _split(type_name)
    action = _action_text(pkg, name)
    return action if action is not None else msg_file(type_name).read_text()


@cache
def full_definition(type_name: str) -> str:
    """The rosbag2-style definition of ``pkg/msg/Name`` with all nested types, depth-first.

    Action feedback types (``pkg/action/Name_FeedbackMessage``, the ``_action/feedback`` topics) are
    built from the ``.action`` file.
    """
    pkg, name = _split(type_name)
    text = _text(type_name)
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
        stack.extend(reversed(_dependencies(dpkg, _text(key))))
    for key in order:
        dpkg, dname = _split(key)
        kind = "action" if _action_text(dpkg, dname) is not None else "msg"
        parts.append(f"{SEPARATOR}\nMSG: {dpkg}/{kind}/{dname}\n" + _text(key).rstrip("\n"))
    return "\n".join(parts) + "\n"

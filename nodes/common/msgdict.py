"""ROS messages to plain Python data (for printing, JSON and YAML) and message types by name.

``rosidl_runtime_py`` has no wheel, so this is the small subset we need: every generated message
class lists its fields with ``get_fields_and_field_types()``.
"""

from __future__ import annotations

import array
import importlib
from typing import Any

import numpy as np


def to_data(msg: Any) -> Any:
    """A message (or field value) as dicts, lists and scalars, recursively."""
    if hasattr(msg, "get_fields_and_field_types"):
        return {name: to_data(getattr(msg, name)) for name in msg.get_fields_and_field_types()}
    if isinstance(msg, (np.ndarray, array.array)):  # rclpy gives numeric sequences as array.array
        return msg.tolist()
    if isinstance(msg, (list, tuple)):
        return [to_data(v) for v in msg]
    if isinstance(msg, (bytes, bytearray)):
        return list(msg)
    if isinstance(msg, np.generic):
        return msg.item()
    return msg


def type_from_name(type_name: str):
    """Import a message/service class from ``pkg/msg/Name`` (or ``pkg/Name``, ``pkg.msg.Name``)."""
    parts = type_name.replace(".", "/").split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3:
        raise ValueError(f"message type must look like pkg/msg/Name, got {type_name!r}")
    pkg, kind, name = parts
    module = importlib.import_module(f"{pkg}.{kind}")
    if hasattr(module, name):
        return getattr(module, name)
    # An action's generated types (the _action/feedback topic's Name_FeedbackMessage, ...).
    action, _, part = name.rpartition("_")
    if kind == "action" and hasattr(module, action):
        cls = getattr(module, action)
        found = getattr(cls, part, None) or getattr(getattr(cls, "Impl", None), part, None)
        if found is not None:
            return found
    raise ValueError(f"{pkg}.{kind} has no type {name}")


def type_name_of(cls) -> str:
    module = cls.__module__.split(".")
    return f"{module[0]}/{module[1]}/{cls.__name__}"

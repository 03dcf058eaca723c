"""GOALS.yaml: several parts, each to its own goal pose (``ppod demo --goals``, ``ppod move``).

::

    goals:
      - {part: bracket, pose: [0.02, -0.02, 0]}     # a label (first unused match) or an index; x, y in m,
                                                   # theta in degrees
      - {part: 1, pose: [-0.03, 0.03], tol_mm: 2}  # no theta: position only; optional tol_mm, tol_deg

Default tolerances 1 mm and 2 degrees. :func:`resolve_parts` names the parts: a label is the first
part with that label not already named, an integer the part at that position (the demo: the scene's
order; ``ppod move``: a track id).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ppod_ros.config.fields import load_yaml_file
from ppod_ros.errors import ConfigError

DEFAULT_TOL_MM = 1.0
DEFAULT_TOL_DEG = 2.0


@dataclass(frozen=True)
class GoalEntry:
    part: str | int
    x_m: float
    y_m: float
    theta_deg: float | None
    tol_mm: float = DEFAULT_TOL_MM
    tol_deg: float = DEFAULT_TOL_DEG


def goals_from_data(data, origin: str = "goals") -> list[GoalEntry]:
    """Validate a parsed GOALS.yaml; ConfigError naming the entry and field otherwise."""
    if not isinstance(data, dict) or not isinstance(data.get("goals"), list) or not data["goals"]:
        raise ConfigError(f"{origin}: goals: expected a non-empty list of {{part, pose}} entries")
    unknown = set(data) - {"goals"}
    if unknown:
        raise ConfigError(f"{origin}: unknown key(s) {sorted(unknown)}; expected 'goals'")
    out = []
    for i, item in enumerate(data["goals"]):
        where = f"{origin}: goals[{i}]"
        if not isinstance(item, dict):
            raise ConfigError(f"{where}: expected a mapping {{part, pose}}, got {item!r}")
        extra = set(item) - {"part", "pose", "tol_mm", "tol_deg"}
        if extra:
            raise ConfigError(f"{where}: unknown key(s) {sorted(extra)}; expected part, pose, tol_mm, tol_deg")
        part = item.get("part")
        if isinstance(part, bool) or not isinstance(part, (str, int)) or (isinstance(part, int) and part < 0):
            raise ConfigError(f"{where}.part: expected a label or a 0-based index, got {part!r}")
        pose = item.get("pose")
        if not isinstance(pose, list) or len(pose) not in (2, 3):
            raise ConfigError(f"{where}.pose: expected [x_m, y_m] or [x_m, y_m, theta_deg], got {pose!r}")
        try:
            vals = [float(v) for v in pose]
        except (TypeError, ValueError):
            raise ConfigError(f"{where}.pose: expected numbers, got {pose!r}") from None
        if not all(math.isfinite(v) for v in vals):
            raise ConfigError(f"{where}.pose: values must be finite, got {pose!r}")
        tols = {}
        for key, default, unit in (("tol_mm", DEFAULT_TOL_MM, "mm"), ("tol_deg", DEFAULT_TOL_DEG, "deg")):
            v = item.get(key, default)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise ConfigError(f"{where}.{key}: expected a number > 0 ({unit}), got {v!r}")
            tols[key] = float(v)
        out.append(GoalEntry(part, vals[0], vals[1], vals[2] if len(vals) == 3 else None, **tols))
    return out


def load_goals_file(path: str | Path) -> list[GoalEntry]:
    return goals_from_data(load_yaml_file(path, "goals"), str(path))


def resolve_parts(entries: Sequence[GoalEntry], labels: Sequence[str], ids: Sequence[int] | None = None) -> list[int]:
    """Positions in ``labels`` of each entry's part: a label names the first part with it not yet
    named; an integer is an index (or, with ``ids``, the position of that id). ConfigError for a
    part named twice or not there."""
    used: set[int] = set()
    out = []
    for i, e in enumerate(entries):
        if isinstance(e.part, int):
            if ids is not None:
                if e.part not in ids:
                    raise ConfigError(f"goals[{i}].part: no part with id {e.part} (ids {', '.join(map(str, ids))})")
                pos = list(ids).index(e.part)
            elif not 0 <= e.part < len(labels):
                raise ConfigError(f"goals[{i}].part: index {e.part} outside 0..{len(labels) - 1}")
            else:
                pos = e.part
            if pos in used:
                raise ConfigError(f"goals[{i}].part: part {e.part} is already given a goal")
        else:
            free = [j for j, lb in enumerate(labels) if lb == e.part and j not in used]
            if not free:
                have = ", ".join(sorted(set(labels))) or "none"
                raise ConfigError(f"goals[{i}].part: no {'further ' if e.part in labels else ''}part labelled "
                                  f"{e.part!r} (labels: {have})")
            pos = free[0]
        used.add(pos)
        out.append(pos)
    return out


__all__ = ["DEFAULT_TOL_DEG", "DEFAULT_TOL_MM", "GoalEntry", "goals_from_data", "load_goals_file", "resolve_parts"]

"""The parts on the simulated plate: the scene file, and how parts keep out of each other.

Scene file (YAML), strictly validated::

    seed: 7                                  # optional; scatter and camera noise
    parts:                                   # placed parts
      - label: washer                        # the part type the tracker knows (config/tracker.yaml)
        part: {type: point, mu: 0.3, footprint: {disk: 0.006}}   # a PART.yaml mapping
        height_m: 0.002                      # height of the top face (renderer, tracker)
        pose: [0.05, 0.02, 0.0]              # x, y (m), theta (rad) in the plate frame
    scatter:                                 # optional: more parts at random, non-overlapping
      count: 4
      types: [washer, pin]                   # labels of parts listed above, used as templates
      region_m: [-0.09, 0.09, -0.09, 0.09]   # x_min x_max y_min y_max
      min_gap_m: 0.01

The full dynamics (ppod_ros.physics) treats each part alone on the plate. Real parts do not pass
through each other, and the tracker cannot separate parts closer than about 1.6 mm, so after each
plate cycle :func:`separate` pushes apart any two parts whose bounding circles overlap (equal and
opposite moves along the line of centres, the approaching velocity removed): a simple, stated
non-penetration model, not a contact-dynamics one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ppod_ros.config.fields import Fields, load_yaml_file
from ppod_ros.errors import ConfigError
from ppod_ros.parts import Footprint, Part, RigidPart, part_from_dict


@dataclass(frozen=True, eq=False)
class ScenePart:
    """One part on the plate: its type label, physics, top-face height and initial pose."""

    label: str
    part: Part
    height_m: float
    pose: np.ndarray  # (3,) x, y, theta

    @property
    def outline(self) -> np.ndarray:
        """Outline (M, 2) in the body frame (footprint, or a rigid part's contact triangle)."""
        if isinstance(self.part, RigidPart):
            return self.part.outline()
        fp = self.part.footprint
        return fp.outline() if fp is not None else Footprint("disk", (0.002,)).outline()

    @property
    def radius_m(self) -> float:
        """Radius of the bounding circle about the pose's point."""
        fp = self.part.footprint
        if fp is not None and fp.kind == "disk":
            return fp.size[0]
        return float(np.max(np.hypot(*self.outline.T)))


@dataclass(frozen=True, eq=False)
class Scene:
    parts: tuple[ScenePart, ...]
    seed: int = 0

    @property
    def poses(self) -> np.ndarray:
        return np.array([p.pose for p in self.parts]).reshape(-1, 3)

    @property
    def radii_m(self) -> np.ndarray:
        return np.array([p.radius_m for p in self.parts])

    def to_dict(self) -> dict[str, Any]:
        """A scene file with every part placed (scatter resolved): what a recording stores."""
        return {"seed": self.seed, "parts": [
            {"label": p.label, "part": p.part.to_dict(), "height_m": p.height_m,
             "pose": [float(v) for v in p.pose]} for p in self.parts]}


def scene_from_dict(data: Mapping[str, Any], origin: str = "scene") -> Scene:
    f = Fields(data, "")
    seed = f.integer("seed", 0, min_value=0)
    placed: list[ScenePart] = []
    for item in f.items("parts", []):
        label = item.string("label")
        part = part_from_dict(item.raw("part"), item.key_path("part"))
        height = item.number("height_m", 0.0, min_value=0.0, unit="m")
        pose = item.array("pose", shape=(3,), unit="m, m, rad")
        item.finish()
        placed.append(ScenePart(label, part, height, pose))
    scatter = f.sub("scatter", None)
    f.finish()
    if scatter is not None:
        placed += _scatter(scatter, placed, np.random.default_rng(seed))
    if not placed:
        raise ConfigError(f"{origin}: no parts (give 'parts' or 'scatter')")
    return Scene(tuple(placed), seed)


def _scatter(f: Fields, placed: list[ScenePart], rng: np.random.Generator) -> list[ScenePart]:
    count = f.integer("count", min_value=1, max_value=200)
    templates = {p.label: p for p in placed}
    types = f.raw("types", list(templates))
    if not isinstance(types, list) or not types or any(t not in templates for t in types):
        raise ConfigError(f"{f.key_path('types')}: expected labels of parts listed under 'parts' "
                          f"({', '.join(templates) or 'none listed'}), got {types!r}")
    region = f.array("region_m", [-0.09, 0.09, -0.09, 0.09], shape=(4,), unit="m")
    gap = f.number("min_gap_m", 0.01, min_value=0.0, unit="m")
    f.finish()
    out: list[ScenePart] = []
    poses = [p.pose for p in placed]
    radii = [p.radius_m for p in placed]
    for i in range(count):
        tmpl = templates[types[i % len(types)]]
        for _ in range(1000):
            xy = rng.uniform(region[[0, 2]], region[[1, 3]])
            if all(math.hypot(*(xy - q[:2])) >= r + tmpl.radius_m + gap for q, r in zip(poses, radii)):
                break
        else:
            raise ConfigError(f"{f.key_path('count')}: cannot place {count} parts {gap} m apart in {region.tolist()}")
        pose = np.array([xy[0], xy[1], rng.uniform(-math.pi, math.pi)])
        out.append(ScenePart(tmpl.label, tmpl.part, tmpl.height_m, pose))
        poses.append(pose)
        radii.append(tmpl.radius_m)
    return out


def load_scene(path: str | Path) -> Scene:
    data = load_yaml_file(path, "scene")
    try:
        return scene_from_dict(data, str(path))
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from exc


def separate(xy: np.ndarray, v: np.ndarray, radii: np.ndarray, active: np.ndarray, gap_m: float = 0.0,
             iterations: int = 4) -> np.ndarray:
    """Push overlapping bounding circles apart in place; returns the indices that were moved.

    Parameters
    ----------
    xy : (N, 2) positions (m), modified in place.
    v : (N, 2) velocities (m/s), modified in place: the approaching normal component is removed.
    radii : (N,) bounding-circle radii (m).
    active : (N,) bool, parts still on the plate (others are ignored).
    gap_m : extra clearance kept between circles.
    """
    xy = np.asarray(xy)
    moved: set[int] = set()
    idx = np.flatnonzero(active)
    for _ in range(iterations):
        any_overlap = False
        for a_pos, a in enumerate(idx):
            for b in idx[a_pos + 1:]:
                d = xy[b] - xy[a]
                dist = float(np.hypot(*d))
                need = radii[a] + radii[b] + gap_m
                if dist >= need:
                    continue
                any_overlap = True
                n = d / dist if dist > 1e-12 else np.array([1.0, 0.0])
                push = 0.5 * (need - dist)
                xy[a] -= push * n
                xy[b] += push * n
                rel = float(np.dot(v[b] - v[a], n))
                if rel < 0:  # approaching: remove the normal component, share it equally
                    v[a] += 0.5 * rel * n
                    v[b] -= 0.5 * rel * n
                moved.update((int(a), int(b)))
        if not any_overlap:
            break
    return np.array(sorted(moved), dtype=int)


__all__ = ["Scene", "ScenePart", "load_scene", "scene_from_dict", "separate"]

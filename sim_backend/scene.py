"""The parts on the simulated plate: the scene file, and how parts keep out of each other.

Scene file (YAML), strictly validated::

    seed: 7                                  # optional; scatter and camera noise
    parts:                                   # placed parts
      - label: washer                        # the part type the tracker knows (ppod_ros/data/tracker.yaml)
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
plate cycle :func:`separate` (:mod:`ppod_sim.separation`) pushes apart any two parts whose outlines
overlap: a simple, stated non-penetration model, not a contact-dynamics one.

- Shape: each outline is covered by a few circles along its long axis (one for a compact part,
  three for a slender bracket; :func:`circle_cover`), so a long part is not treated as the disc
  around it.
- Push: along the line of centres of the most deeply overlapping pair of circles, shared in
  inverse proportion to the parts' masses (a light washer that runs into a heavy bracket moves
  most of the way; friction holds the heavy part), and the approaching velocity removed with the
  same shares. Translation only: contacts exert no torque here.
- Mass: a rigid part's own; a point part's from its footprint area, its height and the density
  of steel (``DENSITY_KG_M3``).
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
from ppod_sim.separation import separate  # re-exported: where callers have always found it


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
    def mass_kg(self) -> float:
        """The rigid part's mass, or a point part's from footprint area x height x steel density."""
        if isinstance(self.part, RigidPart):
            return float(self.part.mass)
        fp = self.part.footprint or Footprint("disk", (0.002,))
        return float(fp.area_m2 * self.height_m * DENSITY_KG_M3)

    @property
    def circles(self) -> np.ndarray:
        """(K, 3) circles (x, y, r) in the body frame that cover the outline (:func:`circle_cover`)."""
        return circle_cover(self.outline)

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
    def masses_kg(self) -> np.ndarray:
        return np.array([p.mass_kg for p in self.parts])

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


DENSITY_KG_M3 = 7850.0  # steel: the mass of point parts, which the physics does not need otherwise


def _inside(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd test: which of ``points`` (M, 2) lie inside the polygon ``poly`` (K, 2)."""
    x, y = points[:, 0:1], points[:, 1:2]
    x0, y0 = poly[:, 0][None], poly[:, 1][None]
    x1, y1 = np.roll(poly[:, 0], -1)[None], np.roll(poly[:, 1], -1)[None]
    crosses = (y0 > y) != (y1 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_at = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
    return (crosses & (x < x_at)).sum(axis=1) % 2 == 1


def circle_cover(outline: np.ndarray, max_circles: int = 5) -> np.ndarray:
    """Circles (K, 3) (x, y, r) centred on the long axis of ``outline`` that cover all of it.

    K = the outline's length over its width, less 0.3, rounded up (at most ``max_circles``): one
    circle for a compact part. Centres are evenly spaced along the principal axis; each radius is
    the largest distance from its centre to the points of the outline (edges and a grid inside)
    nearer to it than to any other centre, plus the grid spacing, so nothing between the samples is
    left out.
    """
    poly = np.asarray(outline, dtype=float)
    nxt = np.roll(poly, -1, axis=0)
    t = np.linspace(0.0, 1.0, 32, endpoint=False)[:, None, None]
    edges = (poly[None] + t * (nxt - poly)[None]).reshape(-1, 2)
    lo_xy, hi_xy = poly.min(axis=0), poly.max(axis=0)
    h = float(np.max(hi_xy - lo_xy)) / 60.0
    gx, gy = np.meshgrid(np.arange(lo_xy[0], hi_xy[0] + h, h), np.arange(lo_xy[1], hi_xy[1] + h, h))
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    pts = np.concatenate([edges, grid[_inside(grid, poly)]])
    centre = edges.mean(axis=0)
    d = edges - centre
    _, vecs = np.linalg.eigh(d.T @ d)
    axis, across = vecs[:, 1], vecs[:, 0]
    along = (pts - centre) @ axis
    length = float(along.max() - along.min())
    width = max(float(np.ptp((pts - centre) @ across)), 1e-9)
    k = int(min(max_circles, max(1, math.ceil(length / width - 0.3))))
    if k == 1:
        return np.array([[0.0, 0.0, float(np.max(np.hypot(*poly.T)))]])  # the bounding circle
    lo, hi = along.min() + length / (2 * k), along.max() - length / (2 * k)
    centres = centre + np.linspace(lo, hi, k)[:, None] * axis
    dist = np.linalg.norm(pts[:, None, :] - centres[None], axis=2)
    nearest = dist.argmin(axis=1)
    radii = np.array([dist[nearest == j, j].max() if np.any(nearest == j) else 0.0 for j in range(k)]) + h
    return np.column_stack([centres, radii])


__all__ = ["DENSITY_KG_M3", "Scene", "ScenePart", "circle_cover", "load_scene", "scene_from_dict", "separate"]

"""Scripted part motions with ground truth, for the tracker's benchmark and tests.

:func:`make_scene` lays ``n`` parts of a few standard types on a grid in the work area and moves
each smoothly (Lissajous drift, steady turning with a wobble). Pairs of neighbours approach each
other head-on until their circumscribed circles are ``gap_m`` apart, then recede: the parts come
close but never overlap (which real parts cannot do), so every frame has an unambiguous truth.
Deterministic under ``seed``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.parts import Footprint
from ppod_ros.vision.shapes import PartSpec
from ppod_sim.camera.scene import RenderPart

#: Standard part types: a pin, a trapezoid tab (no symmetry), a washer, a square tile, a hexagon.
STANDARD_PARTS: tuple[PartSpec, ...] = (
    PartSpec("pin", Footprint.from_value({"rect": [0.008, 0.024]}), 0.004),
    PartSpec(
        "tab",
        Footprint.from_value(
            {"polygon": [[-0.010, -0.006], [0.010, -0.006], [0.005, 0.006], [-0.005, 0.006]]}
        ),
        0.003,
    ),
    PartSpec("washer", Footprint.from_value({"disk": 0.006}), 0.002),
    PartSpec("tile", Footprint.from_value({"rect": [0.014, 0.014]}), 0.003),
    PartSpec(
        "hex",
        Footprint.from_value(
            {
                "polygon": [
                    [0.008 * math.cos(k * math.pi / 3), 0.008 * math.sin(k * math.pi / 3)] for k in range(6)
                ]
            }
        ),
        0.003,
    ),
)


def circumradius(spec: PartSpec) -> float:
    """Largest distance (m) of the outline from the body origin (the pose's point)."""
    fp = spec.footprint
    if fp.kind == "disk":
        return fp.size[0]
    return float(np.max(np.hypot(*fp.outline().T)))


@dataclass(frozen=True)
class _Motion:
    home: tuple[float, float]
    amp: tuple[float, float]
    freq_hz: tuple[float, float]
    phase: tuple[float, float]
    theta0: float
    omega_radps: float
    wobble_rad: float
    approach_m: float  # > 0: moves +x toward a partner; < 0: moves -x toward it
    approach_hz: float


@dataclass(frozen=True)
class Scene:
    """Parts and their scripted motions; :meth:`poses` and :meth:`render_parts` at time t (s)."""

    specs: tuple[PartSpec, ...]
    motions: tuple[_Motion, ...]

    def poses(self, t_s: float) -> np.ndarray:
        """(n, 3) poses (x_m, y_m, theta_rad) at ``t_s``."""
        out = np.empty((len(self.motions), 3))
        for i, m in enumerate(self.motions):
            x = m.home[0] + m.amp[0] * math.sin(2 * math.pi * m.freq_hz[0] * t_s + m.phase[0])
            y = m.home[1] + m.amp[1] * math.sin(2 * math.pi * m.freq_hz[1] * t_s + m.phase[1])
            # Approach: 0 at t = 0, the full distance at half a period, smooth in between.
            x += m.approach_m * 0.5 * (1 - math.cos(2 * math.pi * m.approach_hz * t_s))
            th = m.theta0 + m.omega_radps * t_s + m.wobble_rad * math.sin(1.3 * t_s + i)
            out[i] = (x, y, th)
        return out

    def render_parts(self, t_s: float) -> list[RenderPart]:
        return [
            RenderPart.of(s.label, s.footprint, tuple(p), s.height_m)
            for s, p in zip(self.specs, self.poses(t_s))
        ]

    def min_clearance_m(self, t_s: float) -> float:
        """Smallest distance between circumscribed circles at ``t_s`` (> 0: no two parts overlap)."""
        p = self.poses(t_s)
        r = np.array([circumradius(s) for s in self.specs])
        best = math.inf
        for i in range(len(p)):
            for j in range(i + 1, len(p)):
                best = min(best, math.hypot(*(p[i, :2] - p[j, :2])) - r[i] - r[j])
        return best


def make_scene(
    n: int,
    seed: int = 0,
    work_area_m: tuple[float, float, float, float] = (-0.125, 0.125, -0.125, 0.125),
    gap_m: float = 0.001,
    kinds: tuple[PartSpec, ...] = STANDARD_PARTS,
    approach: bool = True,
) -> Scene:
    """``n`` parts (1..30) on a grid in the work area, pairs approaching to ``gap_m``.

    Speeds are up to about 2 cm/s and turning rates up to about 0.6 rad/s, typical of parts on a
    vibrating plate.
    """
    if not 1 <= n <= 30:
        raise ConfigError(f"n: expected 1..30 parts, got {n}")
    rng = np.random.default_rng(seed)
    x0, x1, y0, y1 = work_area_m
    cols = max(1, math.ceil(math.sqrt(n * 1.25)))
    rows = math.ceil(n / cols)
    r_max = max(circumradius(k) for k in kinds)
    amp = 0.006
    margin = r_max + amp + 0.003
    xs = np.linspace(x0 + margin, x1 - margin, cols) if cols > 1 else np.array([(x0 + x1) / 2])
    ys = np.linspace(y0 + margin, y1 - margin, rows) if rows > 1 else np.array([(y0 + y1) / 2])
    spacing = xs[1] - xs[0] if cols > 1 else math.inf
    if spacing < 2 * (r_max + amp) + gap_m:
        raise ConfigError(f"n: {n} parts do not fit the work area with room to move")
    specs, motions = [], []
    for i in range(n):
        r, c = divmod(i, cols)
        spec = kinds[i % len(kinds)]
        specs.append(spec)
        partner = i + 1 if c % 2 == 0 else i - 1
        paired = approach and 0 <= partner < n and partner // cols == r and (c % 2 == 0 or c - 1 >= 0)
        if paired:
            other = kinds[partner % len(kinds)]
            # Close the gap between circumscribed circles down to gap_m, each part going half way.
            travel = (spacing - circumradius(spec) - circumradius(other) - gap_m) / 2
            approach_m = travel if c % 2 == 0 else -travel
            amp_xy = (0.0, 0.002)
            phase_y = 0.0  # partners drift together in y so they meet head-on
        else:
            approach_m = 0.0
            amp_xy = (amp, amp)
            phase_y = float(rng.uniform(0, 2 * math.pi))
        motions.append(
            _Motion(
                home=(float(xs[c]), float(ys[r])),
                amp=amp_xy,
                freq_hz=(float(rng.uniform(0.05, 0.12)), 0.07 if paired else float(rng.uniform(0.05, 0.12))),
                phase=(float(rng.uniform(0, 2 * math.pi)), phase_y),
                theta0=float(rng.uniform(-math.pi, math.pi)),
                omega_radps=float(rng.choice([-1, 1]) * rng.uniform(0.1, 0.6)),
                wobble_rad=float(rng.uniform(0.0, 0.3)),
                approach_m=approach_m,
                approach_hz=0.1,
            )
        )
    return Scene(tuple(specs), tuple(motions))


__all__ = ["STANDARD_PARTS", "Scene", "circumradius", "make_scene"]

"""The demo's picture and animation: part trajectories over the asymptotic field of the motions.

ROS-free (matplotlib Agg, Pillow for the GIF). The field shown is that of a point part with the
demo's friction under the plate motion that was active (computed with ppod_ros.physics, cached per
motion); parts are drawn with their outlines at their true poses. The picture has a legend for the
paths, outlines, goal, collection point and working disc, and an arrow-scale key; axes are in mm.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ppod_ros.motion import PlateMotion
from ppod_ros.parts import PointPart

PLATE_HALF_M = 0.1
WORKING_DISC_M = 0.08  # radius where the demo's motions keep parts in contact (device.yaml limits)
#: The fastest field arrow is drawn this long (m), in every frame: arrows compare across frames.
LONGEST_ARROW_M = 0.015


class FieldCache:
    """Asymptotic point-part fields on a coarse grid, one per motion (by its physical key)."""

    def __init__(self, mu: float = 0.3, n: int = 15, half_m: float = 0.09):
        self.part = PointPart(mu=mu)
        self.xs = np.linspace(-half_m, half_m, n)
        self._fields: dict[object, np.ndarray] = {}

    def field(self, motion: PlateMotion | None) -> np.ndarray | None:
        """(n, n, 2) velocities (NaN where contact is lost), x along axis 1; None for no motion."""
        if motion is None:
            return None
        if motion.key not in self._fields:
            from ppod_ros.physics import solve_field

            X, Y = np.meshgrid(self.xs, self.xs)
            r = solve_field(motion, self.part, np.column_stack([X.ravel(), Y.ravel()]))
            self._fields[motion.key] = np.asarray(r.velocity, dtype=float)[:, :2].reshape(X.shape + (2,))
        return self._fields[motion.key]


def _outline(part, pose: np.ndarray) -> np.ndarray | None:
    fp = getattr(part, "footprint", None)
    pts = fp.outline() if fp is not None else (part.outline() if hasattr(part, "outline") else None)
    if pts is None:
        return None
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.asarray(pts)[:, :2] @ np.array([[c, s], [-s, c]]) + pose[:2]


def _nice(x: float) -> float:
    """A round number near ``x`` (1, 2 or 5 times a power of ten) for the arrow-scale key."""
    exp = math.floor(math.log10(x))
    return min((1, 2, 5, 10), key=lambda m: abs(m * 10**exp - x)) * 10**exp


def _draw_field(ax, cache: FieldCache, motion: PlateMotion | None, key: bool = True):
    """The field's quiver (None at rest), with an arrow-scale key."""
    v = cache.field(motion)
    if v is None:
        ax.text(0.0, 0.095, "plate at rest", ha="center", va="top", fontsize=8, color="0.4")
        return None
    X, Y = np.meshgrid(cache.xs, cache.xs)
    speed = np.hypot(v[..., 0], v[..., 1])
    finite = speed[np.isfinite(speed)]
    vmax = float(finite.max()) if finite.size and finite.max() > 0 else 1e-3
    q = ax.quiver(X, Y, v[..., 0], v[..., 1], speed, cmap="Blues", alpha=0.8, angles="xy", width=0.004,
                  scale=vmax / LONGEST_ARROW_M, scale_units="xy")
    if key:
        k = _nice(vmax)
        ax.quiverkey(q, 0.02, 1.015, k, f"field: {k * 1000:g} mm/s", labelpos="E", coordinates="axes",
                     fontproperties={"size": 7})
    bad = ~np.isfinite(speed)
    if bad.any():
        ax.plot(X[bad], Y[bad], "x", color="0.6", ms=3, label="contact lost")
    return q


def _frame_axes(ax, title: str, fontsize: float = 9) -> None:
    ax.set_xlim(-PLATE_HALF_M, PLATE_HALF_M)
    ax.set_ylim(-PLATE_HALF_M, PLATE_HALF_M)
    ax.set_aspect("equal")
    # Millimetres, five ticks: labels that never overlap, even in the small GIF frames.
    ticks = np.linspace(-PLATE_HALF_M, PLATE_HALF_M, 5)
    labels = [f"{1000 * v:.0f}" for v in ticks]
    ax.set_xticks(ticks, labels, fontsize=fontsize - 1)
    ax.set_yticks(ticks, labels, fontsize=fontsize - 1)
    ax.set_xlabel("x (mm)", fontsize=fontsize)
    ax.set_ylabel("y (mm)", fontsize=fontsize)
    ax.set_title(title, fontsize=fontsize, loc="right")
    from matplotlib.patches import Circle

    ax.add_patch(Circle((0, 0), WORKING_DISC_M, fill=False, ls=":", color="0.5", lw=0.8))


def _draw_parts(ax, parts, poses: np.ndarray, chosen: int, alpha: float = 1.0) -> None:
    for i, (part, pose) in enumerate(zip(parts, poses)):
        color = "tab:red" if i == chosen else "tab:gray"
        pts = _outline(part, pose)
        if pts is not None:
            ax.fill(pts[:, 0], pts[:, 1], color=color, alpha=0.6 * alpha, lw=0)
        ax.plot(pose[0], pose[1], ".", color=color, ms=3, alpha=alpha)


def _draw_goal(ax, goal, collect) -> None:
    ax.plot(goal[0], goal[1], "+", color="tab:green", ms=14, mew=2, label="goal")
    if goal[2] is not None:
        ax.arrow(goal[0], goal[1], 0.012 * math.cos(goal[2]), 0.012 * math.sin(goal[2]),
                 color="tab:green", width=0.0006, head_width=0.003, length_includes_head=True)
    if collect is not None:
        ax.plot(collect[0], collect[1], "o", mfc="none", color="tab:purple", ms=14, mew=1.5, label="collect")


def _legend_handles(collect: bool, field: bool) -> list:
    """Proxy artists: what every line, outline, marker and circle of the picture means."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [Line2D([], [], color="tab:red", lw=1.2, label="path of the moved part"),
               Line2D([], [], color="tab:gray", lw=0.8, label="paths of the other parts"),
               Patch(color="tab:red", alpha=0.18, label="outlines at the start (faint)"),
               Patch(color="tab:red", alpha=0.6, label="outlines at the end"),
               Line2D([], [], color="tab:green", marker="+", ls="", ms=10, mew=2, label="goal (arrow: orientation)"),
               Line2D([], [], color="0.5", ls=":", lw=0.8,
                      label=f"working disc (r = {WORKING_DISC_M * 1000:.0f} mm)")]
    if collect:
        handles.append(Line2D([], [], color="tab:purple", marker="o", mfc="none", ls="", ms=10,
                              label="collection point"))
    if field:
        handles.append(Line2D([], [], color="tab:blue", marker=r"$\rightarrow$", ls="", ms=10,
                              label="field of a point part (colour: speed)"))
    return handles


def picture_figure(t: np.ndarray, poses: np.ndarray, parts, chosen: int, goal, collect,
                   final_motion: PlateMotion | None, cache: FieldCache, title: str):
    """The demo picture as a matplotlib Figure (see :func:`write_picture`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 7))
    _draw_field(ax, cache, final_motion)
    for i in range(poses.shape[1]):
        color = "tab:red" if i == chosen else "tab:gray"
        ax.plot(poses[:, i, 0], poses[:, i, 1], "-", color=color, lw=1.2 if i == chosen else 0.8)
    _draw_parts(ax, parts, poses[0], chosen, alpha=0.3)
    _draw_parts(ax, parts, poses[-1], chosen)
    _draw_goal(ax, goal, collect)
    _frame_axes(ax, title)
    ax.legend(handles=_legend_handles(collect is not None, final_motion is not None), loc="lower right",
              fontsize=7, framealpha=0.9)
    fig.tight_layout()
    return fig


def write_picture(path: Path, t: np.ndarray, poses: np.ndarray, parts, chosen: int, goal, collect,
                  final_motion: PlateMotion | None, cache: FieldCache, title: str) -> None:
    """Trajectories (T, N, 3) over the field of ``final_motion``; start and end outlines."""
    import matplotlib.pyplot as plt

    fig = picture_figure(t, poses, parts, chosen, goal, collect, final_motion, cache, title)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_animation(path: Path, t: np.ndarray, poses: np.ndarray, parts, chosen: int, goal, collect,
                    motion_at, cache: FieldCache, frame_dt_s: float = 0.5, fps: int = 8,
                    phase_at=None) -> int:
    """A GIF: one frame every ``frame_dt_s`` of device time. Returns the number of frames."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import PillowWriter

    times = np.arange(t[0], t[-1] + 1e-9, frame_dt_s)
    fig, ax = plt.subplots(figsize=(4.8, 4.8))
    writer = PillowWriter(fps=fps)
    with writer.saving(fig, str(path), dpi=80):
        for tf in times:
            j = int(np.searchsorted(t, tf, side="right")) - 1
            ax.clear()
            _draw_field(ax, cache, motion_at(tf), key=False)
            for i in range(poses.shape[1]):
                color = "tab:red" if i == chosen else "tab:gray"
                ax.plot(poses[: j + 1, i, 0], poses[: j + 1, i, 1], "-", color=color, lw=0.8)
            _draw_parts(ax, parts, poses[j], chosen)
            _draw_goal(ax, goal, collect)
            phase = phase_at(tf) if phase_at is not None else ""
            _frame_axes(ax, f"t = {tf - t[0]:5.1f} s  {phase}", fontsize=8)
            writer.grab_frame()
    plt.close(fig)
    return len(times)


def write_multi_picture(path: Path, t: np.ndarray, poses: np.ndarray, parts, goals, final_motion: PlateMotion | None,
                        cache: FieldCache, title: str) -> None:
    """Several parts, each to its own goal: every commanded part's path (T, N, 3 ground truth) in
    its own colour to its goal ``(index, x, y, theta or None)``, over the field of the last motion;
    uncommanded parts in grey."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    fig, ax = plt.subplots(figsize=(7, 7))
    _draw_field(ax, cache, final_motion)
    commanded = {g[0]: colors[k % len(colors)] for k, g in enumerate(goals)}
    for i in range(poses.shape[1]):
        color = commanded.get(i, "tab:gray")
        ax.plot(poses[:, i, 0], poses[:, i, 1], "-", color=color, lw=1.2 if i in commanded else 0.6)
        for pose, alpha in ((poses[0, i], 0.3), (poses[-1, i], 1.0)):
            pts = _outline(parts[i], pose)
            if pts is not None:
                ax.fill(pts[:, 0], pts[:, 1], color=color, alpha=0.6 * alpha, lw=0)
    for index, x, y, theta in goals:
        color = commanded[index]
        ax.plot(x, y, "+", color=color, ms=14, mew=2)
        if theta is not None:
            ax.arrow(x, y, 0.012 * math.cos(theta), 0.012 * math.sin(theta), color=color, width=0.0006,
                     head_width=0.003, length_includes_head=True)
    _frame_axes(ax, title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)

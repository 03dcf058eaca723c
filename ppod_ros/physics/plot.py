"""Plots of asymptotic fields (matplotlib, headless Agg): quivers with invalid configurations marked.

Point parts: one quiver of (vx, vy) over the x-y grid, coloured by speed. Rigid parts: x-y slices at
up to four angles (quiver of (Vx, Vy), coloured by the yaw rate) and a theta profile of the twist at
the grid point nearest the grid's centre. Invalid configurations are red crosses. The title names
the motion (``PlateMotion.describe``).
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion
from ppod_ros.physics.field import FieldResult


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def plot_field(result: FieldResult, motion: PlateMotion, path: str | Path, *, part_label: str = "") -> Path:
    """Save a plot of ``result`` (computed for ``motion``) as an image at ``path``; returns the path."""
    plt = _pyplot()
    path = Path(path)
    title = "\n".join(textwrap.wrap(motion.describe(), 90))
    if part_label:
        title += f"\n{part_label}"
    if result.part_kind == "point":
        fig, ax = plt.subplots(figsize=(7.5, 7))
        _quiver(ax, result.configs[:, 0], result.configs[:, 1], result.velocity[:, 0], result.velocity[:, 1],
                np.hypot(result.velocity[:, 0], result.velocity[:, 1]), result.valid, "speed (m/s)", fig)
        ax.set_title(title, fontsize=8)
    else:
        thetas = np.unique(result.configs[:, 2])
        pick = thetas[np.linspace(0, len(thetas) - 1, min(4, len(thetas))).round().astype(int)]
        fig, axes = plt.subplots(1, len(pick) + 1, figsize=(4.2 * (len(pick) + 1), 4.6), squeeze=False)
        axes = axes[0]
        for ax, th in zip(axes, pick):
            sel = np.isclose(result.configs[:, 2], th)
            v = result.velocity[sel]
            _quiver(ax, result.configs[sel, 0], result.configs[sel, 1], v[:, 0], v[:, 1], v[:, 2],
                    result.valid[sel], "yaw rate (rad/s)", fig)
            ax.set_title(f"theta = {th:.3f} rad", fontsize=9)
        _theta_profile(axes[-1], result)
        fig.suptitle(title, fontsize=8)
    try:
        fig.tight_layout()
        fig.savefig(path, dpi=110)
    except OSError as exc:
        raise ConfigError(f"--plot {path}: cannot write: {exc.strerror or exc}") from exc
    finally:
        plt.close(fig)
    return path


def _quiver(ax, x, y, u, v, colour, valid, label, fig) -> None:
    ok = valid & np.isfinite(u) & np.isfinite(v)
    if ok.any():
        q = ax.quiver(x[ok], y[ok], u[ok], v[ok], colour[ok], cmap="viridis", angles="xy", pivot="mid")
        fig.colorbar(q, ax=ax, label=label, shrink=0.8)
    if (~valid).any():
        ax.plot(x[~valid], y[~valid], "x", color="red", markersize=4, label="invalid")
        ax.legend(loc="upper right", fontsize=7)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal", adjustable="box")


def _theta_profile(ax, result: FieldResult) -> None:
    xy = result.configs[:, :2]
    centre = 0.5 * (xy.min(axis=0) + xy.max(axis=0))
    best = xy[np.argmin(np.hypot(*(xy - centre).T))]
    sel = np.all(np.isclose(xy, best), axis=1)
    th = result.configs[sel, 2]
    order = np.argsort(th)
    v = result.velocity[sel][order]
    ax.plot(th[order], v[:, 2], "o-", label="yaw rate (rad/s)")
    ax.plot(th[order], v[:, 0] * 10, "s--", label="Vx x 10 (m/s)")
    ax.plot(th[order], v[:, 1] * 10, "^--", label="Vy x 10 (m/s)")
    bad = ~result.valid[sel][order]
    if bad.any():
        ax.plot(th[order][bad], np.zeros(bad.sum()), "x", color="red", label="invalid")
    ax.axhline(0.0, color="grey", lw=0.5)
    ax.set_xlabel("theta (rad)")
    ax.set_title(f"theta profile at x = {best[0]:.3g} m, y = {best[1]:.3g} m", fontsize=9)
    ax.legend(fontsize=7)


__all__ = ["plot_field"]

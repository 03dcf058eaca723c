"""Plots of asymptotic fields (matplotlib, headless Agg): quivers with invalid configurations marked.

Point parts: one quiver of (vx, vy) over the x-y grid, coloured by speed. Rigid parts: x-y slices at
up to four angles (quiver of (Vx, Vy), coloured by the yaw rate) and a theta profile of the twist at
the grid point nearest the grid's centre. The slices share one arrow scale (a key shows it) and one
colour scale, symmetric about zero (one colour bar), so panels compare directly and a slice whose
yaw rate is only solver noise stays neutral; angles are in degrees. Invalid configurations are red
crosses. The title names the motion (``PlateMotion.describe``).
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
        fig = _rigid_figure(plt, result)
        fig.suptitle(title, fontsize=8)
    try:
        if result.part_kind == "point":
            fig.tight_layout()
        fig.savefig(path, dpi=110)
    except OSError as exc:
        raise ConfigError(f"--plot {path}: cannot write: {exc.strerror or exc}") from exc
    finally:
        plt.close(fig)
    return path


#: Yaw rates below this (deg/s) are solver noise for the colour scale (a still slice stays neutral).
YAW_NOISE_DEG_S = 1e-3


def _rigid_figure(plt, result: FieldResult):
    """Up to four x-y slices (2 x 2) sharing arrow and colour scales, and the theta profile."""
    from matplotlib.colors import Normalize

    thetas = np.unique(result.configs[:, 2])
    pick = thetas[np.linspace(0, len(thetas) - 1, min(4, len(thetas))).round().astype(int)]
    fig = plt.figure(figsize=(11.0, 7.4), layout="constrained")
    grid = fig.add_gridspec(2, 3, width_ratios=[1, 1, 1.15])
    slices = [fig.add_subplot(grid[i // 2, i % 2]) for i in range(len(pick))]
    ok = result.valid & np.all(np.isfinite(result.velocity), axis=1)
    yaw_deg = np.degrees(result.velocity[:, 2])
    top = float(np.max(np.abs(yaw_deg[ok]))) if ok.any() else 0.0
    norm = Normalize(-max(top, YAW_NOISE_DEG_S), max(top, YAW_NOISE_DEG_S))
    speed = np.hypot(result.velocity[ok, 0], result.velocity[ok, 1])
    vmax = float(speed.max()) if speed.size and speed.max() > 0 else 1e-3
    span = float(np.ptp(result.configs[:, 0])) or 0.1
    scale = vmax / (0.12 * span)  # the fastest arrow is 12 % of the grid's width, in every slice
    mappable = None
    for ax, th in zip(slices, pick):
        sel = np.isclose(result.configs[:, 2], th)
        v = result.velocity[sel]
        good = ok[sel]
        if good.any():
            mappable = ax.quiver(result.configs[sel, 0][good], result.configs[sel, 1][good], v[good, 0], v[good, 1],
                                 yaw_deg[sel][good], cmap="coolwarm", norm=norm, angles="xy", pivot="mid",
                                 scale=scale, scale_units="xy")
        bad = ~result.valid[sel]
        if bad.any():
            ax.plot(result.configs[sel, 0][bad], result.configs[sel, 1][bad], "x", color="red", markersize=4,
                    label="invalid")
            ax.legend(loc="upper right", fontsize=7)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_aspect("equal", adjustable="box")
        ax.set_title(f"theta = {np.degrees(th):.0f} deg", fontsize=9)
    if mappable is not None:
        key = _nice(vmax)
        slices[0].quiverkey(mappable, 0.03, 0.015, key, f"arrow scale: {key * 1000:g} mm/s", labelpos="E",
                            coordinates="figure", fontproperties={"size": 8})
        fig.colorbar(mappable, ax=slices, label="yaw rate (deg/s)", shrink=0.85)
    _theta_profile(fig.add_subplot(grid[:, 2]), result)
    return fig


def _nice(x: float) -> float:
    """A round number near ``x`` (1, 2 or 5 times a power of ten) for a scale key."""
    exp = np.floor(np.log10(x))
    return float(min((1, 2, 5, 10), key=lambda m: abs(m * 10**exp - x)) * 10**exp)


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
    deg = np.degrees(th[order])
    ax.plot(deg, np.degrees(v[:, 2]), "o-", label="yaw rate (deg/s)")
    ax.plot(deg, v[:, 0] * 1000, "s--", label="Vx (mm/s)")
    ax.plot(deg, v[:, 1] * 1000, "^--", label="Vy (mm/s)")
    bad = ~result.valid[sel][order]
    if bad.any():
        ax.plot(deg[bad], np.zeros(bad.sum()), "x", color="red", label="invalid")
    ax.axhline(0.0, color="grey", lw=0.5)
    ax.set_xlabel("theta (deg)")
    ax.set_title(f"theta profile at x = {best[0]:.3g} m, y = {best[1]:.3g} m", fontsize=9)
    ax.legend(fontsize=7)


__all__ = ["plot_field"]

"""Rigid-part field plots: one colour scale and one arrow scale across the slices, angles in degrees."""

import numpy as np
import pytest


@pytest.fixture(scope="module")
def rigid_result():
    from ppod_ros.motion import PlateMotion
    from ppod_ros.parts import load_part
    from ppod_ros.physics.field import grid_configs, solve_field

    root = __import__("pathlib").Path(__file__).parents[2]
    motion = PlateMotion.from_yaml(root / "ppod_ros" / "data" / "motions" / "RigidU1.yaml")
    part = load_part(root / "config" / "parts" / "published_rigid.yaml")
    configs = grid_configs(np.linspace(-0.04, 0.04, 3), np.linspace(-0.04, 0.04, 3),
                           np.radians([0.0, 90.0, 225.0, 315.0]))
    return motion, solve_field(motion, part, configs)


def test_rigid_slices_share_one_symmetric_colour_scale_and_one_arrow_scale(rigid_result):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.quiver import Quiver

    from ppod_ros.physics.plot import _rigid_figure

    _, result = rigid_result
    fig = _rigid_figure(plt, result)
    try:
        quivers = [c for ax in fig.axes for c in ax.collections if isinstance(c, Quiver)]
        assert len(quivers) == 4
        limits = {(q.norm.vmin, q.norm.vmax) for q in quivers}
        assert len(limits) == 1
        vmin, vmax = limits.pop()
        assert vmin == -vmax and vmax == pytest.approx(np.degrees(np.nanmax(np.abs(result.velocity[:, 2]))))
        assert len({q.scale for q in quivers}) == 1
        titles = [ax.get_title() for ax in fig.axes]
        assert "theta = 225 deg" in titles and not any("rad" in t for t in titles)
        colourbars = [ax for ax in fig.axes if ax.get_ylabel() == "yaw rate (deg/s)"]
        assert len(colourbars) == 1
    finally:
        plt.close(fig)


def test_the_plot_is_written_and_compact(rigid_result, tmp_path):
    from PIL import Image

    from ppod_ros.physics.plot import plot_field

    motion, result = rigid_result
    path = plot_field(result, motion, tmp_path / "rigid.png")
    width, height = Image.open(path).size
    assert width <= 1400 and height <= 1000

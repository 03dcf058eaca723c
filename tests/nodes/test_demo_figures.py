"""The demo picture explains itself (legend, arrow-scale key) and its axes stay legible in the GIF."""

import numpy as np
import pytest

from ppod_nodes.demo.figures import FieldCache, _frame_axes, picture_figure
from ppod_ros.motion import PlateMotion
from ppod_sim.ros_node import default_scene_path
from ppod_sim.scene import load_scene

pytestmark = pytest.mark.ros  # ppod_sim.ros_node imports rclpy

LINESINKX = PlateMotion.from_yaml_text(
    "name: LineSinkX\nfrequency_hz: 30\nharmonics:\n"
    "  - {k: 1, amplitude: [10, 0, 0, 0, 100, 0], phase: [0, 0, 0, 0, 4.71238898, 0]}\n")


def test_the_picture_has_a_legend_for_paths_outlines_goal_and_disc_and_an_arrow_key():
    import matplotlib.pyplot as plt
    from matplotlib.quiver import QuiverKey

    scene = load_scene(default_scene_path())
    t = np.linspace(0.0, 2.0, 11)
    poses = scene.poses[None] * (1 - t[:, None, None] / 4)
    fig = picture_figure(t, poses, [p.part for p in scene.parts], 0, (0.02, -0.02, 0.0), (-0.03, 0.03),
                         LINESINKX, FieldCache(n=7), "test")
    try:
        ax = fig.axes[0]
        labels = [text.get_text() for text in ax.get_legend().get_texts()]
        for words in ("path of the moved part", "paths of the other parts", "outlines at the start",
                      "outlines at the end", "goal", "working disc", "collection point", "field"):
            assert any(words in label for label in labels), (words, labels)
        keys = [a for a in ax.get_children() if isinstance(a, QuiverKey)]
        assert len(keys) == 1 and "mm/s" in keys[0].text.get_text()
    finally:
        plt.close(fig)


def test_small_frames_have_tick_labels_that_do_not_overlap():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4.8, 4.8), dpi=80)
    try:
        _frame_axes(ax, "t = 1.0 s", fontsize=8)
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        for labels in (ax.get_xticklabels(), ax.get_yticklabels()):
            boxes = [label.get_window_extent(renderer) for label in labels if label.get_text()]
            assert len(boxes) == 5
            for a, b in zip(boxes, boxes[1:]):
                assert not a.overlaps(b)
        assert ax.get_xlabel() == "x (mm)"
    finally:
        plt.close(fig)

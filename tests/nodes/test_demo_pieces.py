"""The demo's ROS-free pieces: argument checks, the picture and the animation."""

import math

import numpy as np
import pytest

from ppod_nodes.cli.demo import _choose, _goal
from ppod_nodes.demo.figures import FieldCache, write_animation, write_picture
from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion
from ppod_sim.ros_node import default_scene_path
from ppod_sim.scene import load_scene

LINESINKX = PlateMotion.from_yaml_text(
    "name: LineSinkX\nfrequency_hz: 30\nharmonics:\n"
    "  - {k: 1, amplitude: [10, 0, 0, 0, 100, 0], phase: [0, 0, 0, 0, 4.71238898, 0]}\n")


def test_the_demo_finds_the_chosen_part_by_label_or_index_and_names_the_choices_otherwise():
    scene = load_scene(default_scene_path())
    assert scene.parts[_choose(scene, "bracket")].label == "bracket"
    assert _choose(scene, "2") == 2
    with pytest.raises(ConfigError, match="no part labelled 'gear'.*bracket"):
        _choose(scene, "gear")
    with pytest.raises(ConfigError, match="index 99"):
        _choose(scene, "99")


def test_demo_goals_are_checked_and_theta_is_kept_only_for_rigid_parts():
    assert _goal([0.01, 0.02, 90.0], rigid=True) == (0.01, 0.02, pytest.approx(math.pi / 2))
    assert _goal([0.01, 0.02, 90.0], rigid=False) == (0.01, 0.02, None)
    with pytest.raises(ConfigError, match="outside the working disc"):
        _goal([0.09, 0.0], rigid=False)
    with pytest.raises(ConfigError, match="X Y"):
        _goal([0.01], rigid=False)
    with pytest.raises(ConfigError, match="finite"):
        _goal([float("nan"), 0.0], rigid=False)


def test_the_field_cache_computes_the_linesink_field_once_per_motion():
    cache = FieldCache(n=9, half_m=0.06)
    v = cache.field(LINESINKX)
    assert v.shape == (9, 9, 2)
    # LineSinkX pulls parts towards x = 0 (PHYSICS.md: v_x about -0.28 x).
    assert np.nanmean(v[:, -1, 0]) < 0 < np.nanmean(v[:, 0, 0])
    assert cache.field(LINESINKX) is v
    assert cache.field(None) is None


def test_the_picture_and_the_animation_are_written(tmp_path):
    scene = load_scene(default_scene_path())
    parts = [p.part for p in scene.parts]
    t = np.linspace(0.0, 2.0, 21)
    start = scene.poses
    poses = start[None] * (1 - t[:, None, None] / 4)
    cache = FieldCache(n=7)
    write_picture(tmp_path / "demo.png", t, poses, parts, 0, (0.02, -0.02, 0.0), (-0.03, 0.03), LINESINKX, cache,
                  "test")
    n = write_animation(tmp_path / "demo.gif", t, poses, parts, 0, (0.02, -0.02, 0.0), None,
                        lambda tf: LINESINKX if tf > 1.0 else None, cache, frame_dt_s=0.5)
    assert n == 5
    png, gif = (tmp_path / "demo.png").read_bytes(), (tmp_path / "demo.gif").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    assert gif[:6] in (b"GIF87a", b"GIF89a")


def test_the_multi_goal_summary_follows_the_ground_truth(tmp_path):
    import json

    from ppod_nodes.cli.demo_multi import goals_for_scene, summarize
    from ppod_nodes.demo.figures import write_multi_picture

    scene = load_scene(default_scene_path())
    goals = goals_for_scene(scene, None)  # the default set: the bracket, oriented, and the two washers
    assert [g["label"] for g in goals] == ["bracket", "washer", "washer"]
    assert goals[0]["theta_rad"] == 0.0 and goals[1]["theta_rad"] is None and goals[1]["index"] != goals[2]["index"]
    t = np.arange(0.0, 10.01, 0.1)
    poses = np.repeat(scene.poses[None], len(t), axis=0)
    for g in goals:  # each commanded part arrives at its goal at t = 5 s; the second never quite does
        arrive = t >= 5.0
        poses[arrive, g["index"], 0], poses[arrive, g["index"], 1] = g["x"], g["y"]
        poses[arrive, g["index"], 2] = 0.0
    poses[:, goals[2]["index"], 0] += 0.003 * (t >= 5.0)
    s = summarize(goals, [p.part for p in scene.parts], t, poses, 1.0, 9.0, 1.5)
    assert s["all_reached"] is False and s["device_time_s"] == 9.0 and s["real_time_factor"] == 1.5
    assert [e["index"] for e in s["parts"]] == [g["index"] for g in goals]  # one entry per goal, in order
    first, _second, third = s["parts"]
    assert first["reached"] and first["time_to_goal_s"] == pytest.approx(4.0) and first["angle_error_deg"] == 0.0
    assert first["goal"] == [0.02, -0.02, 0.0] and len(first["final"]) == 3
    assert not third["reached"] and third["time_to_goal_s"] is None and third["angle_error_deg"] is None
    assert third["position_error_m"] == pytest.approx(0.003)
    json.dumps(s)  # JSON as it stands
    write_multi_picture(tmp_path / "multi.png", t, poses, [p.part for p in scene.parts],
                        [(g["index"], g["x"], g["y"], g["theta_rad"]) for g in goals], LINESINKX, FieldCache(n=7),
                        "test")
    assert (tmp_path / "multi.png").stat().st_size > 1000


def test_the_demo_s_progress_names_each_part_as_the_demo_does_not_by_track_or_planner_row():
    from types import SimpleNamespace

    from ppod_nodes.cli.demo_multi import goals_for_scene, progress_line

    scene = load_scene(default_scene_path())
    goals = goals_for_scene(scene, None)   # #0 bracket (oriented), then the two washers
    ids = [4, 3, 2]                        # their track ids, in the goals' order
    # The planner reports in its own order (here the tracks' rows); orientation 0 for position-only goals.
    fb = SimpleNamespace(phase="moving", part_ids=[3, 4, 2], position_error_m=[0.0292, 0.0361, 0.0005],
                         orientation_error_rad=[0.0, math.radians(51.6), 0.0], within=[False, False, True])
    line = progress_line(goals, ids, fb)
    w1, w2 = goals[1]["index"], goals[2]["index"]
    assert line == (f"moving: #{w1} (washer) 29.2 mm, #0 (bracket) 36.1 mm +51.6 deg, "
                    f"#{w2} (washer) 0.5 mm ok")


def test_the_planner_node_s_texts_name_parts_by_track_id():
    from ppod_nodes.field_planner import _track_names
    from ppod_ros.parts import PointPart
    from ppod_ros.planning.mpc import MultiTask, PartGoal

    parts = [PointPart(0.3), PointPart(0.3)]
    goals = [PartGoal(1, 0.02, 0.0, None, 2e-3)]
    poses = np.array([[-0.03, 0.03, 0.0], [0.02, 0.0, 0.0]])   # the commanded part already at its goal
    task = MultiTask(parts, goals, timeout_s=10.0, names=_track_names([7, 9]))
    step = task.step(0.0, poses)
    assert "track 9 0.0 mm" in step.text and "#1" not in step.text
    assert MultiTask(parts, goals, timeout_s=10.0).step(0.0, poses).text.startswith(f"{step.phase}: #1 ")
    with pytest.raises(ConfigError, match="names: expected one per part"):
        MultiTask(parts, goals, timeout_s=10.0, names=["track 7"])


def test_goals_are_not_combined_with_part_or_goal():
    import argparse

    from ppod_nodes.cli import demo

    parser = argparse.ArgumentParser()
    demo.add_arguments(parser)
    args = parser.parse_args(["--goals", "g.yaml", "--part", "washer"])
    with pytest.raises(ConfigError, match="--goals: not combined with --part/--goal"):
        demo.run(args)
    args = parser.parse_args(["--timeout", "-1"])
    with pytest.raises(ConfigError, match="--timeout"):
        demo.run(args)
    assert parser.parse_args([]).goals is None


def test_the_planner_node_gives_a_lost_track_to_a_new_one_of_the_same_label_nearby():
    from types import SimpleNamespace

    from ppod_nodes.field_planner import reassociate

    def pose(label, x, y):
        return SimpleNamespace(label=label, pose=SimpleNamespace(x=x, y=y))

    ids, labels, last = [4, 1, 3], ["bracket", "washer", "washer"], [(0.02, 0.0), (0.0, 0.0), (0.03, 0.03)]
    by_id = {4: pose("bracket", 0.02, 0.0), 6: pose("washer", 0.031, 0.029), 7: pose("tile", 0.0, 0.001),
             8: pose("washer", 0.06, 0.0)}
    reassociate(ids, labels, last, by_id)
    assert ids == [4, 1, 6]  # row 1: no washer within 20 mm (the tile does not count); row 2: track 6

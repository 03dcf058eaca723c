"""Every example in docs/formats.md loads with the code's own loaders (the page and the code agree)."""

import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

DOC = Path(__file__).parents[2] / "docs" / "formats.md"


def _blocks() -> list[tuple[str, str, str]]:
    """(section heading, language, text) of every fenced block."""
    out, section = [], ""
    text = DOC.read_text()
    for m in re.finditer(r"^## (?P<h>[^\n]+)$|^```(?P<lang>\w+)\n(?P<body>.*?)^```$", text, re.MULTILINE | re.DOTALL):
        if m["h"]:
            section = m["h"]
        else:
            out.append((section, m["lang"], m["body"]))
    return out


def _section(prefix: str) -> list[str]:
    return [body for section, _, body in _blocks() if section.startswith(prefix)]


def test_the_page_has_an_example_of_every_format():
    for prefix, n in (("Plate motion", 1), ("Part", 2), ("Scene", 1), ("Field JSON", 1), ("GOALS.yaml", 1),
                      ("Demo summary", 1)):
        assert len(_section(prefix)) == n, prefix


def test_the_motion_example_loads_and_means_what_the_comments_say():
    from ppod_ros.motion import PlateMotion

    [text] = _section("Plate motion")
    motion = PlateMotion.from_yaml_text(text)
    assert motion.name == "LineSinkX" and motion.frequency_hz == 30
    assert np.allclose(motion.amplitude[0], [10, 0, 0, 0, 100, 0])


def test_the_part_examples_load():
    from ppod_ros.parts import part_from_yaml_text

    kinds = [part_from_yaml_text(text).kind for text in _section("Part")]
    assert kinds == ["point", "rigid"]


def test_the_scene_example_loads_with_its_scatter():
    from ppod_sim.scene import scene_from_dict

    [text] = _section("Scene")
    scene = scene_from_dict(yaml.safe_load(text))
    assert scene.seed == 7
    assert [p.label for p in scene.parts][:2] == ["washer", "tile"] and len(scene.parts) == 2 + 4


def test_the_field_json_example_has_the_keys_the_solver_writes():
    from ppod_ros.motion import PlateMotion
    from ppod_ros.parts import PointPart
    from ppod_ros.physics.field import solve_field
    from ppod_ros.physics.settings import REASONS

    [text] = _section("Field JSON")
    example = json.loads(text)
    motion = PlateMotion.from_yaml_text(_section("Plate motion")[0])
    written = solve_field(motion, PointPart(mu=0.3), np.array([[0.0, 0.0], [0.01, 0.0]])).to_dict()
    assert set(example) == set(written)
    assert set(example["settings"]) <= set(written["settings"])
    assert set(example["reason"]) <= set(REASONS.values())


@pytest.mark.parametrize("path", ["config/lab.example.yaml", "nodes/data/ppod_up.yaml"])
def test_launch_configurations_named_on_the_page_load(path):
    from ppod_nodes.launch.spec import load_launch_spec

    assert load_launch_spec(Path(__file__).parents[2] / path).nodes


def test_the_goals_example_loads_with_the_planners_parser():
    from ppod_ros.planning.goals import goals_from_data

    [text] = _section("GOALS.yaml")
    bracket, second = goals_from_data(yaml.safe_load(text), "docs/formats.md")
    assert (bracket.part, bracket.theta_deg, bracket.tol_mm, bracket.tol_deg) == ("bracket", 0.0, 1.0, 2.0)
    assert (second.part, second.theta_deg, second.tol_mm) == (1, None, 2.0)


def test_the_summary_example_has_exactly_the_keys_the_demo_writes():
    from ppod_nodes.cli.demo_multi import summarize
    from ppod_ros.parts import PointPart

    [text] = _section("Demo summary")
    doc = json.loads(text)
    goal = {"index": 0, "label": "washer", "x": 0.0, "y": 0.0, "theta_rad": None, "tol_m": 1e-3, "tol_rad": 0.0}
    t = np.linspace(0.0, 2.0, 21)
    written = summarize([goal], [PointPart(0.3)], t, np.zeros((t.size, 1, 3)), 0.0, 2.0, 1.0)
    assert set(doc) == set(written)
    assert set(doc["parts"][0]) == set(written["parts"][0])
    assert written["all_reached"] and written["parts"][0]["time_to_goal_s"] == 0.0

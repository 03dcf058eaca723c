"""GOALS.yaml (ppod demo --goals, ppod move): parsing, one-line errors, naming parts."""

import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.planning.goals import GoalEntry, goals_from_data, load_goals_file, resolve_parts


def test_the_issue_example_parses_with_defaults(tmp_path):
    path = tmp_path / "goals.yaml"
    path.write_text("goals:\n"
                    "  - {part: bracket, pose: [0.02, -0.02, 0]}\n"
                    "  - {part: 1, pose: [-0.03, 0.03], tol_mm: 2}\n")
    assert load_goals_file(path) == [GoalEntry("bracket", 0.02, -0.02, 0.0, 1.0, 2.0),
                                     GoalEntry(1, -0.03, 0.03, None, 2.0, 2.0)]


@pytest.mark.parametrize("data, match", [
    ({}, "non-empty list"),
    ({"goals": []}, "non-empty list"),
    ({"goals": [{"part": "a", "pose": [0, 0]}], "extra": 1}, "unknown key"),
    ({"goals": [{"part": "a", "pose": [0]}]}, r"goals\[0\].pose"),
    ({"goals": [{"part": "a", "pose": [0, "x"]}]}, r"goals\[0\].pose: expected numbers"),
    ({"goals": [{"part": -1, "pose": [0, 0]}]}, r"goals\[0\].part"),
    ({"goals": [{"part": True, "pose": [0, 0]}]}, r"goals\[0\].part"),
    ({"goals": [{"part": "a", "pose": [0, 0], "tol_mm": 0}]}, r"goals\[0\].tol_mm.*mm"),
    ({"goals": [{"part": "a", "pose": [0, 0], "speed": 1}]}, "unknown key"),
])
def test_bad_files_name_the_entry_and_field(data, match):
    with pytest.raises(ConfigError, match=match):
        goals_from_data(data)


def test_labels_name_the_first_unused_match_and_indices_or_ids_name_one_part():
    labels = ["bracket", "washer", "washer", "tile"]
    entries = goals_from_data({"goals": [{"part": "washer", "pose": [0, 0]}, {"part": "washer", "pose": [0.03, 0]},
                                         {"part": 0, "pose": [-0.03, 0]}]})
    assert resolve_parts(entries, labels) == [1, 2, 0]
    assert resolve_parts(entries, labels, ids=[0, 5, 6, 7]) == [1, 2, 0]  # ids: track 0 is row 0
    three = goals_from_data({"goals": [{"part": "washer", "pose": [0, 0]}] * 3})
    with pytest.raises(ConfigError, match="no further part labelled 'washer'"):
        resolve_parts(three, labels)
    with pytest.raises(ConfigError, match="already given a goal"):
        resolve_parts(goals_from_data({"goals": [{"part": 1, "pose": [0, 0]}, {"part": "washer", "pose": [0, 0]},
                                                 {"part": 1, "pose": [0, 0]}]}), labels)
    with pytest.raises(ConfigError, match="no part with id 9"):
        resolve_parts(goals_from_data({"goals": [{"part": 9, "pose": [0, 0]}]}), labels, ids=[0, 5, 6, 7])
    with pytest.raises(ConfigError, match="index 9 outside"):
        resolve_parts(goals_from_data({"goals": [{"part": 9, "pose": [0, 0]}]}), labels)

"""The layers of docs/architecture.md: who may import whom (every import, also inside functions)."""

import ast
from pathlib import Path

ROOT = Path(__file__).parents[2]

#: ppod_ros package (or top-level module) -> the ppod_ros packages it may import (docs/architecture.md).
CORE_ALLOWED = {
    "errors": set(),
    "config": {"errors"},
    "motion": {"config", "errors"},
    "parts": {"config", "errors"},
    "physics": {"errors", "motion", "parts"},
    "estimation": {"config", "errors", "motion"},
    "device": {"config", "errors", "estimation", "motion"},
    "can": {"device", "errors"},
    "kinematics": {"actuation", "config", "device", "errors", "motion"},
    "actuation": {"can", "device", "errors", "kinematics", "motion"},
    "vision": {"config", "errors", "parts"},
    "control": {"actuation", "config", "device", "errors", "estimation", "motion"},
    "planning": {"actuation", "config", "control", "device", "errors", "motion", "parts", "physics"},
    "view": {"errors", "parts", "physics"},
    "__init__": {"errors", "motion"},
}
#: Outside packages the core must never import: it runs without ROS (STYLE.md rule 1).
NEVER_IN_CORE = {"rclpy", "ppod_msgs", "ppod_nodes", "ppod_sim", "ppod_bench", "foxglove", "launch", "launch_ros"}


def _imports(path: Path):
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield node.module


def test_core_packages_import_only_the_layers_below_them_and_never_ros():
    wrong = []
    for path in (ROOT / "ppod_ros").rglob("*.py"):
        rel = path.relative_to(ROOT / "ppod_ros")
        unit = rel.stem if len(rel.parts) == 1 else rel.parts[0]
        assert unit in CORE_ALLOWED, f"ppod_ros/{rel}: a new package: add it to docs/architecture.md and this table"
        for module in _imports(path):
            parts = module.split(".")
            if parts[0] in NEVER_IN_CORE:
                wrong.append(f"ppod_ros/{rel} imports {module} (the core never imports ROS or the nodes)")
            elif parts[0] == "ppod_ros" and len(parts) > 1 and parts[1] != unit and parts[1] not in CORE_ALLOWED[unit]:
                wrong.append(f"ppod_ros/{rel} imports {module} ({unit} may import {sorted(CORE_ALLOWED[unit])})")
    assert not wrong, "\n".join(wrong)


def test_the_simulator_uses_ros_only_in_its_node_and_nodes_leave_the_simulator_to_the_cli():
    wrong = []
    for path in (ROOT / "sim_backend").rglob("*.py"):
        if path.name == "ros_node.py":
            continue
        wrong += [f"sim_backend/{path.name} imports {m}" for m in _imports(path)
                  if m.split(".")[0] in {"rclpy", "ppod_msgs", "ppod_nodes"}]
    for path in (ROOT / "nodes").rglob("*.py"):
        rel = path.relative_to(ROOT / "nodes")
        if rel.parts[0] == "cli":
            continue  # ppod demo and ppod bench drive the simulator and the benchmarks
        wrong += [f"nodes/{rel} imports {m}" for m in _imports(path) if m.split(".")[0] in {"ppod_sim", "ppod_bench"}]
    assert not wrong, "\n".join(wrong)

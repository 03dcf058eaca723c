"""Helpers shared by the physics tests (imported as a plain module: pytest puts this folder on sys.path)."""

from pathlib import Path

from ppod_ros.motion import PlateMotion

CONFIG = Path(__file__).resolve().parents[2] / "config"


def suite_motion(name: str) -> PlateMotion:
    """A motion of the benchmark suite, config/motions/NAME.yaml."""
    return PlateMotion.from_yaml(CONFIG / "motions" / f"{name}.yaml")

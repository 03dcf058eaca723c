"""Shared fixtures for the physics tests: suite motions (config/motions) and common parts."""

import pytest

from ppod_ros.motion import PlateMotion
from ppod_ros.parts import PointPart, load_part
from tests.physics.physics_suite import CONFIG, suite_motion


@pytest.fixture(scope="session")
def line_sink_x() -> PlateMotion:
    return suite_motion("LineSinkX")


@pytest.fixture(scope="session")
def point_part() -> PointPart:
    return PointPart(0.3)


@pytest.fixture(scope="session")
def rigid_part():
    return load_part(CONFIG / "parts" / "published_rigid.yaml")

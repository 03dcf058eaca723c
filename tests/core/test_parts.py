import math

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.parts import Footprint, PointPart, RigidPart, part_from_yaml_text, published_rigid_part

RIGID = """
type: rigid
mass: 0.0216
inertia: [1.084e-5, 0.123e-5, 1.20e-5]
contacts:
  - [0.01, -0.03, -0.002]
  - [0.0, 0.03, -0.002]
  - [-0.01, -0.03, -0.002]
mu: [0.3, 0.3, 0.3]
"""


def test_rigid_part_yaml_loads_the_published_part():
    p = part_from_yaml_text(RIGID)
    ref = published_rigid_part()
    assert isinstance(p, RigidPart) and p.key == ref.key
    assert p.h == pytest.approx(0.002)
    np.testing.assert_allclose(p.inertia, np.diag([1.084e-5, 0.123e-5, 1.20e-5]))


def test_point_part_defaults_static_friction_to_kinetic():
    p = part_from_yaml_text("type: point\nmu: 0.4\nfootprint: {disk: 0.005}")
    assert isinstance(p, PointPart) and p.mu_static == 0.4
    assert p.footprint.kind == "disk" and p.footprint.symmetry_rad == 0.0


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("type: point\nmu: -0.1", "mu"),
        ("type: point\nmu: 0.3\nmu_static: 0.2", "mu_static"),
        ("type: point\nmu: 0.3\ncolour: red", "colour"),
        ("type: blob", "type"),
        (RIGID.replace("[-0.01, -0.03, -0.002]", "[-0.01, -0.03, -0.003]"), "same z"),
        (RIGID.replace("[0.0, 0.03, -0.002]", "[0.0, -0.03, -0.002]"), "collinear"),
        (RIGID.replace("mass: 0.0216", "mass: 0"), "mass"),
        (RIGID.replace("[1.084e-5, 0.123e-5, 1.20e-5]", "[1.084e-5, -0.123e-5, 1.20e-5]"), "positive definite"),
        (RIGID.replace("mu: [0.3, 0.3, 0.3]", "mu: [0.3, 0.3]"), "mu"),
        (RIGID.replace("  - [-0.01, -0.03, -0.002]\n", ""), "three contacts"),
        (RIGID.replace("-0.002]\n  - [0.0", "0.002]\n  - [0.0").replace("-0.002]\n  - [-0.01", "0.002]\n  - [-0.01")
         .replace("[-0.01, -0.03, -0.002]", "[-0.01, -0.03, 0.002]"), "z must be <= 0"),
    ],
)
def test_bad_part_yaml_is_rejected_naming_the_problem(text, fragment):
    with pytest.raises(ConfigError, match=fragment):
        part_from_yaml_text(text)


def test_footprint_symmetry_of_rectangles_squares_and_regular_polygons():
    assert Footprint.from_value({"rect": [0.01, 0.02]}).symmetry_rad == pytest.approx(math.pi)
    assert Footprint.from_value({"rect": [0.02, 0.02]}).symmetry_rad == pytest.approx(math.pi / 2)
    hexagon = [[math.cos(a), math.sin(a)] for a in np.linspace(0, 2 * math.pi, 6, endpoint=False)]
    assert Footprint.from_value({"polygon": hexagon}).symmetry_rad == pytest.approx(math.pi / 3)
    l_shape = [[0, 0], [2, 0], [2, 1], [1, 1], [1, 3], [0, 3]]
    assert Footprint.from_value({"polygon": l_shape}).symmetry_rad == pytest.approx(2 * math.pi)
    clockwise = Footprint.from_value({"polygon": [[0, 0], [0, 1], [1, 1], [1, 0]]})
    assert clockwise.area_m2 == pytest.approx(1.0)

"""The scene's core pieces: the camera transform's quaternion and the field arrows inside the disc."""

import math

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.view.scene import Scene, camera_transform, field_arrows, quaternion_from_matrix


def _matrix(q):
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def test_the_camera_quaternion_reproduces_the_mounting_rotation():
    from ppod_ros.vision import CameraConfig

    camera = CameraConfig()
    translation, q = camera_transform(camera)
    assert translation == pytest.approx(camera.position_m)
    assert math.isclose(sum(v * v for v in q), 1.0)
    assert np.allclose(_matrix(q), camera.rotation_plate_from_camera, atol=1e-12)
    # Looking straight down: the camera's z axis is the plate's -z.
    assert (_matrix(q) @ [0, 0, 1])[2] < -0.99


def test_quaternions_of_half_turns_are_exact():
    assert np.allclose(_matrix(quaternion_from_matrix(np.diag([1.0, -1.0, -1.0]))), np.diag([1.0, -1.0, -1.0]))


def test_field_arrows_lie_inside_the_disc_and_follow_the_line_sink():
    from ppod_ros.motion import PlateMotion

    motion = PlateMotion.from_yaml_text(
        "frequency_hz: 30\nharmonics:\n"
        "  - {k: 1, amplitude: [10, 0, 0, 0, 100, 0], phase: [0, 0, 0, 0, 4.71238898, 0]}\n")
    arrows = field_arrows(motion, 0.08, n=5)
    assert arrows and all(math.hypot(a.x, a.y) <= 0.08 for a in arrows)
    # LineSinkX pulls towards x = 0.
    assert all(a.vx * a.x < 0 for a in arrows if abs(a.x) > 0.01)


def test_a_scene_needs_a_positive_radius_and_arrow_scale():
    with pytest.raises(ConfigError, match="plate_radius_m"):
        Scene(0.0)
    with pytest.raises(ConfigError, match="arrow_scale_s"):
        Scene(0.1, arrow_scale_s=-1)

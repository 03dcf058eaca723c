import math

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.vision import CameraConfig, PlateLayout

YAML = """
camera:
  width: 640
  height: 480
  encoding: bgr8
  fps: 15
  intrinsics: {fx: 800, fy: 810, cx: 320, cy: 240}
  distortion: [-0.1, 0.02, 0, 0, 0]
  mount: {position_m: [0.01, 0.0, 0.5], rotation_deg: [1, 2, 3]}
plate:
  size_m: 0.3
  work_area_m: [-0.1, 0.1, -0.08, 0.08]
  markers: {dictionary: DICT_5X5_50, size_m: 0.02, layout: [[3, -0.13, -0.13], [9, 0.13, 0.13]]}
"""


def test_camera_config_loads_from_yaml_and_round_trips():
    cfg = CameraConfig.from_yaml_text(YAML)
    assert (cfg.width, cfg.height, cfg.encoding, cfg.fps) == (640, 480, "bgr8", 15.0)
    assert cfg.shape == (480, 640, 3)
    assert cfg.plate.markers == ((3, -0.13, -0.13), (9, 0.13, 0.13))
    again = CameraConfig.from_yaml_text(cfg.to_yaml())
    assert again == cfg


def test_empty_yaml_gives_the_default_camera_that_sees_the_whole_plate():
    cfg = CameraConfig.from_yaml_text("{}")
    assert cfg == CameraConfig()
    from ppod_ros.vision import PlateCalibration

    cal = PlateCalibration.nominal(cfg)
    h = cfg.plate.size_m / 2
    uv = cal.plate_to_image([[-h, -h], [h, -h], [h, h], [-h, h]])
    assert np.all(uv > 0) and np.all(uv[:, 0] < cfg.width) and np.all(uv[:, 1] < cfg.height)


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("camera: {width: 0}", "camera.width"),
        ("camera: {encoding: rgb8}", "camera.encoding"),
        ("camera: {distortion: [1, 2]}", "camera.distortion"),
        ("camera: {mount: {position_m: [0, 0, -0.5]}}", "position_m"),
        ("camera: {intrinsics: {fx: .nan}}", "camera.intrinsics.fx"),
        ("camera: {lens: wide}", "camera.lens"),
        ("plate: {markers: {layout: [[0, 0.0, 0.0], [0, 0.1, 0.1]]}}", "unique"),
        ("plate: {markers: {layout: [[60, 0.0, 0.0]]}}", "0..49"),
        ("plate: {work_area_m: [0.1, -0.1, -0.1, 0.1]}", "work_area_m"),
        ("plate: {size_m: 0.35, colour: black}", "plate.colour"),
    ],
)
def test_camera_config_rejects_bad_values_naming_the_key(text, fragment):
    with pytest.raises(ConfigError, match=fragment.replace(".", r"\.")):
        CameraConfig.from_yaml_text(text)


def test_extrinsics_put_the_optical_centre_where_the_mount_says():
    import cv2

    cfg = CameraConfig()
    rvec, tvec = cfg.extrinsics()
    R, _ = cv2.Rodrigues(rvec)
    np.testing.assert_allclose(-R.T @ tvec, cfg.position_m, atol=1e-12)
    # Straight down: the optical axis is plate -z and image x runs along plate x.
    down = cfg.with_changes(rotation_deg=(0.0, 0.0, 0.0))
    np.testing.assert_allclose(down.rotation_plate_from_camera, np.diag([1.0, -1.0, -1.0]), atol=1e-15)


def test_marker_corners_follow_the_aruco_order_upright_on_the_plate():
    layout = PlateLayout(markers=((5, 0.1, -0.1),))
    c = layout.marker_corners()[5]
    s = layout.marker_size_m / 2
    np.testing.assert_allclose(
        c, [[0.1 - s, -0.1 + s], [0.1 + s, -0.1 + s], [0.1 + s, -0.1 - s], [0.1 - s, -0.1 - s]]
    )
    assert math.isclose(np.linalg.norm(c[0] - c[1]), layout.marker_size_m)

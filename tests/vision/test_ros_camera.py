"""ROS camera conventions: Bayer, mono16 and rgb8 images; intrinsics from camera_info and ost.yaml."""

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.vision import CameraConfig
from ppod_ros.vision.frames import BadFrameError
from ppod_ros.vision.ros_camera import (
    decode_image,
    intrinsics_from_camera_info,
    load_ost_yaml,
    to_encoding,
    with_intrinsics,
)

# Colour patches (BGR) large enough that demosaicing is exact away from their borders.
PATCHES = np.zeros((32, 32, 3), np.uint8)
PATCHES[:16, :16] = (200, 40, 10)
PATCHES[:16, 16:] = (10, 220, 30)
PATCHES[16:, :16] = (30, 60, 240)
PATCHES[16:, 16:] = (120, 120, 120)
# Which colour (BGR index) each pixel of a 2x2 cell carries, by ROS encoding.
PATTERNS = {"bayer_rggb8": [[2, 1], [1, 0]], "bayer_bggr8": [[0, 1], [1, 2]],
            "bayer_gbrg8": [[1, 0], [2, 1]], "bayer_grbg8": [[1, 2], [0, 1]]}


def _mosaic(bgr: np.ndarray, pattern) -> np.ndarray:
    out = np.empty(bgr.shape[:2], np.uint8)
    for i in range(2):
        for j in range(2):
            out[i::2, j::2] = bgr[i::2, j::2, pattern[i][j]]
    return out


@pytest.mark.parametrize("encoding", sorted(PATTERNS))
def test_bayer_images_are_demosaiced_to_the_scene_colours(encoding):
    raw = _mosaic(PATCHES, PATTERNS[encoding])
    image = decode_image(encoding, 32, 32, 32, raw.tobytes())
    assert image.shape == (32, 32, 3)
    for y, x in ((6, 6), (6, 26), (26, 6), (26, 26)):
        assert np.abs(image[y, x].astype(int) - PATCHES[y, x].astype(int)).max() <= 2, (encoding, y, x)


@pytest.mark.parametrize("big_endian", [False, True])
def test_mono16_keeps_the_high_byte_in_either_byte_order(big_endian):
    words = (np.arange(12, dtype=np.uint16).reshape(3, 4) * 5000)
    data = words.astype(">u2" if big_endian else "<u2").tobytes()
    image = decode_image("mono16", 4, 3, 8, data, big_endian=big_endian)
    assert image.dtype == np.uint8 and np.array_equal(image, (words >> 8).astype(np.uint8))


def test_rgb8_becomes_bgr_and_frames_follow_the_camera_encoding():
    rgb = PATCHES[:, :, ::-1].copy()
    image = decode_image("rgb8", 32, 32, 96, rgb.tobytes())
    assert np.array_equal(image, PATCHES)
    assert to_encoding(image, "mono8").shape == (32, 32)
    assert to_encoding(to_encoding(image, "mono8"), "bgr8").shape == (32, 32, 3)


def test_unknown_encodings_and_short_buffers_are_rejected_with_the_reason():
    with pytest.raises(BadFrameError) as info:
        decode_image("yuv422", 4, 4, 8, bytes(32))
    assert info.value.reason == "encoding"
    with pytest.raises(BadFrameError) as info:
        decode_image("mono16", 4, 4, 8, bytes(10))
    assert info.value.reason == "size"


OST = """image_width: 640
image_height: 512
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [851.2, 0, 319.1, 0, 849.7, 255.8, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.081, 0.052, 0.0004, -0.0002, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [851.2, 0, 319.1, 0, 0, 849.7, 255.8, 0, 0, 0, 1, 0]
"""


def test_camera_calibrations_ost_yaml_replaces_the_intrinsics_and_keeps_the_mount(tmp_path):
    path = tmp_path / "ost.yaml"
    path.write_text(OST)
    base = CameraConfig()
    camera = with_intrinsics(base, load_ost_yaml(path))
    assert (camera.width, camera.height) == (640, 512)
    assert (camera.fx, camera.fy, camera.cx, camera.cy) == (851.2, 849.7, 319.1, 255.8)
    assert camera.distortion == (-0.081, 0.052, 0.0004, -0.0002, 0.0)
    assert camera.position_m == base.position_m and camera.rotation_deg == base.rotation_deg


def test_camera_info_intrinsics_and_their_errors():
    got = intrinsics_from_camera_info(640, 480, [500, 0, 320, 0, 510, 240, 0, 0, 1], [0.1, -0.05, 0, 0],
                                      "plumb_bob")
    assert got["fx"] == 500 and got["fy"] == 510 and got["distortion"] == (0.1, -0.05, 0.0, 0.0, 0.0)
    with pytest.raises(ConfigError, match="K"):
        intrinsics_from_camera_info(640, 480, [0] * 9, [], "plumb_bob")
    with pytest.raises(ConfigError, match="distortion_model"):
        intrinsics_from_camera_info(640, 480, [500, 0, 320, 0, 510, 240, 0, 0, 1], [], "equidistant")

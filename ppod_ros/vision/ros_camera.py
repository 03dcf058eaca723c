"""ROS camera conventions: images in any common encoding, intrinsics from camera_info or ost.yaml.

* :func:`decode_image` turns a ``sensor_msgs/Image`` payload into the tracker's frames: ``mono8``,
  ``mono16`` (scaled to 8 bits, either byte order), ``bgr8``, ``rgb8`` and the four 8-bit Bayer
  patterns (demosaiced with OpenCV), as uint8 (H, W) or (H, W, 3) BGR.
* :func:`intrinsics_from_camera_info` and :func:`load_ost_yaml` read a camera's intrinsics from a
  ``sensor_msgs/CameraInfo`` (its K, D, width, height) or from the ``ost.yaml`` that
  ``camera_calibration`` writes (``camera_matrix``, ``distortion_coefficients``, ...); either can
  replace the intrinsics of a :class:`~ppod_ros.vision.camera.CameraConfig` with
  :func:`with_intrinsics`, keeping its mounting pose and plate layout.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ppod_ros.config.fields import load_yaml_file
from ppod_ros.errors import ConfigError
from ppod_ros.vision.frames import BadFrameError

#: encoding -> (channels, bytes per channel, OpenCV conversion to BGR or None)
ENCODINGS: dict[str, tuple[int, int, int | None]] = {
    "mono8": (1, 1, None),
    "mono16": (1, 2, None),
    "bgr8": (3, 1, None),
    "rgb8": (3, 1, cv2.COLOR_RGB2BGR),
    # ROS names the pattern by its first two rows; OpenCV by the second row's first two pixels.
    "bayer_rggb8": (1, 1, cv2.COLOR_BayerBG2BGR),
    "bayer_bggr8": (1, 1, cv2.COLOR_BayerRG2BGR),
    "bayer_gbrg8": (1, 1, cv2.COLOR_BayerGR2BGR),
    "bayer_grbg8": (1, 1, cv2.COLOR_BayerGB2BGR),
}
#: Distortion models whose first five coefficients are OpenCV's (k1, k2, p1, p2, k3).
DISTORTION_MODELS = ("plumb_bob", "rational_polynomial")


def decode_image(encoding: str, width: int, height: int, step: int, data: bytes | np.ndarray,
                 big_endian: bool = False) -> np.ndarray:
    """A ROS image buffer as uint8 (H, W) (mono) or (H, W, 3) (BGR); BadFrameError if malformed."""
    spec = ENCODINGS.get(encoding)
    if spec is None:
        raise BadFrameError(f"unsupported encoding {encoding!r} ({', '.join(ENCODINGS)})", "encoding")
    channels, depth, conversion = spec
    if height == 0 or width == 0:
        raise BadFrameError("empty image", "empty")
    buf = np.frombuffer(bytes(data) if not isinstance(data, np.ndarray) else data.tobytes(), dtype=np.uint8)
    need = height * step
    if step < width * channels * depth or buf.size < need:
        raise BadFrameError(f"image data of {buf.size} bytes does not fit {width}x{height} {encoding} "
                            f"with step {step}", "size")
    rows = buf[:need].reshape(height, step)[:, : width * channels * depth]
    if depth == 2:
        words = np.ascontiguousarray(rows).view(">u2" if big_endian else "<u2").reshape(height, width)
        return (words >> 8).astype(np.uint8)
    image = np.ascontiguousarray(rows.reshape(height, width, channels) if channels == 3 else rows)
    return cv2.cvtColor(image, conversion) if conversion is not None else image


def to_encoding(image: np.ndarray, encoding: str) -> np.ndarray:
    """A decoded frame in the tracker camera's encoding (``mono8``: (H, W); ``bgr8``: (H, W, 3))."""
    if encoding == "mono8" and image.ndim == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if encoding == "bgr8" and image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    return image


def intrinsics_from_camera_info(width: int, height: int, k: Sequence[float], d: Sequence[float],
                                distortion_model: str = "plumb_bob") -> dict[str, Any]:
    """CameraConfig fields (width, height, fx, fy, cx, cy, distortion) from CameraInfo's K and D."""
    K = np.asarray(k, dtype=float)
    if K.size != 9 or not np.all(np.isfinite(K)) or K[0] <= 0 or K[4] <= 0:
        raise ConfigError(f"camera_info K: expected 9 finite values with fx, fy > 0, got {list(K)}")
    if distortion_model and distortion_model not in DISTORTION_MODELS:
        raise ConfigError(f"camera_info distortion_model: {distortion_model!r} is not supported "
                          f"({', '.join(DISTORTION_MODELS)})")
    D = [float(x) for x in d][:5]
    D += [0.0] * (5 - len(D))
    if int(width) <= 0 or int(height) <= 0:
        raise ConfigError(f"camera_info width, height: must be > 0 px, got {width} x {height}")
    return {"width": int(width), "height": int(height), "fx": float(K[0]), "fy": float(K[4]),
            "cx": float(K[2]), "cy": float(K[5]), "distortion": tuple(D)}


def _matrix(data: Mapping[str, Any], key: str, path: str) -> list[float]:
    block = data.get(key)
    if not isinstance(block, Mapping) or not isinstance(block.get("data"), list):
        raise ConfigError(f"{path}: {key}: expected {{rows, cols, data: [...]}} (camera_calibration's ost.yaml)")
    return [float(v) for v in block["data"]]


def load_ost_yaml(path: str | Path) -> dict[str, Any]:
    """Intrinsics (CameraConfig fields) from camera_calibration's ost.yaml (or a camera_info YAML)."""
    data = load_yaml_file(path, "ost.yaml")
    if not isinstance(data, Mapping):
        raise ConfigError(f"{path}: expected a mapping (camera_calibration's ost.yaml)")
    missing = [k for k in ("image_width", "image_height", "camera_matrix") if k not in data]
    if missing:
        raise ConfigError(f"{path}: missing {', '.join(missing)} (camera_calibration's ost.yaml)")
    d = _matrix(data, "distortion_coefficients", str(path)) if "distortion_coefficients" in data else []
    return intrinsics_from_camera_info(data["image_width"], data["image_height"],
                                       _matrix(data, "camera_matrix", str(path)), d,
                                       str(data.get("distortion_model", "plumb_bob")))


def with_intrinsics(camera, intrinsics: Mapping[str, Any]):
    """``camera`` with its intrinsics replaced (mounting pose, plate layout and encoding kept)."""
    return camera.with_changes(**intrinsics)


__all__ = ["DISTORTION_MODELS", "ENCODINGS", "decode_image", "intrinsics_from_camera_info", "load_ost_yaml",
           "to_encoding", "with_intrinsics"]

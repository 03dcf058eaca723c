"""Camera frames: what a valid frame is, and the reason when one is not.

Frames are numpy uint8 arrays in one of the ROS image encodings the stack uses (``mono8``:
(H, W); ``bgr8``: (H, W, 3)), with a capture time in seconds on the device clock. A frame that is
empty, of the wrong size, encoding or dtype, or not later than the previous one is rejected with a
:class:`BadFrameError` whose message says which; callers (the tracker node) log it and skip the
frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from ppod_ros.errors import ConfigError


class BadFrameError(ConfigError):
    """A camera frame was rejected; ``reason`` is a short machine-readable tag.

    Reasons: ``"empty"``, ``"not_array"``, ``"dtype"``, ``"size"``, ``"encoding"``,
    ``"stamp"`` (non-finite or not after the previous frame), ``"exposure"`` (the plate is too dark
    or overexposed: lamp off, lens covered, wrong exposure), ``"noise"`` (no parts, only noise).
    """

    def __init__(self, message: str, reason: str):
        super().__init__(message)
        self.reason = reason


@dataclass(frozen=True)
class Frame:
    """One camera frame: ``image`` (uint8, (H, W) or (H, W, 3)) taken at ``stamp_s`` (s)."""

    image: np.ndarray
    stamp_s: float
    index: int = -1


def check_frame(image: Any, width: int, height: int, encoding: str) -> np.ndarray:
    """Return ``image`` as a valid uint8 array of the expected size and encoding, else raise.

    Parameters
    ----------
    image : ndarray
        The frame: (height, width) for ``mono8``, (height, width, 3) for ``bgr8``.
    width, height : int
        Expected size (pixels).
    encoding : str
        ``"mono8"`` or ``"bgr8"``.
    """
    if image is None:
        raise BadFrameError("frame is empty (None)", "empty")
    if not isinstance(image, np.ndarray):
        raise BadFrameError(f"frame is a {type(image).__name__}, expected a numpy array", "not_array")
    if image.size == 0:
        raise BadFrameError(f"frame is empty (shape {image.shape})", "empty")
    if image.dtype != np.uint8:
        raise BadFrameError(f"frame has dtype {image.dtype}, expected uint8 ({encoding})", "dtype")
    want_channels = 1 if encoding == "mono8" else 3
    channels = 1 if image.ndim == 2 else (image.shape[2] if image.ndim == 3 else -1)
    if image.ndim == 3 and channels == 1:
        image = image[:, :, 0]
        channels = 1
    if channels != want_channels:
        raise BadFrameError(
            f"frame has shape {image.shape}: {_describe_channels(channels)}, expected "
            f"{encoding} ({want_channels} channel{'s' if want_channels > 1 else ''})",
            "encoding",
        )
    if image.shape[0] != height or image.shape[1] != width:
        raise BadFrameError(
            f"frame is {image.shape[1]}x{image.shape[0]} px, expected {width}x{height} px", "size"
        )
    return image


def check_stamp(stamp_s: Any, previous_s: float | None) -> float:
    """A finite capture time strictly after ``previous_s`` (s)."""
    try:
        t = float(stamp_s)
    except (TypeError, ValueError) as exc:
        raise BadFrameError(f"frame stamp {stamp_s!r} is not a number of seconds", "stamp") from exc
    if not math.isfinite(t):
        raise BadFrameError(f"frame stamp {t} is not finite", "stamp")
    if previous_s is not None and t <= previous_s:
        raise BadFrameError(
            f"frame stamp {t:.6f} s is not after the previous frame's {previous_s:.6f} s", "stamp"
        )
    return t


def to_gray(image: np.ndarray) -> np.ndarray:
    """A single-channel uint8 view or conversion of a mono8 or bgr8 image."""
    if image.ndim == 2:
        return image
    if image.ndim == 3 and image.shape[2] == 1:
        return image[:, :, 0]
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    raise BadFrameError(f"cannot convert an image of shape {image.shape} to grey", "encoding")


def _describe_channels(channels: int) -> str:
    return {1: "1 channel", 3: "3 channels", 4: "4 channels (bgra8?)"}.get(channels, f"{channels} channels")


__all__ = ["BadFrameError", "Frame", "check_frame", "check_stamp", "to_gray"]

"""Frame sources: where camera frames come from, each giving (image, stamp_s).

- :class:`GeneratorSource`: any iterable of frames (a renderer's generator, a test's list).
- :class:`VideoCaptureSource`: a live camera through OpenCV VideoCapture, by device index or URL
  (rtsp://, http://); stamps from a monotonic clock at grab time.
- :class:`RecordedSource`: a recorded file: a video (stamps from the container), a folder of
  images (stamps from ``stamps.csv`` beside them, else frame index / fps) or an ``.npz`` holding
  ``images`` (N, H, W[, 3]) uint8 and ``stamps_s`` (N,).

Every source delivers frames in the encoding it was asked for (``mono8`` or ``bgr8``) and returns
None at the end of a stream; a live camera that stops delivering raises DeviceError.
:func:`open_source` picks the kind from a string the way a command line or a node parameter gives
it. Sources are context managers and iterables of :class:`~ppod_ros.vision.frames.Frame`.
"""

from __future__ import annotations

import csv
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ppod_ros.config.fields import check_array
from ppod_ros.errors import ConfigError, DeviceError
from ppod_ros.vision.camera import ENCODINGS
from ppod_ros.vision.frames import Frame

IMAGE_SUFFIXES = (".png", ".bmp", ".tif", ".tiff", ".jpg", ".jpeg", ".pgm", ".ppm")
VIDEO_SUFFIXES = (".avi", ".mp4", ".mkv", ".mov", ".webm", ".m4v")


class FrameSource(ABC):
    """A stream of frames; ``read()`` returns the next :class:`Frame` or None at the end."""

    def __init__(self, encoding: str = "mono8"):
        if encoding not in ENCODINGS:
            raise ConfigError(f"encoding: expected one of {', '.join(ENCODINGS)}; got {encoding!r}")
        self.encoding = encoding
        self._index = 0

    @abstractmethod
    def _next(self) -> tuple[np.ndarray, float] | None:
        """The next raw (image, stamp_s), or None at the end."""

    def read(self) -> Frame | None:
        item = self._next()
        if item is None:
            return None
        image, stamp = item
        frame = Frame(convert_encoding(image, self.encoding), float(stamp), self._index)
        self._index += 1
        return frame

    def close(self) -> None:  # noqa: B027 - sources without a device have nothing to release
        """Release the device or file (idempotent)."""

    def __iter__(self) -> Iterator[Frame]:
        while (frame := self.read()) is not None:
            yield frame

    def __enter__(self) -> FrameSource:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def convert_encoding(image: np.ndarray, encoding: str) -> np.ndarray:
    """``image`` as ``mono8`` or ``bgr8``. Arrays that are not uint8 images pass unchanged, so
    that the consumer (the tracker) rejects them with its own reason."""
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.size == 0:
        return image
    if encoding == "mono8" and image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if encoding == "bgr8" and image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    return image


class GeneratorSource(FrameSource):
    """Frames from an iterable of (image, stamp_s) pairs or of objects with ``image`` and
    ``stamp_s`` attributes (a :class:`Frame`, a rendered frame)."""

    def __init__(self, frames: Iterable[Any], encoding: str = "mono8"):
        super().__init__(encoding)
        self._it = iter(frames)

    def _next(self) -> tuple[np.ndarray, float] | None:
        item = next(self._it, None)
        if item is None:
            return None
        if hasattr(item, "image") and hasattr(item, "stamp_s"):
            return item.image, item.stamp_s
        image, stamp = item
        return image, stamp


class VideoCaptureSource(FrameSource):
    """A live camera through cv2.VideoCapture.

    Parameters
    ----------
    device : int or str
        Device index (0 = first camera) or a stream URL.
    encoding : str
    clock : callable() -> float
        Stamp source (s), read right after each grab; default ``time.monotonic``.
    width, height, fps : optional
        Requested capture format (the device may ignore it; check the frames).
    """

    def __init__(
        self,
        device: int | str,
        encoding: str = "mono8",
        clock: Callable[[], float] = time.monotonic,
        width: int | None = None,
        height: int | None = None,
        fps: float | None = None,
    ):
        super().__init__(encoding)
        self.device = device
        self._clock = clock
        self._cap = cv2.VideoCapture(device)
        if not self._cap.isOpened():
            self._cap.release()
            raise DeviceError(f"camera {device!r}: could not be opened by OpenCV VideoCapture")
        for prop, value in (
            (cv2.CAP_PROP_FRAME_WIDTH, width),
            (cv2.CAP_PROP_FRAME_HEIGHT, height),
            (cv2.CAP_PROP_FPS, fps),
        ):
            if value is not None:
                self._cap.set(prop, float(value))

    def _next(self) -> tuple[np.ndarray, float] | None:
        if self._cap is None:
            return None
        ok = self._cap.grab()
        stamp = self._clock()
        if ok:
            ok, image = self._cap.retrieve()
        if not ok:
            raise DeviceError(f"camera {self.device!r}: no frame (disconnected or stream ended)")
        return image, stamp

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None


class RecordedSource(FrameSource):
    """Frames from a recording: a video file, a folder of images or an ``.npz`` file.

    Parameters
    ----------
    path : str or Path
    encoding : str
    fps : float
        Frame rate for stamps when the recording has none (folders without ``stamps.csv``).
    """

    def __init__(self, path: str | Path, encoding: str = "mono8", fps: float = 10.0):
        super().__init__(encoding)
        self.path = Path(path)
        self.fps = float(fps)
        self._cap: cv2.VideoCapture | None = None
        self._items: list[Any] = []
        self._stamps: np.ndarray | None = None
        self._pos = 0
        if self.path.is_dir():
            self._open_folder()
        elif not self.path.exists():
            raise ConfigError(f"recording {self.path}: no such file or folder")
        elif self.path.suffix.lower() == ".npz":
            self._open_npz()
        elif self.path.suffix.lower() in VIDEO_SUFFIXES:
            self._cap = cv2.VideoCapture(str(self.path))
            if not self._cap.isOpened():
                raise ConfigError(f"recording {self.path}: OpenCV cannot read this video")
        else:
            raise ConfigError(
                f"recording {self.path}: expected a folder of images, an .npz or a video "
                f"({', '.join(VIDEO_SUFFIXES)})"
            )

    def __len__(self) -> int:
        if self._cap is not None:
            return int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT))
        return len(self._items)

    def _open_folder(self) -> None:
        files = sorted(p for p in self.path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise ConfigError(
                f"recording {self.path}: the folder holds no images ({', '.join(IMAGE_SUFFIXES)})"
            )
        self._items = files
        stamps_file = self.path / "stamps.csv"
        if stamps_file.exists():
            stamps = _read_stamps_csv(stamps_file)
            missing = [p.name for p in files if p.name not in stamps]
            if missing:
                raise ConfigError(f"{stamps_file}: no stamp for {', '.join(missing[:5])}")
            self._stamps = np.array([stamps[p.name] for p in files])
        else:
            self._stamps = np.arange(len(files)) / self.fps

    def _open_npz(self) -> None:
        try:
            data = np.load(self.path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise ConfigError(f"recording {self.path}: not a readable .npz ({exc})") from exc
        if "images" not in data:
            raise ConfigError(f"recording {self.path}: expected an array 'images' (N, H, W[, 3])")
        images = data["images"]
        if images.ndim not in (3, 4):
            raise ConfigError(
                f"recording {self.path}: 'images' must have shape (N, H, W) or (N, H, W, 3), "
                f"got {images.shape}"
            )
        stamps = (
            check_array(data["stamps_s"], f"{self.path}: stamps_s", shape=(len(images),), unit="s")
            if "stamps_s" in data
            else np.arange(len(images)) / self.fps
        )
        self._items = list(images)
        self._stamps = stamps

    def _next(self) -> tuple[np.ndarray, float] | None:
        if self._cap is not None:
            ok, image = self._cap.read()
            if not ok:
                return None
            return image, self._cap.get(cv2.CAP_PROP_POS_MSEC) / 1000.0
        if self._pos >= len(self._items):
            return None
        item = self._items[self._pos]
        assert self._stamps is not None
        stamp = float(self._stamps[self._pos])
        self._pos += 1
        if isinstance(item, Path):
            image = cv2.imread(str(item), cv2.IMREAD_UNCHANGED)
            if image is None:
                raise ConfigError(f"recording {item}: OpenCV cannot read this image")
            return image, stamp
        return item, stamp

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None


def _read_stamps_csv(path: Path) -> dict[str, float]:
    """``file,stamp_s`` rows (a header row is allowed)."""
    out: dict[str, float] = {}
    with path.open(newline="", encoding="utf-8") as fh:
        for i, row in enumerate(csv.reader(fh)):
            if not row or (i == 0 and row[0].strip().lower() in ("file", "filename", "name")):
                continue
            if len(row) != 2:
                raise ConfigError(f"{path}: line {i + 1}: expected 'file,stamp_s', got {row}")
            try:
                out[row[0].strip()] = float(row[1])
            except ValueError as exc:
                raise ConfigError(f"{path}: line {i + 1}: stamp {row[1]!r} is not a number") from exc
    return out


def save_npz_recording(path: str | Path, frames: Iterable[Any]) -> int:
    """Write frames ((image, stamp_s) pairs or objects with ``image`` and ``stamp_s``) to an
    ``.npz`` that :class:`RecordedSource` reads back; returns the number of frames."""
    images, stamps = [], []
    for item in frames:
        image, stamp = (item.image, item.stamp_s) if hasattr(item, "image") else item
        images.append(np.asarray(image))
        stamps.append(float(stamp))
    if not images:
        raise ConfigError(f"recording {path}: no frames to save")
    np.savez_compressed(path, images=np.stack(images), stamps_s=np.array(stamps))
    return len(images)


def open_source(spec: int | str, encoding: str = "mono8", fps: float = 10.0) -> FrameSource:
    """A source from a command-line style spec: a device index (``0``), a URL (``rtsp://...``) or
    a recording's path."""
    if isinstance(spec, int) or (isinstance(spec, str) and spec.isdigit()):
        return VideoCaptureSource(int(spec), encoding)
    if not isinstance(spec, str) or not spec:
        raise ConfigError(f"frame source: expected a device index, a URL or a path, got {spec!r}")
    if "://" in spec:
        return VideoCaptureSource(spec, encoding)
    return RecordedSource(spec, encoding, fps)


__all__ = [
    "FrameSource",
    "GeneratorSource",
    "RecordedSource",
    "VideoCaptureSource",
    "convert_encoding",
    "open_source",
    "save_npz_recording",
]

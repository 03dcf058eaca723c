"""Frame sources: generators, recordings (npz, image folders, video files) and VideoCapture."""

import cv2
import numpy as np
import pytest

from ppod_ros.errors import ConfigError, DeviceError
from ppod_ros.vision import (
    GeneratorSource,
    PartTracker,
    RecordedSource,
    TrackStatus,
    VideoCaptureSource,
    open_source,
    save_npz_recording,
)
from ppod_ros.vision.sources import convert_encoding
from ppod_sim.camera import RenderPart
from ppod_sim.camera.scenarios import STANDARD_PARTS


def small_frames(n=4, shape=(48, 64)):
    return [(np.full(shape, 30 * k, np.uint8), 0.1 * k) for k in range(n)]


def test_a_generator_source_yields_frames_then_ends():
    src = GeneratorSource(small_frames())
    frames = list(src)
    assert [f.index for f in frames] == [0, 1, 2, 3]
    assert [f.stamp_s for f in frames] == pytest.approx([0.0, 0.1, 0.2, 0.3])
    assert src.read() is None


def test_sources_deliver_the_encoding_they_were_asked_for():
    bgr = np.zeros((8, 8, 3), np.uint8)
    bgr[..., 2] = 200
    mono = GeneratorSource([(bgr, 0.0)], "mono8").read().image
    assert mono.shape == (8, 8) and mono[0, 0] == round(0.299 * 200)
    again = GeneratorSource([(mono, 0.0)], "bgr8").read().image
    assert again.shape == (8, 8, 3)
    # Not an image: passed through for the tracker to reject with its own reason.
    assert convert_encoding(None, "mono8") is None
    with pytest.raises(ConfigError, match="encoding"):
        GeneratorSource([], "rgb16")


def test_npz_recordings_round_trip_with_their_stamps(tmp_path):
    path = tmp_path / "rec.npz"
    assert save_npz_recording(path, small_frames()) == 4
    with RecordedSource(path) as src:
        assert len(src) == 4
        frames = list(src)
    assert [f.stamp_s for f in frames] == pytest.approx([0.0, 0.1, 0.2, 0.3])
    assert frames[2].image[0, 0] == 60


def test_image_folders_take_stamps_from_stamps_csv_or_the_frame_rate(tmp_path):
    for i, (img, _) in enumerate(small_frames(3)):
        cv2.imwrite(str(tmp_path / f"f{i:03d}.png"), img)
    assert [f.stamp_s for f in RecordedSource(tmp_path, fps=5.0)] == pytest.approx([0.0, 0.2, 0.4])
    (tmp_path / "stamps.csv").write_text("file,stamp_s\nf000.png,10.0\nf001.png,10.25\nf002.png,10.5\n")
    frames = list(RecordedSource(tmp_path))
    assert [f.stamp_s for f in frames] == pytest.approx([10.0, 10.25, 10.5])
    assert frames[1].image.dtype == np.uint8 and frames[1].image[0, 0] == 30
    (tmp_path / "stamps.csv").write_text("f000.png,1.0\n")
    with pytest.raises(ConfigError, match="no stamp for f001.png"):
        RecordedSource(tmp_path)


def test_video_files_play_back_through_videocapture(tmp_path):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (64, 48), False)
    assert writer.isOpened()
    for img, _ in small_frames(5):
        writer.write(img)
    writer.release()
    frames = list(RecordedSource(path))
    assert len(frames) == 5 and frames[0].image.shape == (48, 64)
    assert [f.stamp_s for f in frames] == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4])
    # A live source stamps frames with its clock at grab time.
    ticks = iter([5.0, 5.1, 5.2])
    with VideoCaptureSource(str(path), clock=lambda: next(ticks)) as live:
        assert [live.read().stamp_s for _ in range(3)] == [5.0, 5.1, 5.2]


def test_missing_cameras_and_recordings_are_clear_errors(tmp_path):
    with pytest.raises(DeviceError, match="could not be opened"):
        open_source("97")
    with pytest.raises(ConfigError, match="no such file"):
        open_source(str(tmp_path / "nothing.npz"))
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(ConfigError, match="expected a folder of images"):
        RecordedSource(tmp_path / "notes.txt")
    with pytest.raises(ConfigError, match="holds no images"):
        RecordedSource(tmp_path)


def test_a_recorded_sequence_replays_into_the_tracker_like_the_live_one(
    tmp_path, camera, calibration, renderer
):
    pin = STANDARD_PARTS[0]
    rendered = [
        renderer.render(
            [RenderPart.of("pin", pin.footprint, (0.01 * k, 0.0, 0.1 * k), pin.height_m)], 0.1 * k
        )
        for k in range(3)
    ]
    save_npz_recording(tmp_path / "seq.npz", rendered)
    live = PartTracker(camera, [pin], calibration=calibration)
    replay = PartTracker(camera, [pin], calibration=calibration)
    for direct, frame in zip(rendered, open_source(str(tmp_path / "seq.npz"))):
        a, b = live.update(direct.image, direct.stamp_s), replay.update(frame.image, frame.stamp_s)
        assert a.parts[0].status == b.parts[0].status == TrackStatus.TRACKED
        np.testing.assert_array_equal(a.parts[0].pose, b.parts[0].pose)

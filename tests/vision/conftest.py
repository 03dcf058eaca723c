"""Shared fixtures for the vision tests: the default camera, its exact calibration, a renderer.

The calibration is session-scoped so that its per-pixel plate map is computed once for all the
trackers the tests build (they receive it instead of calibrating from markers, except where the
calibration itself is under test).
"""

import cv2
import pytest

from ppod_ros.vision import CameraConfig, PlateCalibration
from ppod_sim.camera import CameraRenderer

# Tests run on 2 shared cores: keep OpenCV from spawning its own thread pool.
cv2.setNumThreads(1)


@pytest.fixture(scope="session")
def camera() -> CameraConfig:
    return CameraConfig()


@pytest.fixture(scope="session")
def nominal_camera(camera) -> CameraConfig:
    """What a lab file would state before calibration: centred, looking straight down."""
    return camera.with_changes(position_m=(0.0, 0.0, 0.70), rotation_deg=(0.0, 0.0, 0.0))


@pytest.fixture(scope="session")
def calibration(camera) -> PlateCalibration:
    cal = PlateCalibration.nominal(camera)
    cal.pixel_map(cal.window_of_region(camera.plate.work_area_m[:2], camera.plate.work_area_m[2:]))
    return cal


@pytest.fixture(scope="session")
def stack_camera_path() -> str:
    """The stack's own camera file (640 x 512), as ``ppod up`` gives the simulator and the tracker."""
    from importlib import resources

    return str(resources.files("ppod_ros") / "data" / "camera_640.yaml")


@pytest.fixture(scope="session")
def stack_camera(stack_camera_path) -> CameraConfig:
    return CameraConfig.from_yaml(stack_camera_path)


@pytest.fixture
def renderer(camera) -> CameraRenderer:
    return CameraRenderer(camera, seed=7)

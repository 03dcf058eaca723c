"""Calibration recovers the plate-to-image mapping within stated bounds.

Bounds: over the work area, the fitted mapping agrees with the true camera to 0.05 mm on the plate
(about 0.12 px) from the fiducials or a flat checkerboard, and intrinsics from checkerboard views
reproduce the true projection to 0.3 px over the plate.
"""

import math

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.vision import (
    CalibrationError,
    Checkerboard,
    PlateCalibration,
    calibrate_intrinsics,
    calibrate_plate_from_checkerboard,
    calibrate_plate_from_markers,
    detect_markers,
)
from ppod_sim.camera import CameraRenderer, Occluder, board_pose_flat, tilted_board_pose


def work_area_grid(camera, n=9):
    x0, x1, y0, y1 = camera.plate.work_area_m
    x, y = np.meshgrid(np.linspace(x0, x1, n), np.linspace(y0, y1, n))
    return np.stack([x.ravel(), y.ravel()], axis=1)


def mapping_error_m(fitted: PlateCalibration, true: PlateCalibration, pts: np.ndarray) -> float:
    """Largest plate-frame distance between where the fitted and true mappings put each pixel."""
    uv = true.plate_to_image(pts)
    return float(np.max(np.linalg.norm(fitted.image_to_plate(uv) - pts, axis=1)))


def test_markers_give_the_plate_pose_from_a_nominal_mount(camera, nominal_camera, renderer):
    frame = renderer.render([])
    assert sorted(detect_markers(frame.image, camera.plate)) == list(range(8))
    cal = calibrate_plate_from_markers(frame.image, nominal_camera)
    assert cal.source == "markers" and cal.n_points == 32 and cal.rms_px < 0.3
    true = PlateCalibration.nominal(camera)
    pts = work_area_grid(camera)
    assert mapping_error_m(cal, true, pts) < 5e-5
    assert np.max(np.abs(cal.plate_to_image(pts) - true.plate_to_image(pts))) < 0.12
    np.testing.assert_allclose(cal.camera_centre_m, camera.position_m, atol=2e-3)


def test_markers_calibrate_the_plate_where_the_triggered_camera_sees_it(camera, nominal_camera, renderer):
    # The plate is displaced by its vibration at the frame's phase; the fitted pose must describe
    # the displaced plate, so parts measured in it are in plate coordinates.
    d = np.array([2.5e-4, -1.5e-4, 1e-4, 0.0, 4e-4, 0.0])
    frame = renderer.render([], plate_displacement=d)
    cal = calibrate_plate_from_markers(frame.image, nominal_camera)
    pts = work_area_grid(camera)
    import cv2

    R, _ = cv2.Rodrigues(d[3:])
    moved = np.concatenate([pts, np.zeros((len(pts), 1))], axis=1) @ R.T + d[:3]
    uv_true = renderer.project(moved)
    assert np.max(np.linalg.norm(cal.image_to_plate(uv_true) - pts, axis=1)) < 5e-5


def test_too_few_visible_markers_is_an_error_that_says_so(camera, nominal_camera, renderer):
    hide = [
        Occluder(
            np.array(
                [[x - 0.02, y - 0.02], [x + 0.02, y - 0.02], [x + 0.02, y + 0.02], [x - 0.02, y + 0.02]]
            ),
            0.01,
        )
        for _, x, y in camera.plate.markers[:6]
    ]
    frame = renderer.render([], occluders=hide)
    with pytest.raises(CalibrationError, match="found 2 of the plate's 8 markers"):
        calibrate_plate_from_markers(frame.image, nominal_camera)


def test_a_checkerboard_flat_on_the_plate_gives_the_same_mapping(camera, nominal_camera, renderer):
    # A board that spans most of the work area (a small one extrapolates its tilt error).
    board = Checkerboard(11, 8, 0.02)
    pose = (-0.093, -0.083, 0.05)
    frame = renderer.render_checkerboard(board, *board_pose_flat(*pose))
    cal = calibrate_plate_from_checkerboard(frame.image, board, nominal_camera, pose)
    assert cal.source == "checkerboard" and cal.n_points == 88 and cal.rms_px < 0.3
    assert mapping_error_m(cal, PlateCalibration.nominal(camera), work_area_grid(camera)) < 5e-5


def test_checkerboard_rejects_a_square_board_whose_orientation_is_ambiguous():
    with pytest.raises(ConfigError, match="differ"):
        Checkerboard(6, 6, 0.02)


@pytest.mark.slow
def test_intrinsics_from_tilted_checkerboard_views_reproduce_the_true_projection(camera):
    renderer = CameraRenderer(camera, seed=11)
    board = Checkerboard(9, 6, 0.022)
    views = []
    for i, (tx, ty, yaw, z) in enumerate(
        [
            (0.35, 0.0, 0.1, 0.05),
            (-0.35, 0.1, -0.2, 0.08),
            (0.0, 0.4, 0.3, 0.1),
            (0.1, -0.4, 0.0, 0.06),
            (0.3, 0.3, 1.2, 0.12),
            (-0.3, -0.25, 2.0, 0.1),
            (0.2, -0.1, -1.0, 0.15),
            (-0.15, 0.3, 0.6, 0.04),
        ]
    ):
        # Centre the board below the camera, then tilt it about its centre.
        rvec, _ = tilted_board_pose(0, 0, 0, tx, ty, yaw)
        import cv2

        R, _ = cv2.Rodrigues(rvec)
        centre = np.array([board.cols - 1, board.rows - 1, 0]) * board.square_m / 2
        offset = np.array([0.04 * math.cos(i), 0.04 * math.sin(i), z])
        views.append(renderer.render_checkerboard(board, rvec, offset - R @ centre).image)
    result = calibrate_intrinsics(views, board)
    assert result.rms_px < 0.2 and len(result.per_view_rms_px) == len(views)
    np.testing.assert_allclose(result.camera_matrix[[0, 1], [0, 1]], [camera.fx, camera.fy], rtol=0.01)
    # What matters downstream: with these intrinsics, the markers give the true plate mapping
    # (the plate pose absorbs the small principal-point error of a few views).
    true = PlateCalibration.nominal(camera)
    start = PlateCalibration(
        result.camera_matrix, result.dist_coeffs, true.rvec, true.tvec, camera.width, camera.height
    )
    cal = calibrate_plate_from_markers(renderer.render([]).image, start, camera.plate)
    assert mapping_error_m(cal, true, work_area_grid(camera)) < 1e-4


def test_intrinsics_need_enough_views():
    blank = np.full((256, 320), 60, np.uint8)
    with pytest.raises(CalibrationError, match="found in 0 views"):
        calibrate_intrinsics([blank, blank], Checkerboard(9, 6, 0.02))

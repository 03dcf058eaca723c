import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ppod_ros.errors import ConfigError
from ppod_ros.vision import CameraConfig, PlateCalibration

finite = st.floats(min_value=-0.17, max_value=0.17, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(x=finite, y=finite, z=st.floats(min_value=0.0, max_value=0.02))
def test_image_to_plate_inverts_plate_to_image_anywhere_on_the_plate(x, y, z):
    cal = PlateCalibration.nominal(CameraConfig())
    uv = cal.plate_to_image([[x, y]], z)
    back = cal.image_to_plate(uv, z)
    np.testing.assert_allclose(back[0], [x, y], atol=1e-9)


@settings(max_examples=30, deadline=None)
@given(x=finite, y=finite, z=st.floats(min_value=0.0, max_value=0.02))
def test_lift_moves_a_surface_point_to_where_its_ray_meets_a_raised_plane(x, y, z):
    cal = PlateCalibration.nominal(CameraConfig())
    uv = cal.plate_to_image([[x, y]], z)
    on_surface = cal.image_to_plate(uv, 0.0)
    np.testing.assert_allclose(cal.lift(on_surface[0], z), [x, y], atol=1e-9)


def test_pixel_map_areas_add_up_to_the_plate_area_they_cover(calibration):
    window = (400, 300, 700, 600)
    pm = calibration.pixel_map(window)
    assert pm.x_m.shape == (300, 300) and pm.window == window
    # The window's outline on the plate, from its outer pixel corners.
    u0, v0, u1, v1 = window
    edge = (
        np.concatenate(
            [
                np.stack([np.linspace(u0, u1, 301), np.full(301, v0)], 1),
                np.stack([np.full(301, u1), np.linspace(v0, v1, 301)], 1),
                np.stack([np.linspace(u1, u0, 301), np.full(301, v1)], 1),
                np.stack([np.full(301, u0), np.linspace(v1, v0, 301)], 1),
            ]
        )
        - 0.5
    )
    xy = calibration.image_to_plate(edge)
    area = 0.5 * abs(np.dot(xy[:, 0], np.roll(xy[:, 1], -1)) - np.dot(xy[:, 1], np.roll(xy[:, 0], -1)))
    assert pm.area_m2.sum(dtype=np.float64) == pytest.approx(area, rel=1e-5)
    # Pixel centres map like single points do.
    np.testing.assert_allclose(
        [pm.x_m[10, 20], pm.y_m[10, 20]], calibration.image_to_plate([[420, 310]])[0], atol=1e-7
    )


def test_pixel_size_on_the_plate_matches_the_focal_length_and_height(calibration, camera):
    assert calibration.pixel_size_m() == pytest.approx(camera.position_m[2] / camera.fx, rel=0.02)


def test_calibration_rejects_a_camera_below_the_plate_and_bad_windows(calibration):
    with pytest.raises(ConfigError, match="above the plate"):
        PlateCalibration(
            calibration.camera_matrix, calibration.dist_coeffs, [0.0, 0.0, 0.0], [0, 0, 0.5], 1280, 1024
        )
    with pytest.raises(ConfigError, match="window"):
        calibration.pixel_map((0, 0, 2000, 10))


def test_calibration_round_trips_through_a_dict(calibration):
    again = PlateCalibration.from_dict(calibration.to_dict())
    np.testing.assert_allclose(
        again.plate_to_image([[0.05, -0.02]]), calibration.plate_to_image([[0.05, -0.02]])
    )

import math

import cv2
import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion
from ppod_ros.parts import Footprint, published_rigid_part
from ppod_ros.vision import BlobDetector
from ppod_sim.camera import (
    CameraRenderer,
    Lighting,
    RenderPart,
    SensorModel,
    TriggeredCamera,
    frame_times_s,
    trigger_time_s,
)

CLEAN = SensorModel(blur_sigma_px=0.0, read_noise_dn=0.0, shot_noise_dn2_per_dn=0.0)
FLAT = Lighting(gradient_u=0.0, gradient_v=0.0, vignetting=0.0)


def disk(x=0.0, y=0.0, r=0.006, height=0.0):
    return RenderPart.of("disk", Footprint.from_value({"disk": r}), (x, y, 0.0), height)


def test_the_same_seed_and_frame_index_render_the_same_image(camera):
    a = CameraRenderer(camera, seed=3).render([disk()], 0.0, index=5)
    b = CameraRenderer(camera, seed=3).render([disk()], 0.0, index=5)
    c = CameraRenderer(camera, seed=3).render([disk()], 0.0, index=6)
    assert a.image.dtype == np.uint8 and a.image.shape == (camera.height, camera.width)
    assert np.array_equal(a.image, b.image)
    assert not np.array_equal(a.image, c.image)


def test_edges_are_anti_aliased_so_pixel_sums_give_the_area(camera, calibration):
    r = CameraRenderer(camera, sensor=CLEAN, lighting=FLAT)
    plate_only = r.render([], 0.0).image.astype(float)
    with_part = r.render([disk(0.01, -0.02)], 0.0).image.astype(float)
    diff = with_part - plate_only
    inside = diff.max()
    partial = (diff > 0.05 * inside) & (diff < 0.95 * inside)
    assert partial.sum() > 50  # a ring of partly covered pixels, not a hard 0/1 edge
    # Coverage times each pixel's plate area sums to the disk's area (quantisation to 8 bits and
    # the 1/64 sub-pixel grid allow a few parts in a thousand).
    window = calibration.window_of_region((0.0, 0.02), (-0.03, -0.01), margin_px=6)
    pm = calibration.pixel_map(window)
    u0, v0, u1, v1 = window
    assert not diff[:v0].any() and not diff[v1:].any() and not diff[:, :u0].any() and not diff[:, u1:].any()
    area = np.sum(diff[v0:v1, u0:u1] / inside * pm.area_m2)
    assert area == pytest.approx(math.pi * 0.006**2, rel=0.004)


def test_bgr8_frames_have_three_equal_channels(camera):
    cfg = camera.with_changes(encoding="bgr8")
    img = CameraRenderer(cfg).render([disk()]).image
    assert img.shape == (camera.height, camera.width, 3)
    assert np.array_equal(img[..., 0], img[..., 2])


def test_ground_truth_comes_back_and_flags_parts_outside_the_image(camera, renderer):
    part = RenderPart.of("rigid", published_rigid_part(), (0.02, 0.01, 0.4), 0.002)
    frame = renderer.render([part, disk(0.5, 0.0)], 1.5)
    assert frame.stamp_s == 1.5 and len(frame.truth) == 2
    t0, t1 = frame.truth
    assert (t0.label, t0.x_m, t0.y_m, t0.theta_rad, t0.in_image) == ("rigid", 0.02, 0.01, 0.4, True)
    assert not t1.in_image


def test_the_plate_vibration_displacement_moves_the_parts_with_the_plate(camera, calibration):
    r = CameraRenderer(camera, sensor=CLEAN, lighting=FLAT)
    det = BlobDetector(calibration, camera.plate)
    at_rest = det.detect(r.render([disk(0.03, 0.02)]).image)
    moved = det.detect(r.render([disk(0.03, 0.02)], plate_displacement=[3e-4, -2e-4, 0, 0, 0, 0]).image)
    assert len(at_rest) == len(moved) == 1
    np.testing.assert_allclose(moved[0].centroid_m - at_rest[0].centroid_m, [3e-4, -2e-4], atol=1.5e-5)


def test_the_plate_and_markers_warped_with_the_vibration_match_them_re_rasterised(camera, nominal_camera):
    # The static layer is rendered once at rest and moved per frame by the homography the plate's
    # displacement induces; it must be what re-rasterising at the displacement gives: the same
    # marker calibration and the same plate points, to far below what the tracker resolves.
    from ppod_ros.vision.calibration import calibrate_plate_from_markers

    r = CameraRenderer(camera, sensor=CLEAN, lighting=FLAT)
    d = np.array([3e-4, -2e-4, 1e-4, 2e-3, -1e-3, 3e-3])  # a strong 30 Hz vibration's displacement
    H = r.plate_homography(d)
    uv0 = r.project(r._plate_grid)
    moved = cv2.perspectiveTransform(uv0.reshape(-1, 1, 2), H).reshape(-1, 2)
    assert np.abs(moved - r.project(r._plate_grid, d)).max() < 0.01  # px
    warped, exact = r._static_layer(d), r._render_static(d)
    assert np.abs(warped - exact).mean() < 2e-3 and abs(warped.sum() / exact.sum() - 1) < 1e-4
    # The markers in either layer give the displaced plate's pose equally well (13-27 um here).
    pts = np.array([[x, y] for x in (-0.06, 0.0, 0.06) for y in (-0.06, 0.0, 0.06)])
    R, _ = cv2.Rodrigues(d[3:])
    uv_true = r.project(np.concatenate([pts, np.zeros((len(pts), 1))], axis=1) @ R.T + d[:3])
    errors = []
    for layer in (warped, exact):
        cal = calibrate_plate_from_markers(np.clip(layer * 255, 0, 255).astype(np.uint8), nominal_camera)
        errors.append(np.max(np.linalg.norm(cal.image_to_plate(uv_true) - pts, axis=1)))
    assert errors[0] < 3.5e-5 and errors[0] < errors[1] + 1e-5, errors  # m
    assert r._static_layer(None) is r._static_layer(np.zeros(6))  # at rest: the layer itself


def test_a_lighting_schedule_changes_the_image_over_time(camera):
    r = CameraRenderer(camera, sensor=CLEAN, lighting=lambda t: Lighting(brightness=1.0 if t < 1 else 0.5))
    bright, dim = r.render([], 0.0).image, r.render([], 2.0).image
    assert dim.mean() == pytest.approx(bright.mean() / 2, rel=0.02)


def test_the_camera_triggers_at_the_first_cycle_start_after_each_tick():
    assert trigger_time_s(0.1, 30.0) == pytest.approx(0.1)
    assert trigger_time_s(0.101, 30.0) == pytest.approx(4 / 30)
    t = frame_times_s(0.0, 1.0, 10.0, 27.0)
    assert len(t) == 10
    np.testing.assert_allclose(t * 27.0, np.round(t * 27.0), atol=1e-9)  # all at cycle starts
    assert np.all(t >= np.arange(10) / 10) and np.all(t - np.arange(10) / 10 < 1 / 27)


def test_a_triggered_camera_sees_the_plate_at_the_same_phase_every_frame(camera):
    motion = PlateMotion.single(30.0, [10, 0, 0, 0, 100, 0], [0, 0, 0, 0, 3 * math.pi / 2, 0])
    cam = TriggeredCamera(CameraRenderer(camera, sensor=CLEAN), motion)
    times = [cam.next_trigger(0.0), cam.next_trigger(0.0), cam.next_trigger(0.0)]
    np.testing.assert_allclose(np.diff(times), [0.1, 0.1], atol=1e-9)
    d = [cam.plate_displacement(t) for t in times]
    np.testing.assert_allclose(d[0], d[1], atol=1e-12)
    np.testing.assert_allclose(d[0], motion.displacement(0.0), atol=1e-12)
    frame = cam.capture([disk()], times[1])
    np.testing.assert_allclose(frame.plate_displacement, d[1])


def test_renderer_rejects_bad_inputs(camera, renderer):
    with pytest.raises(ConfigError, match="plate_displacement"):
        renderer.render([], plate_displacement=[0.01, 0, 0, 0, 0, 0])
    with pytest.raises(ConfigError, match="outline"):
        RenderPart("bad", np.zeros((2, 2)), 0.0, 0.0, 0.0)
    with pytest.raises(ConfigError, match="point part needs a footprint"):
        from ppod_ros.parts import PointPart

        RenderPart.of("p", PointPart(), (0, 0, 0))
    with pytest.raises(ConfigError, match="supersample"):
        CameraRenderer(camera, supersample=0)

"""PartTracker on rendered sequences: ids, status and poses through motion, dropped frames,
parts leaving the view, touching, occlusion, lighting changes and bad frames.

Bounds for every TRACKED report: position within 0.1 mm, orientation within 0.3 degrees.
"""

import math

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.parts import Footprint
from ppod_ros.vision import (
    BadFrameError,
    PartSpec,
    PartTracker,
    TrackerSettings,
    TrackStatus,
    load_part_specs,
    load_tracker_config,
    wrap_angle,
)
from ppod_sim.camera import CameraRenderer, Lighting, Occluder, RenderPart, SceneStyle

PIN = PartSpec("pin", Footprint.from_value({"rect": [0.008, 0.024]}), 0.004)
WASHER = PartSpec("washer", Footprint.from_value({"disk": 0.006}), 0.002)
TAB = PartSpec(
    "tab",
    Footprint.from_value({"polygon": [[-0.01, -0.006], [0.01, -0.006], [0.005, 0.006], [-0.005, 0.006]]}),
    0.003,
)
POS_TOL_M = 1e-4
THETA_TOL_RAD = math.radians(0.3)


def render(renderer, placed, t, **kw):
    return renderer.render(
        [RenderPart.of(s.label, s.footprint, tuple(p), s.height_m) for s, p in placed], t, **kw
    )


def check_pose(report, truth):
    assert math.hypot(report.x_m - truth[0], report.y_m - truth[1]) < POS_TOL_M
    if report.symmetry_rad > 0:
        assert abs(wrap_angle(report.theta_rad - truth[2], report.symmetry_rad)) < THETA_TOL_RAD


def nearest(result, xy):
    return min(result.parts, key=lambda p: math.hypot(p.x_m - xy[0], p.y_m - xy[1]))


def linear(start, velocity, t):
    return np.asarray(start, float) + np.asarray(velocity, float) * t


@pytest.mark.parametrize("dropped", [False, True], ids=["every frame", "frames 5-9 dropped"])
def test_moving_parts_keep_their_ids_and_get_velocity_estimates(camera, calibration, renderer, dropped):
    motions = [
        (PIN, (-0.05, -0.03, 0.2), (0.008, 0.004, 0.3)),
        (WASHER, (0.04, 0.05, 0.0), (-0.006, 0.0, 0.0)),
        (TAB, (0.05, -0.06, 2.0), (0.0, 0.01, -0.4)),
    ]
    tracker = PartTracker(camera, [PIN, WASHER, TAB], calibration=calibration)
    ids = None
    frames = [k for k in range(20) if not (dropped and 5 <= k <= 9)]
    for k in frames:
        t = k / camera.fps
        truths = [linear(start, vel, t) for _, start, vel in motions]
        result = tracker.update(
            render(renderer, [(s, p) for (s, _, _), p in zip(motions, truths)], t).image, t
        )
        assert len(result.parts) == 3 and all(p.status == TrackStatus.TRACKED for p in result.parts)
        reports = [nearest(result, p) for p in truths]
        if ids is None:
            ids = [r.id for r in reports]
            assert sorted(result.new_ids) == sorted(ids)
        assert [r.id for r in reports] == ids and not result.new_ids or k == 0
        for r, p in zip(reports, truths):
            check_pose(r, p)
    for r, (spec, _, vel) in zip(reports, motions):
        assert r.label == spec.label and r.symmetry_rad == pytest.approx(spec.symmetry_rad)
        np.testing.assert_allclose(r.velocity[:2], vel[:2], atol=1e-3)
        if spec.symmetry_rad > 0:
            assert r.omega_radps == pytest.approx(vel[2], abs=0.03)
            assert np.all(np.linalg.eigvalsh(r.covariance) > 0)
        else:
            assert r.theta_rad == 0.0 and r.omega_radps == 0.0 and math.isinf(r.covariance[2, 2])
        assert r.covariance[0, 0] < (5e-5) ** 2


def test_a_part_leaving_and_reentering_the_view_is_reported_lost_then_reacquired(
    camera, calibration, renderer
):
    tracker = PartTracker(camera, [PIN], TrackerSettings(max_coast_s=0.5), calibration=calibration)
    statuses, reasons, lost_pose = [], set(), None
    for k in range(31):
        t = k / camera.fps
        # Out through the work area's +x edge (x = 0.125 m) and back to where it left.
        pose = (0.095 + 0.07 * math.sin(math.pi * t / 3.0), 0.01, 0.6)
        result = tracker.update(render(renderer, [(PIN, pose)], t).image, t)
        assert len(result.parts) == 1
        p = result.parts[0]
        statuses.append(p.status)
        if p.status == TrackStatus.TRACKED:
            check_pose(p, pose)
        else:
            reasons.add(p.reason)
        if p.status == TrackStatus.LOST:
            # The pose of a lost part is its last measured one, never an extrapolation.
            lost_pose = p.pose if lost_pose is None else lost_pose
            np.testing.assert_allclose(p.pose, lost_pose)
            assert p.x_m < 0.125
        if p.reacquired:
            assert p.status == TrackStatus.TRACKED and result.reacquired_ids == (p.id,)
    assert p.id == 1 and tracker._next_id == 2  # one part, one id, all along
    assert statuses[0] == TrackStatus.TRACKED and statuses[-1] == TrackStatus.TRACKED
    assert TrackStatus.LOST in statuses and TrackStatus.PREDICTED in statuses
    first_lost = statuses.index(TrackStatus.LOST)
    assert TrackStatus.TRACKED in statuses[first_lost:]
    assert reasons <= {"edge", "out_of_view"} and "edge" in reasons


def test_two_parts_touching_are_reported_not_guessed_and_keep_their_ids(camera, calibration, renderer):
    tracker = PartTracker(camera, [WASHER], calibration=calibration)
    seen_reasons, left_id, right_id = set(), None, None
    for k in range(26):
        t = k / camera.fps
        # Two identical washers close in at 15 mm/s each, touch for 0.4 s, and back off.
        half_gap = 0.009 - 0.015 * t if t < 0.8 else (-0.003 if t < 1.2 else -0.003 + 0.015 * (t - 1.2))
        left = (-0.006 - half_gap - 0.0, 0.02, 0.0)
        right = (0.006 + half_gap, 0.02, 0.0)
        result = tracker.update(render(renderer, [(WASHER, left), (WASHER, right)], t).image, t)
        assert len(result.parts) == 2
        for p in result.parts:
            if p.status == TrackStatus.TRACKED:
                truth = left if abs(p.x_m - left[0]) < abs(p.x_m - right[0]) else right
                check_pose(p, truth)
            else:
                seen_reasons.add(p.reason)
        if k == 0:
            left_id, right_id = nearest(result, left).id, nearest(result, right).id
        if result.unexplained:
            assert {b.kind for b in result.unexplained} <= {"merged", "touching"}
    assert seen_reasons and seen_reasons <= {"merged", "touching"}
    assert result.with_status(TrackStatus.TRACKED) == result.parts
    assert nearest(result, left).id == left_id and nearest(result, right).id == right_id
    assert tracker._next_id == 3


def test_an_occluded_part_is_predicted_then_lost_then_reacquired(camera, calibration, renderer):
    tracker = PartTracker(camera, [TAB], TrackerSettings(max_coast_s=0.5), calibration=calibration)
    pose = (-0.02, 0.03, 1.0)
    statuses, reasons = [], set()
    for k in range(22):
        t = k / camera.fps
        # A dark tool sweeps over the part between 0.4 s and 1.5 s.
        cover = 0.4 <= t <= 1.5
        occ = (
            [Occluder(np.array([[-0.05, 0.0], [0.01, 0.0], [0.01, 0.06], [-0.05, 0.06]]), 0.05, 0.05)]
            if cover
            else []
        )
        result = tracker.update(render(renderer, [(TAB, pose)], t, occluders=occ).image, t)
        p = result.parts[0]
        statuses.append(p.status)
        if p.status == TrackStatus.TRACKED:
            check_pose(p, pose)
        else:
            reasons.add(p.reason)
    assert statuses[:4] == [TrackStatus.TRACKED] * 4 and statuses[-1] == TrackStatus.TRACKED
    assert TrackStatus.PREDICTED in statuses and TrackStatus.LOST in statuses
    assert reasons <= {"missed", "occluded"} and p.id == 1


def test_a_lighting_change_does_not_disturb_tracking(camera, calibration):
    def lighting(t):
        if t < 0.5:
            return Lighting()
        return Lighting(brightness=0.55, gradient_u=-0.35, gradient_v=0.2, vignetting=0.3)

    renderer = CameraRenderer(camera, seed=2, lighting=lighting)
    tracker = PartTracker(camera, [PIN, TAB], calibration=calibration)
    for k in range(10):
        t = k / camera.fps
        placed = [
            (PIN, linear((0.06, -0.02, 0.4), (0.0, 0.01, 0.2), t)),
            (TAB, linear((-0.07, 0.08, -1), (0.01, 0, 0), t)),
        ]
        result = tracker.update(render(renderer, placed, t).image, t)
        assert [p.status for p in result.parts] == [TrackStatus.TRACKED] * 2
        assert [p.id for p in result.parts] == [1, 2]
        for _, pose in placed:
            check_pose(nearest(result, pose), pose)


@pytest.mark.parametrize(
    "frame, stamp, reason",
    [
        (None, 1.0, "empty"),
        (np.zeros((0, 0), np.uint8), 1.0, "empty"),
        ([[0, 1], [2, 3]], 1.0, "not_array"),
        (np.zeros((1024, 1280), np.uint16), 1.0, "dtype"),
        (np.zeros((1024, 1280, 3), np.uint8), 1.0, "encoding"),
        (np.zeros((480, 640), np.uint8), 1.0, "size"),
        (np.zeros((1024, 1280), np.uint8), 1.0, "exposure"),
        (np.full((1024, 1280), 255, np.uint8), 1.0, "exposure"),
        ("good", 0.0, "stamp"),
        ("good", float("nan"), "stamp"),
    ],
)
def test_bad_frames_are_rejected_with_a_reason_and_change_nothing(
    camera, calibration, renderer, frame, stamp, reason
):
    tracker = PartTracker(camera, [PIN], calibration=calibration)
    good = render(renderer, [(PIN, (0.0, 0.0, 0.5))], 0.0).image
    first = tracker.update(good, 0.0)
    with pytest.raises(BadFrameError) as info:
        tracker.update(good if isinstance(frame, str) else frame, stamp)
    assert info.value.reason == reason and tracker.rejected == {reason: 1} and tracker.frames_processed == 1
    after = tracker.update(good, 0.1)
    assert after.frame_index == 1 and after.parts[0].id == first.parts[0].id
    assert after.parts[0].status == TrackStatus.TRACKED


def test_the_first_frame_calibrates_from_the_markers_and_bgr8_frames_work(camera, nominal_camera):
    cfg = camera.with_changes(encoding="bgr8")
    renderer = CameraRenderer(cfg, seed=4)
    tracker = PartTracker(nominal_camera.with_changes(encoding="bgr8"), [PIN])
    pose = (0.03, -0.05, -0.7)
    result = tracker.update(render(renderer, [(PIN, pose)], 0.0).image, 0.0)
    assert tracker.calibration.source == "markers"
    check_pose(result.parts[0], pose)


def test_tracker_settings_and_part_lists_load_strictly():
    s = TrackerSettings.from_dict(
        {"max_coast_s": 2.0, "detector": {"polarity": "dark"}, "filter": {"accel_mps2": 0.1}}
    )
    assert s.max_coast_s == 2.0 and s.detector.polarity == "dark" and s.filter.accel_mps2 == 0.1
    with pytest.raises(ConfigError, match="tracker.gate"):
        TrackerSettings.from_dict({"gate": 1})
    with pytest.raises(ConfigError, match="tracker.detector.polarity"):
        TrackerSettings.from_dict({"detector": {"polarity": "grey"}})
    specs = load_part_specs(
        [{"label": "a", "footprint": {"disk": 0.004}}, {"label": "b", "footprint": {"rect": [0.01, 0.02]}}]
    )
    assert [p.label for p in specs] == ["a", "b"]
    with pytest.raises(ConfigError, match=r"parts\[0\]"):
        load_part_specs([{"label": "a"}])


def test_a_tracker_yaml_gives_part_types_and_settings(tmp_path):
    path = tmp_path / "tracker.yaml"
    path.write_text(
        "parts:\n"
        "  - {label: washer, footprint: {disk: 0.006}, height_m: 0.002}\n"
        "  - {label: bracket, part: {type: rigid, mass: 0.02, inertia: [1.0e-5, 1.0e-6, 1.0e-5],\n"
        "     contacts: [[0.01, -0.03, -0.002], [0.0, 0.03, -0.002], [-0.01, -0.03, -0.002]]}}\n"
        "settings: {max_coast_s: 2.5}\n"
    )
    specs, settings = load_tracker_config(path)
    assert [s.label for s in specs] == ["washer", "bracket"] and settings.max_coast_s == 2.5
    assert specs[1].footprint.kind == "polygon"
    path.write_text("parts: []\nextra: 1\n")
    with pytest.raises(ConfigError, match="tracker.yaml: unknown key: extra"):
        load_tracker_config(path)


def test_dark_parts_on_a_bright_plate_are_tracked_with_the_dark_polarity(camera, calibration):
    renderer = CameraRenderer(camera, seed=5, style=SceneStyle(plate=0.7))
    settings = TrackerSettings.from_dict({"detector": {"polarity": "dark"}})
    tracker = PartTracker(camera, [PIN, WASHER, TAB], settings, calibration=calibration)
    placed = [(PIN, (-0.05, 0.02, 0.7)), (WASHER, (0.0, -0.04, 0.0)), (TAB, (0.06, 0.05, -2.0))]
    frame = renderer.render(
        [RenderPart.of(s.label, s.footprint, p, s.height_m, reflectance=0.08) for s, p in placed], 0.0
    )
    result = tracker.update(frame.image, 0.0)
    assert len(result.parts) == 3 and not result.unexplained
    for spec, pose in placed:
        report = nearest(result, pose)
        assert report.label == spec.label and report.status == TrackStatus.TRACKED
        check_pose(report, pose)


def test_tracker_rejects_duplicate_labels_and_mismatched_calibrations(camera, calibration):
    with pytest.raises(ConfigError, match="unique"):
        PartTracker(camera, [PIN, PIN])
    with pytest.raises(ConfigError, match="made for 1280x1024"):
        PartTracker(camera.with_changes(width=640, height=512), [PIN], calibration=calibration)


@pytest.mark.parametrize("follow", [True, False], ids=["following the plate", "not following"])
def test_poses_are_in_the_vibrating_plates_frame_when_following_its_markers(camera, calibration, renderer, follow):
    # A phase-locked camera catches the plate displaced by the motion (here 0.4 mm, 0.3 mm and
    # 0.25 degrees in plane, plus some heave and tilt): part poses are wanted in the plate's frame.
    disp = np.array([4e-4, -3e-4, 2e-4, 1e-3, -1e-3, math.radians(0.25)])
    tracker = PartTracker(camera, [PIN, TAB], calibration=calibration, settings=TrackerSettings(follow_plate=follow))
    placed = [(PIN, (0.05, -0.04, 0.3)), (TAB, (-0.06, 0.07, -1.0))]
    result = tracker.update(render(renderer, placed, 0.0, plate_displacement=disp).image, 0.0)
    errors = [math.hypot(nearest(result, p).x_m - p[0], nearest(result, p).y_m - p[1]) for _, p in placed]
    if follow:
        for _, pose in placed:
            check_pose(nearest(result, pose), pose)
        shift = tracker.plate_shift
        assert shift.markers >= 3
        assert shift.dx_m == pytest.approx(4e-4, abs=5e-5) and shift.dy_m == pytest.approx(-3e-4, abs=5e-5)
        assert shift.dtheta_rad == pytest.approx(math.radians(0.25), abs=math.radians(0.03))
    else:
        assert min(errors) > 3e-4  # the bias the plate's shift gives without the correction


HEX = PartSpec("hex", Footprint.from_value({"polygon": [[0.008, 0.0], [0.004, 0.006928203], [-0.004, 0.006928203],
                                                        [-0.008, 0.0], [-0.004, -0.006928203], [0.004, -0.006928203]]}),
               0.003)


def test_parts_close_but_apart_are_still_measured(stack_camera):
    # Regression (the demo, 2 of 3 runs failed): a washer at its goal and a hex that came to rest
    # 16-18 mm from it (a gap of 2-4 mm) were both reported "touching" and lost for good, because a
    # blob near another one was never measured; the planner then gave up on the washer. A crowded
    # blob whose fit is clean is a measurement (on the stack's 640 x 512 camera, within 0.3 mm: the
    # pixels within reach of both blobs count for neither, which biases it by a fraction of a pixel).
    from ppod_ros.vision import PlateCalibration

    cam = stack_camera
    cal = PlateCalibration.nominal(cam)
    tracker = PartTracker(cam, [WASHER, HEX], calibration=cal)
    ren = CameraRenderer(cam, seed=7)
    washer, hexa = (-0.03, 0.02, 0.0), (-0.03 + 0.0165, 0.02 + 0.0075, 0.4)
    for k in range(15):
        t = k / cam.fps
        result = tracker.update(render(ren, [(WASHER, washer), (HEX, hexa)], t).image, t)
    assert len(result.parts) == 2
    assert result.with_status(TrackStatus.TRACKED) == result.parts, [(p.label, p.reason) for p in result.parts]
    for truth in (washer, hexa):
        p = nearest(result, truth)
        assert math.hypot(p.x_m - truth[0], p.y_m - truth[1]) < 3e-4


@pytest.mark.parametrize("seed", [0, 1, 4, 7])
def test_the_stacks_half_resolution_camera_calibrates_from_its_markers_to_a_tenth_of_a_millimetre(seed, stack_camera):
    # Regression (the demo ended "done" with a washer 1.88 mm from its goal by the tracker and 2.06 mm
    # by ground truth, tolerance 2 mm): on the stack's 640 x 512 camera the marker corners' sub-pixel
    # window was cut to a fraction of a bit cell, and the calibration from the first frame and the
    # plate's shift in every frame after it were off by up to 0.3 mm, the same for every part.
    # The tracker as the node runs it: calibrated from the markers of its first frame, following
    # the plate. Parts at rest and on the vibrating plate, against ground truth.
    from importlib import resources

    cam = stack_camera
    specs, settings = load_tracker_config(resources.files("ppod_ros") / "data" / "tracker.yaml")
    by_label = {s.label: s for s in specs}
    rng = np.random.default_rng(seed)
    placed = [(by_label[label], (x + rng.uniform(-0.004, 0.004), y + rng.uniform(-0.004, 0.004),
                                 rng.uniform(-math.pi, math.pi)))
              for label, x, y in (("washer", -0.03, 0.02), ("washer", 0.03, 0.03), ("hex", -0.01, -0.04),
                                  ("tile", 0.04, -0.03))]
    renderer = CameraRenderer(cam, seed=seed)
    tracker = PartTracker(cam, specs, settings)
    worst_rest, worst_moving = 0.0, 0.0
    for i in range(16):
        moving = i >= 8   # the plate caught at one displacement of a motion, as a phase-locked camera sees it
        disp = np.array([3e-4, -2e-4, 1e-4, 2e-3, -1e-3, math.radians(0.15)]) if moving else None
        result = tracker.update(render(renderer, placed, 0.1 * i, plate_displacement=disp).image, 0.1 * i)
        if i in (0, 8):
            continue   # a new track's first report, and the first frame after the plate moved
        for _, pose in placed:
            report = nearest(result, pose)
            assert report.status == TrackStatus.TRACKED
            error = math.hypot(report.x_m - pose[0], report.y_m - pose[1])
            if moving:
                worst_moving = max(worst_moving, error)
            else:
                worst_rest = max(worst_rest, error)
    assert worst_rest < 1.2e-4, f"at rest: {1e3 * worst_rest:.3f} mm"
    assert worst_moving < 2.5e-4, f"plate vibrating: {1e3 * worst_moving:.3f} mm"

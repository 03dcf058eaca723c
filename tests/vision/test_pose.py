"""Pose of parts from rendered images: position within 0.1 mm, orientation within 0.2 degrees
(modulo each footprint's symmetry), for disks, rectangles, squares, polygons and a rigid part's
contact triangle, at their heights, under noise, blur and a lighting gradient."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ppod_ros.errors import ConfigError
from ppod_ros.parts import Footprint, PointPart, published_rigid_part
from ppod_ros.vision import BlobDetector, PartSpec, wrap_angle
from ppod_ros.vision.shapes import _polygon_moments
from ppod_sim.camera import RenderPart

SPECS = [
    PartSpec("washer", Footprint.from_value({"disk": 0.006}), 0.002),
    PartSpec("pin", Footprint.from_value({"rect": [0.008, 0.024]}), 0.004),
    PartSpec("tile", Footprint.from_value({"rect": [0.014, 0.014]}), 0.003),
    PartSpec(
        "tab",
        Footprint.from_value({"polygon": [[-0.01, -0.006], [0.01, -0.006], [0.005, 0.006], [-0.005, 0.006]]}),
        0.003,
    ),
    PartSpec(
        "hex",
        Footprint.from_value(
            {
                "polygon": [
                    [0.008 * math.cos(k * math.pi / 3), 0.008 * math.sin(k * math.pi / 3)] for k in range(6)
                ]
            }
        ),
        0.0,
    ),
    PartSpec.from_part("rigid", published_rigid_part(), 0.002),
]


def render_and_fit(renderer, calibration, camera, placed):
    """Render (spec, pose) pairs; return (spec, truth pose, fitted pose) for each part's blob."""
    frame = renderer.render([RenderPart.of(s.label, s.footprint, p, s.height_m) for s, p in placed])
    blobs = BlobDetector(calibration, camera.plate).detect(frame.image)
    assert len(blobs) == len(placed)
    out = []
    for spec, pose in placed:
        blob = min(blobs, key=lambda b: np.hypot(*(b.centroid_m - pose[:2])))
        assert not blob.at_edge and not blob.crowded
        out.append((spec, pose, spec.fit(blob, calibration)))
    return out


def test_parts_of_every_footprint_kind_are_located_within_bounds(renderer, calibration, camera):
    rng = np.random.default_rng(5)
    # The rigid part's 60 mm triangle in the middle, two of each other kind around it.
    ring = [
        (-0.09, -0.08),
        (-0.09, 0.0),
        (-0.09, 0.08),
        (0.09, -0.08),
        (0.09, 0.0),
        (0.09, 0.08),
        (0.0, -0.09),
        (0.0, 0.09),
        (-0.05, -0.09),
        (0.05, 0.09),
        (0.05, -0.09),
        (-0.05, 0.09),
    ]
    placed = [(SPECS[5], np.array([0.0, 0.0, 1.3]))]
    for i, (x, y) in enumerate(ring):
        jitter = rng.uniform(-0.003, 0.003, 2)
        placed.append(
            (SPECS[i % 5], np.array([x + jitter[0], y + jitter[1], rng.uniform(-math.pi, math.pi)]))
        )
    for spec, pose, fit in render_and_fit(renderer, calibration, camera, placed):
        assert math.hypot(fit.x_m - pose[0], fit.y_m - pose[1]) < 1e-4, spec.label
        assert abs(fit.area_ratio - 1) < 0.02 and fit.shape_distance < 0.01 and fit.moment_residual < 0.03
        if spec.symmetry_rad > 0:
            err = wrap_angle(fit.theta_rad - pose[2], spec.symmetry_rad)
            assert abs(err) < math.radians(0.2), (spec.label, math.degrees(err))
            assert -spec.symmetry_rad / 2 <= fit.theta_rad < spec.symmetry_rad / 2
        else:
            assert fit.theta_rad == 0.0


def test_symmetric_parts_report_orientation_modulo_their_symmetry(renderer, calibration, camera):
    tile, pin, tab = SPECS[2], SPECS[1], SPECS[3]
    assert tile.symmetry_rad == pytest.approx(math.pi / 2) and pin.symmetry_rad == pytest.approx(math.pi)
    assert tab.symmetry_rad == pytest.approx(2 * math.pi)
    th = 0.3
    placed = [
        (tile, np.array([-0.08, -0.05, th])),
        (tile, np.array([-0.08, 0.05, th + math.pi / 2])),
        (pin, np.array([0.0, -0.05, th])),
        (pin, np.array([0.0, 0.05, th + math.pi])),
        (tab, np.array([0.08, -0.05, th])),
        (tab, np.array([0.08, 0.05, th + math.pi])),
    ]
    fits = [f for _, _, f in render_and_fit(renderer, calibration, camera, placed)]
    assert fits[0].theta_rad == pytest.approx(th, abs=0.004) and fits[1].theta_rad == pytest.approx(
        th, abs=0.004
    )
    assert fits[2].theta_rad == pytest.approx(th, abs=0.004) and fits[3].theta_rad == pytest.approx(
        th, abs=0.004
    )
    # No symmetry: a half turn is a different, reported orientation.
    assert fits[4].theta_rad == pytest.approx(th, abs=0.004)
    assert fits[5].theta_rad == pytest.approx(wrap_angle(th + math.pi, 2 * math.pi), abs=0.004)


def test_the_top_face_height_is_what_makes_positions_right_off_axis(renderer, calibration, camera):
    tall = PartSpec("block", Footprint.from_value({"rect": [0.012, 0.02]}), 0.015)
    flat = PartSpec("block", tall.footprint, 0.0)
    pose = np.array([0.11, 0.1, 0.4])
    ((_, _, fit),) = render_and_fit(renderer, calibration, camera, [(tall, pose)])
    assert math.hypot(fit.x_m - pose[0], fit.y_m - pose[1]) < 1e-4
    blob = BlobDetector(calibration, camera.plate).detect(
        renderer.render([RenderPart.of("block", tall.footprint, pose, 0.015)]).image
    )[0]
    wrong = flat.fit(blob, calibration)
    assert math.hypot(wrong.x_m - pose[0], wrong.y_m - pose[1]) > 2e-3  # parallax of a 15 mm top face


@settings(max_examples=40, deadline=None)
@given(phi=st.floats(min_value=-math.pi, max_value=math.pi), n=st.integers(min_value=0, max_value=8))
def test_reference_moments_rotate_by_e_to_the_i_n_phi(phi, n):
    v = np.array([[-0.01, -0.006], [0.01, -0.006], [0.005, 0.006], [-0.005, 0.004]])
    c, s = math.cos(phi), math.sin(phi)
    rotated = v @ np.array([[c, s], [-s, c]])
    m0 = _polygon_moments(v, 0j, n)[n]
    m1 = _polygon_moments(rotated, 0j, n)[n]
    assert abs(m1 - np.exp(1j * n * phi) * m0) <= 1e-12 * max(abs(m0), 1e-30) + 1e-24


def test_reference_moments_match_the_rectangle_formulas():
    spec = PartSpec("r", Footprint.from_value({"rect": [0.01, 0.03]}))
    w, length = 0.01, 0.03
    assert spec.area_m2 == pytest.approx(w * length)
    # integral of (x + iy)^2 = integral of x^2 - y^2 over the rectangle
    assert spec._ref["moments"][2].real == pytest.approx((w**3 * length - w * length**3) / 12, rel=1e-12)
    # A half-turn symmetric outline has no odd moments: only even orders carry its angle.
    assert spec.orders[0] == 2 and all(n % 2 == 0 for n in spec.orders)


def test_part_specs_load_strictly_from_mappings():
    spec = PartSpec.from_dict({"label": "w", "footprint": {"disk": 0.005}, "height_m": 0.001})
    assert spec.symmetry_rad == 0.0 and spec.height_m == 0.001
    rigid = PartSpec.from_dict({"label": "r", "part": published_rigid_part().to_dict()})
    assert rigid.footprint.kind == "polygon" and len(rigid.footprint.vertices) == 3
    with pytest.raises(ConfigError, match="exactly one of footprint or part"):
        PartSpec.from_dict({"label": "x"})
    with pytest.raises(ConfigError, match="colour"):
        PartSpec.from_dict({"label": "x", "footprint": {"disk": 0.005}, "colour": "red"})
    with pytest.raises(ConfigError, match="needs a footprint"):
        PartSpec.from_part("p", PointPart())

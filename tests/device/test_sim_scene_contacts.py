"""The simulated plate's non-penetration model: circle covers of outlines, mass-shared pushes."""

import math

import numpy as np
import pytest

from ppod_sim.scene import circle_cover, load_scene, separate

SCENE = "sim_backend/data/scene.yaml"


def _inside_some_circle(points, circles):
    d = np.linalg.norm(points[:, None, :] - circles[None, :, :2], axis=2)
    return np.all((d <= circles[None, :, 2] + 1e-12).any(axis=1))


@pytest.mark.parametrize("outline", [
    np.array([[0.01, -0.03], [0.0, 0.03], [-0.01, -0.03]]),               # the bracket's contact triangle
    np.array([[-0.04, -0.005], [0.04, -0.005], [0.04, 0.005], [-0.04, 0.005]]),  # a long pin
    np.array([[-0.007, -0.007], [0.007, -0.007], [0.007, 0.007], [-0.007, 0.007]]),  # a square tile
])
def test_the_cover_contains_the_outline_and_is_tighter_than_the_bounding_circle(outline):
    circles = circle_cover(outline)
    # Every point of the outline's edges and interior lies in some circle.
    rng = np.random.default_rng(1)
    w = rng.dirichlet(np.ones(len(outline)), size=2000)
    interior = w @ outline
    edges = np.concatenate([a + np.linspace(0, 1, 50)[:, None] * (b - a)
                            for a, b in zip(outline, np.roll(outline, -1, axis=0))])
    assert _inside_some_circle(interior, circles) and _inside_some_circle(edges, circles)
    bounding = np.max(np.hypot(*outline.T))
    covered_area = np.pi * np.sum(circles[:, 2] ** 2)
    assert covered_area <= np.pi * bounding ** 2 + 1e-15
    slender = np.ptp(outline, axis=0).max() / np.ptp(outline, axis=0).min() > 2
    assert (len(circles) > 1) == slender


def test_a_washer_can_sit_beside_a_slender_bracket_where_its_bounding_circle_would_push_it():
    scene = load_scene(SCENE)
    bracket, washer = scene.parts[0], scene.parts[1]
    xy = np.array([[0.0, 0.0], [0.019, 0.0]])  # 19 mm from the bracket's axis: clear of its outline
    v = np.zeros((2, 2))
    moved = separate(xy, v, np.array([0.0, 0.0]), [bracket.circles, washer.circles],
                     np.array([bracket.mass_kg, washer.mass_kg]), np.array([True, True]))
    assert moved.size == 0 and np.allclose(xy, [[0.0, 0.0], [0.019, 0.0]])
    assert bracket.radius_m + washer.radius_m > 0.019  # the old bounding-circle model would have pushed


def test_pushes_are_shared_by_inverse_mass_and_stop_the_approach():
    circles = [np.array([[0.0, 0.0, 0.01]]), np.array([[0.0, 0.0, 0.01]])]
    xy = np.array([[0.0, 0.0], [0.015, 0.0]])  # 5 mm overlap
    v = np.array([[0.0, 0.0], [-0.01, 0.0]])   # the light one runs into the heavy one
    moved = separate(xy, v, np.zeros(2), circles, np.array([9.0, 1.0]), np.array([True, True]))
    assert list(moved) == [0, 1]
    assert xy[1, 0] - xy[0, 0] == pytest.approx(0.02)
    assert xy[0, 0] == pytest.approx(-0.0005) and xy[1, 0] == pytest.approx(0.0195)  # 10 % / 90 %
    assert v[1, 0] - v[0, 0] == pytest.approx(0.0)  # no approach left
    assert 9.0 * v[0, 0] + 1.0 * v[1, 0] == pytest.approx(-0.01)  # momentum kept


def test_orientation_places_the_circles_and_inactive_parts_are_ignored():
    long = circle_cover(np.array([[-0.04, -0.005], [0.04, -0.005], [0.04, 0.005], [-0.04, 0.005]]))
    dot = np.array([[0.0, 0.0, 0.004]])
    # Along x the pin reaches 40 mm; turned by 90 degrees it does not reach a part 30 mm away on x.
    for theta, overlaps in ((0.0, True), (math.pi / 2, False)):
        xy = np.array([[0.0, 0.0], [0.03, 0.0]])
        moved = separate(xy, np.zeros((2, 2)), np.array([theta, 0.0]), [long, dot], np.ones(2),
                         np.array([True, True]))
        assert (moved.size > 0) == overlaps
    xy = np.array([[0.0, 0.0], [0.001, 0.0]])
    assert separate(xy, np.zeros((2, 2)), np.zeros(2), [dot, dot], np.ones(2), np.array([True, False])).size == 0

"""Keep-out polygon geometry (cnt_env/task/geometry.py) against hand-worked cases."""

from __future__ import annotations

import numpy as np
import pytest

from cnt_env.task.geometry import (
    FAR,
    in_polygons,
    inside_polygon,
    length_in_polygons,
    nearest_on_boundary,
    nearest_on_polygons,
    outward_normal,
    pack,
)

SQUARE = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
# an L: the square minus its upper-right quarter (concave at (5, 5))
ELL = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 5.0], [5.0, 5.0], [5.0, 10.0], [0.0, 10.0]])


def test_inside_by_the_even_odd_rule_on_a_concave_polygon() -> None:
    pts = np.array([[2.0, 2.0], [8.0, 2.0], [2.0, 8.0], [8.0, 8.0], [-1.0, 5.0], [12.0, 2.0]])
    assert inside_polygon(pts, ELL).tolist() == [True, True, True, False, False, False]
    # the vertex order does not matter
    assert inside_polygon(pts, ELL[::-1]).tolist() == [True, True, True, False, False, False]


def test_in_polygons_counts_a_point_in_two_polygons_once() -> None:
    other = SQUARE + 5.0  # overlaps SQUARE on [5, 10]^2
    pts = np.array([[7.0, 7.0], [2.0, 2.0], [13.0, 13.0], [20.0, 20.0]])
    assert np.count_nonzero(in_polygons(pts, *pack((SQUARE, other)))) == 3
    assert not in_polygons(pts, *pack(())).any()


def test_nearest_on_boundary_projects_on_edges_and_corners() -> None:
    pts = np.array([[5.0, -3.0], [13.0, 14.0], [5.0, 4.0], [7.0, 7.0]])
    near, d = nearest_on_boundary(pts, ELL)
    # below the bottom edge; beyond the corner (5, 10); inside, 1 below the concave
    # corner (5, 5) and 4 above the bottom edge; outside, 2 from both inner edges
    np.testing.assert_allclose(near[0], [5.0, 0.0])
    assert d[0] == pytest.approx(3.0)
    np.testing.assert_allclose(near[1], [5.0, 10.0])  # the vertex (5, 10), not (10, 5)
    assert d[1] == pytest.approx(np.hypot(8.0, 4.0))
    np.testing.assert_allclose(near[2], [5.0, 5.0])
    assert d[2] == pytest.approx(1.0)
    assert d[3] == pytest.approx(2.0)  # (7, 7) is outside, 2 above the edge z = 5


def test_nearest_on_polygons_picks_the_nearest_polygon_and_far_without_any() -> None:
    p = np.array([20.0, 5.0])
    far_right, near_right = SQUARE + np.array([30.0, 0.0]), SQUARE + np.array([23.0, 0.0])
    np.testing.assert_allclose(nearest_on_polygons(p, (SQUARE, far_right)), [10.0, 5.0])
    np.testing.assert_allclose(nearest_on_polygons(p, (near_right, SQUARE)), [23.0, 5.0])
    np.testing.assert_allclose(nearest_on_polygons(p, ()), p + FAR)


def test_a_repeated_vertex_is_a_point_of_the_boundary_not_a_nan() -> None:
    """A closed ring (first vertex repeated at the end) or a repeated vertex has an edge
    of length zero: the nearest point is the same as for the open polygon (it was 0 / 0,
    and argmin picked the NaN)."""
    pts = np.array([[5.0, -3.0], [13.0, 14.0], [5.0, 4.0], [0.0, 0.0]])
    closed = np.vstack([ELL, ELL[:1]])
    doubled = np.insert(ELL, 2, ELL[2], axis=0)
    for poly in (closed, doubled):
        near, d = nearest_on_boundary(pts, poly)
        ref_near, ref_d = nearest_on_boundary(pts, ELL)
        np.testing.assert_array_equal(near, ref_near)
        np.testing.assert_array_equal(d, ref_d)


@pytest.mark.parametrize("order", [1, -1])
def test_outward_normal_points_out_of_each_edge_whatever_the_winding(order: int) -> None:
    poly = ELL[::order]
    cases = {(5.0, 0.0): (0, -1), (10.0, 2.0): (1, 0), (7.0, 5.0): (0, 1),
             (5.0, 8.0): (1, 0), (2.0, 10.0): (0, 1), (0.0, 6.0): (-1, 0)}  # fmt: skip
    for point, normal in cases.items():
        np.testing.assert_allclose(outward_normal(np.array(point), poly), normal, atol=1e-12)
    # a closed ring: its zero-length edge is skipped
    np.testing.assert_allclose(outward_normal(np.array([5.0, 0.0]), np.vstack([poly, poly[:1]])),
                               [0, -1], atol=1e-12)  # fmt: skip


def test_length_in_polygons_closed_forms() -> None:
    """The length of a polyline inside packed polygons: a crossing of the square, a run
    along the concave L (in, out over its notch, in again), two overlapping squares
    counted once, an edge touched only at a corner, and no polygon."""
    across = np.array([[-5.0, 5.0], [15.0, 5.0]])
    assert length_in_polygons(across, *pack((SQUARE,))) == pytest.approx(10.0)
    high = np.array([[-5.0, 7.5], [15.0, 7.5]])  # through the L's upper arm only
    assert length_in_polygons(high, *pack((ELL,))) == pytest.approx(5.0)
    # a polyline, its nodes on both sides and one inside
    bent = np.array([[-5.0, 2.0], [3.0, 2.0], [3.0, 20.0]])
    assert length_in_polygons(bent, *pack((SQUARE,))) == pytest.approx(3.0 + 8.0)
    shifted = SQUARE + np.array([5.0, 0.0])  # overlaps SQUARE over x in [5, 10]
    assert length_in_polygons(across, *pack((SQUARE, shifted))) == pytest.approx(15.0)
    corner = np.array([[-5.0, -5.0], [0.0, 0.0], [-5.0, 5.0]])
    assert length_in_polygons(corner, *pack((SQUARE,))) == pytest.approx(0.0)
    assert length_in_polygons(across, *pack(())) == 0.0


def test_a_pads_electrode_is_one_strip_to_the_image_and_the_score() -> None:
    """The points the image fills as a pad's electrode (in_pad_strips) and the points
    where a short trace segment touches the pad in the score (scoring._touches_strip)
    are one strip, the rectangle of the pad's segment widened by half its width either
    side: the same answer at random points around a slanted pad."""
    from cnt_env.task.geometry import in_pad_strips, inside_polygon
    from cnt_env.task.scoring import _touches_strip

    a, b, half = np.array([3.0, -2.0]), np.array([11.0, 4.0]), 1.5  # length 10
    e = (b - a) / 10.0
    off = half * np.array([-e[1], e[0]])
    rect = np.array([a + off, b + off, b - off, a - off])
    rng = np.random.default_rng(4)
    pts = rng.uniform([-2.0, -8.0], [16.0, 10.0], (4000, 2))
    mine = in_pad_strips(pts, np.array([[a, b]]), half)
    assert 200 < mine.sum() < 3800
    assert np.array_equal(mine, inside_polygon(pts, rect))
    score = [_touches_strip(p[0], p[1], p[0], p[1], a[0], a[1], e[0], e[1], 10.0, half)
             for p in pts]  # fmt: skip
    assert np.array_equal(mine, np.array(score))

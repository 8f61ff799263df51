from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bevflow.analytics.zones import PolygonSet, ZoneIndex, points_in_polygons, zone_lists, zones_by_track
from bevflow.site import Zone

SQUARE = [(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)]
# A "U": a 3 x 3 block with a 1 m wide notch cut down from the top to y = 1.
U_SHAPE = [(0, 0), (3, 0), (3, 3), (2, 3), (2, 1), (1, 1), (1, 3), (0, 3)]
# An "L" drawn clockwise, starting at a reflex vertex.
L_CLOCKWISE = [(1, 1), (1, 3), (0, 3), (0, 0), (3, 0), (3, 1)]


@pytest.mark.parametrize(
    ("polygon", "point", "expected"),
    [
        (SQUARE, (1.0, 1.0), True),
        (SQUARE, (3.0, 1.0), False),
        (SQUARE, (-0.01, 1.0), False),
        # Edges: the rule reads a boundary point as the point a hair above and right of it.
        (SQUARE, (0.0, 1.0), True),  # left edge
        (SQUARE, (2.0, 1.0), False),  # right edge
        (SQUARE, (1.0, 0.0), True),  # bottom edge
        (SQUARE, (1.0, 2.0), False),  # top edge
        (SQUARE, (0.0, 0.0), True),  # bottom-left corner
        (SQUARE, (2.0, 0.0), False),
        (SQUARE, (0.0, 2.0), False),
        (SQUARE, (2.0, 2.0), False),
        # Concave: the notch is outside even though it lies within the bounding box.
        (U_SHAPE, (1.5, 2.0), False),
        (U_SHAPE, (0.5, 2.0), True),
        (U_SHAPE, (2.5, 2.0), True),
        (U_SHAPE, (1.5, 0.5), True),
        (U_SHAPE, (1.5, 1.0), False),  # notch floor: the hair above is in the notch
        (U_SHAPE, (1.0, 2.0), False),  # notch's left wall: the hair right is in the notch
        (U_SHAPE, (2.0, 2.0), True),  # notch's right wall: the hair right is in the right arm
        (U_SHAPE, (1.5, 3.0), False),
        (L_CLOCKWISE, (2.0, 2.0), False),
        (L_CLOCKWISE, (0.5, 2.5), True),
        (L_CLOCKWISE, (2.5, 0.5), True),
        (L_CLOCKWISE, (1.0, 2.0), False),  # right edge of the vertical bar
        (L_CLOCKWISE, (2.0, 1.0), False),  # top edge of the horizontal bar
        (L_CLOCKWISE, (0.0, 0.5), True),
    ],
)
def test_point_in_polygon(polygon: list, point: tuple[float, float], expected: bool) -> None:
    assert points_in_polygons([point], [polygon]).tolist() == [[expected]]


def test_matrix_has_one_row_per_point_and_one_column_per_zone() -> None:
    inside = points_in_polygons([(0.5, 0.5), (2.5, 2), (5, 5)], [SQUARE, U_SHAPE])
    assert inside.dtype == bool
    assert inside.tolist() == [[True, True], [False, True], [False, False]]


@pytest.mark.parametrize(
    ("points", "polygons", "shape"),
    [
        (np.zeros((0, 2)), [SQUARE], (0, 1)),
        ([(1, 1)], [], (1, 0)),
        (np.zeros((0, 2)), [], (0, 0)),
    ],
)
def test_empty_inputs_give_empty_matrices(points: object, polygons: list, shape: tuple[int, int]) -> None:
    assert points_in_polygons(points, polygons).shape == shape


def test_polygon_needs_three_points() -> None:
    with pytest.raises(ValueError, match="at least 3"):
        PolygonSet([[(0, 0), (1, 1)]])


def _triangulated_grid(n: int) -> list[list[tuple[int, int]]]:
    """Cells of an n x n grid, each split into two triangles along a diagonal; half the cells use
    the other diagonal and half the triangles are drawn clockwise."""
    triangles = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = (i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)
            pair = [[a, b, c], [a, c, d]] if (i + j) % 2 else [[a, b, d], [b, c, d]]
            triangles += [t if k % 2 else t[::-1] for k, t in enumerate(pair)]
    return triangles


def test_zones_that_tile_the_floor_count_every_point_exactly_once() -> None:
    # Points on a quarter-metre lattice land on many shared edges, diagonals and vertices.
    g = np.arange(0, 4, 0.25)
    points = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    inside = points_in_polygons(points, _triangulated_grid(4))
    assert inside.sum(axis=1).tolist() == [1] * len(points)


coordinate = st.floats(-1.0, 4.0, allow_nan=False).map(lambda v: round(v * 8) / 8)


@settings(max_examples=60, deadline=None)
@given(points=st.lists(st.tuples(coordinate, coordinate), min_size=1, max_size=30), shift=st.integers(0, 7))
def test_result_does_not_depend_on_drawing_order(points: list, shift: int) -> None:
    ring = U_SHAPE[shift:] + U_SHAPE[:shift]
    forward = points_in_polygons(points, [U_SHAPE])
    assert (points_in_polygons(points, [ring]) == forward).all()
    assert (points_in_polygons(points, [ring[::-1]]) == forward).all()


def test_zone_index_names_columns_and_finds_first_zone() -> None:
    zones = ZoneIndex(
        [
            Zone(id="hall", polygon=[(0, 0), (10, 0), (10, 10), (0, 10)]),
            Zone(id="stand", polygon=[(2, 2), (4, 2), (4, 4), (2, 4)]),
            Zone(id="exit", polygon=[(20, 0), (22, 0), (22, 2)]),
        ]
    )
    assert zones.ids == ("hall", "stand", "exit")
    assert zones.first_zone([(3, 3), (21.5, 0.5), (-5, -5), (8, 1)]) == ["hall", "exit", None, "hall"]
    inside = zones.contains([(3, 3), (21.5, 0.5), (-5, -5)])
    assert zones_by_track(np.array([12, 4, 9]), inside, zones.ids) == {12: ["hall", "stand"], 4: ["exit"], 9: []}


@pytest.mark.parametrize(
    ("inside", "zone_ids", "expected"),
    [
        pytest.param(np.zeros((0, 2), bool), ["a", "b"], [], id="nobody"),
        pytest.param(np.zeros((2, 0), bool), [], [[], []], id="no-zones"),
        pytest.param([[True, False], [False, False], [True, True], [True, False]], ["a", "b"],
                     [["a"], [], ["a", "b"], ["a"]], id="combinations"),
        pytest.param(np.eye(3, 70, 66, dtype=bool), [f"z{k}" for k in range(70)], [["z66"], ["z67"], ["z68"]],
                     id="more-zones-than-bits-in-a-word"),
        pytest.param(np.eye(3, 64, 61, dtype=bool), [f"z{k}" for k in range(64)], [["z61"], ["z62"], ["z63"]],
                     id="sixty-four-zones"),
    ],
)
def test_zone_lists_name_each_rows_zones(inside, zone_ids, expected) -> None:
    assert zone_lists(np.asarray(inside, bool), zone_ids) == expected


def test_zone_lists_are_independent_lists() -> None:
    first, second = zone_lists(np.array([[True], [True]]), ["a"])
    first.append("changed")
    assert second == ["a"]


@pytest.mark.parametrize("inside", [np.zeros((2, 3), bool), np.zeros(2, bool)], ids=["too-wide", "flat"])
def test_zone_lists_refuse_a_matrix_that_does_not_match_the_zones(inside) -> None:
    with pytest.raises(ValueError, match="membership matrix"):
        zone_lists(inside, ["a", "b"])


def test_zones_by_track_needs_one_row_per_track() -> None:
    with pytest.raises(ValueError, match="2 track ids but 1 membership rows"):
        zones_by_track(np.array([1, 2]), np.zeros((1, 1), bool), ["a"])


@settings(max_examples=60, deadline=None)
@given(zones=st.integers(1, 80), people=st.integers(0, 40), seed=st.integers(0, 2**32 - 1))
def test_zone_lists_match_reading_each_row(zones: int, people: int, seed: int) -> None:
    inside = np.random.default_rng(seed).random((people, zones)) < 0.3
    ids = [f"z{k}" for k in range(zones)]
    assert zone_lists(inside, ids) == [[ids[z] for z in np.flatnonzero(row)] for row in inside]

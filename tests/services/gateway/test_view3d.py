from __future__ import annotations

import math
import urllib.request
from collections.abc import Iterator

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from bevflow.site import Site, parse_site

from bevflow_services.gateway import GatewayState, create_app
from bevflow_services.gateway.view3d import (
    LEVEL_COLORS,
    PERSON_COLOR,
    VIOLATION_COLOR,
    View3D,
    floor_extent,
    on_floor,
    person_colors,
    triangulate,
    unit_cylinder,
    vertical_fov,
)
from bevflow_services.launcher import free_port
from tests.services.gateway.feed import S, SITE_YAML, T0, occupancy, tracks


def _get(url: str) -> tuple[int, str]:
    with urllib.request.urlopen(url, timeout=10) as response:
        return response.status, response.read().decode("utf-8", "replace")


@pytest.fixture
def view(state: GatewayState) -> Iterator[View3D]:
    view = View3D(state, port=free_port(), rate_hz=50.0)
    view.start()
    try:
        yield view
    finally:
        view.stop()


def test_the_view_serves_its_page(view: View3D) -> None:
    status, page = _get(f"http://127.0.0.1:{view.port}/")
    assert status == 200 and "<html" in page.lower()


def test_the_view_shows_the_latest_people_with_labels(view: View3D, state: GatewayState) -> None:
    state.apply(tracks(T0, {1: (0.0, 0.0), 2: (1.0, 0.0), 3: (5.0, 5.0)}, [(1, 2)]))
    view.refresh()
    assert (view.shown_people, view.shown_labels) == (3, [1, 2, 3])
    state.apply(tracks(T0 + S, {2: (1.0, 0.5), 4: (6.0, 1.0)}))
    view.refresh()
    assert (view.shown_people, view.shown_labels) == (2, [2, 4])
    state.apply(tracks(T0 + 2 * S, {}))
    view.refresh()
    assert (view.shown_people, view.shown_labels) == (0, [])


def test_zones_are_coloured_by_their_occupancy_level_as_on_the_2d_map(view: View3D, state: GatewayState) -> None:
    shown = lambda: {zone: (area.color, level) for zone, (area, _, level) in view._zones.items()}  # noqa: E731
    state.apply(occupancy(T0, 9, gate=5, shop=6))  # gate over its capacity of 3, shop crowded from 5
    state.apply(tracks(T0, {1: (1.0, 1.0)}))
    view.refresh()
    assert shown() == {"gate": (LEVEL_COLORS["over_capacity"], "over_capacity"), "shop": (LEVEL_COLORS["crowded"], "crowded")}
    state.apply(occupancy(T0 + S, 2, gate=1, shop=1))
    state.apply(tracks(T0 + S, {1: (1.0, 1.0)}))
    view.refresh()
    assert {zone: level for zone, (_, level) in shown().items()} == {"gate": "normal", "shop": "normal"}


def test_violations_get_red_people_lines_and_discs(view: View3D, state: GatewayState) -> None:
    state.apply(tracks(T0, {1: (0.0, 0.0), 2: (1.0, 0.0), 3: (1.5, 1.0), 4: (9.0, 0.0)}, [(1, 2), (2, 3)]))
    view.refresh()
    assert (view.shown_violation_lines, view.shown_violation_discs) == (2, 3)  # two pairs, three people
    state.apply(tracks(T0 + S, {1: (0.0, 0.0), 4: (9.0, 0.0)}))
    view.refresh()
    assert (view.shown_violation_lines, view.shown_violation_discs) == (0, 0)


def test_person_colors_mark_everyone_in_a_violation() -> None:
    message = tracks(T0, {1: (0.0, 0.0), 2: (1.0, 0.0), 3: (5.0, 5.0)}, [(1, 2)])
    assert person_colors(message).tolist() == [list(VIOLATION_COLOR), list(VIOLATION_COLOR), list(PERSON_COLOR)]
    assert person_colors(tracks(T0, {})).shape == (0, 3)


def _area(points: np.ndarray) -> float:
    x, y = points[:, 0], points[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


@pytest.mark.parametrize(
    "polygon",
    [
        pytest.param([(0, 0), (4, 0), (4, 3), (0, 3)], id="rectangle"),
        pytest.param([(0, 3), (4, 3), (4, 0), (0, 0)], id="clockwise rectangle"),
        pytest.param([(0, 0), (4, 0), (4, 1), (1, 1), (1, 4), (0, 4)], id="L shape"),
        pytest.param([(0, 0), (6, 0), (6, 5), (3, 1), (0, 5)], id="deep notch"),
    ],
)
def test_triangulate_covers_a_zone_exactly_once(polygon: list) -> None:
    points = np.asarray(polygon, dtype=float)
    faces = triangulate(points)
    assert faces.shape == (len(points) - 2, 3)
    areas = [_area(points[f]) for f in faces]
    # Every triangle faces up, and together they cover the polygon's area: no overlap, no gap.
    assert min(areas) > 0
    assert sum(areas) == pytest.approx(abs(_area(points)))
    # Each triangle's centroid lies inside the polygon (none bridges the notch of a concave zone).
    contour = points.astype(np.float32).reshape(-1, 1, 2)
    centroids = points[faces].mean(axis=1)
    assert all(cv2.pointPolygonTest(contour, (float(x), float(y)), False) > 0 for x, y in centroids)


def test_on_floor_keeps_the_segments_inside_the_floor() -> None:
    inside, on_edge = [[0, 0, 0], [1, 1, 0]], [[10, 5, 0], [10, 0, 0]]
    crossing, outside = [[9, 9, 0], [11, 9, 0]], [[-1, 0, 0], [-1, 5, 0]]
    segments = np.array([inside, crossing, outside, on_edge], dtype=float)
    assert on_floor(segments, (0.0, 0.0, 10.0, 10.0)).tolist() == [inside, on_edge]


def test_the_app_starts_the_view_with_its_lifespan_and_reports_its_url(site: Site, state: GatewayState) -> None:
    port = free_port()
    with TestClient(create_app(site, state, view3d_port=port)) as client:
        url = client.get("/api/config").json()["view3d_url"]
        assert url == "/view3d/"  # through the gateway, behind its login
        status, page = _get(f"http://127.0.0.1:{port}/")
        assert status == 200 and "<html" in page.lower()
        assert client.get(url).text == page
    assert client.app.state.view3d_port is None  # stopped with the app


def test_unit_cylinder_spans_radius_one_height_one() -> None:
    vertices, faces = unit_cylinder(12)
    assert np.allclose(np.hypot(vertices[:24, 0], vertices[:24, 1]), 1.0)
    assert (vertices[:, 2].min(), vertices[:, 2].max()) == (0.0, 1.0)
    assert faces.shape == (4 * 12, 3) and faces.max() == len(vertices) - 1


def test_floor_extent_is_the_site_floor_or_the_camera_coverage(site: Site) -> None:
    assert floor_extent(site) == (-5.0, -5.0, 15.0, 5.0)
    no_floor = site.model_copy(update={"floor": None})
    # north covers 6 m (its monitored radius) around (0, 0); south has none, so the 5 m default, but
    # the larger reach of the two is used for both.
    assert floor_extent(no_floor) == pytest.approx((-6.0, -6.0, 16.0, 6.0))


@pytest.mark.parametrize(("focal_px", "fov_rad"), [(500, 1.6), (250, math.radians(150))])
def test_vertical_fov_of_an_equidistant_fisheye(focal_px: int, fov_rad: float) -> None:
    # 800 px high: the top and bottom centre pixels are 400 / f rad off axis; wider is capped at 150 degrees.
    site = parse_site(SITE_YAML.replace("fx: 250, fy: 250", f"fx: {focal_px}, fy: {focal_px}"))
    assert vertical_fov(site, "north") == pytest.approx(fov_rad)

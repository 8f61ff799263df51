from __future__ import annotations

import math
import socket
import urllib.request
from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from bevflow.site import Site, parse_site

from bevflow_services.gateway import GatewayState, create_app
from bevflow_services.gateway.view3d import View3D, floor_extent, unit_cylinder, vertical_fov
from tests.services.gateway.feed import S, SITE_YAML, T0, tracks


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _get(url: str) -> tuple[int, str]:
    with urllib.request.urlopen(url, timeout=10) as response:
        return response.status, response.read().decode("utf-8", "replace")


@pytest.fixture
def view(state: GatewayState) -> Iterator[View3D]:
    view = View3D(state, port=_free_port(), rate_hz=50.0)
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


def test_the_app_starts_the_view_with_its_lifespan_and_reports_its_url(site: Site, state: GatewayState) -> None:
    port = _free_port()
    with TestClient(create_app(site, state, view3d_port=port)) as client:
        url = client.get("/api/config").json()["view3d_url"]
        assert url == f"http://testserver:{port}/"
        status, page = _get(f"http://127.0.0.1:{port}/")
        assert status == 200 and "<html" in page.lower()
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

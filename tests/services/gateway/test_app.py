from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from bevflow.site import Site

from bevflow_services.gateway import GatewayState, create_app
from tests.services.gateway.feed import S, T0, occupancy, tracks


def test_root_shows_a_placeholder_until_the_dashboard_exists(site: Site, state: GatewayState, tmp_path: Path) -> None:
    with TestClient(create_app(site, state, dashboard_dir=tmp_path)) as client:
        placeholder = client.get("/")
        assert placeholder.status_code == 200 and "bevflow gateway" in placeholder.text
        (tmp_path / "index.html").write_text("<html><body>floor map</body></html>")
        (tmp_path / "app.js").write_text("console.log('map');")
        page = client.get("/")
        assert page.text == "<html><body>floor map</body></html>" and page.headers["content-type"].startswith("text/html")
        script = client.get("/app.js")
        assert script.text == "console.log('map');" and "javascript" in script.headers["content-type"]
        assert client.get("/missing.css").status_code == 404


def test_the_installed_dashboard_folder_is_served_by_default(client: TestClient) -> None:
    from bevflow_services.gateway.app import DASHBOARD_DIR

    index = DASHBOARD_DIR / "index.html"
    body = client.get("/").text
    if index.is_file():
        assert body == index.read_text(encoding="utf-8")
    else:
        assert "bevflow gateway" in body


def test_the_state_must_be_for_the_same_site(site: Site) -> None:
    other = site.model_copy(update={"site": "other"})
    with pytest.raises(ValueError, match="site 'hall', not 'other'"):
        create_app(other, GatewayState(site))


BAD_REQUESTS = [
    # (path, status, words the message must contain)
    ("/api/occupancy/history?zone=roof", 404, ["zone", "'roof'", "gate, shop"]),
    ("/api/occupancy/history?since=1700000100&until=1700000000", 400, ["since", "after until"]),
    ("/api/occupancy/history?since=1700000000&last_s=60", 400, ["since", "last_s"]),
    ("/api/occupancy/history?step_s=0", 422, ["query parameter step_s", "greater than or equal to 1"]),
    ("/api/occupancy/history?last_s=-5", 422, ["query parameter last_s"]),
    ("/api/occupancy/history?last_s=1e300", 422, ["query parameter last_s"]),
    ("/api/occupancy/history?since=yesterday", 422, ["query parameter since"]),
    ("/api/intervals?zone=roof", 404, ["zone", "'roof'"]),
    ("/api/intervals?min_gap_s=-1", 422, ["query parameter min_gap_s"]),
    ("/api/intervals?level=-2", 422, ["query parameter level"]),
    ("/api/tracks?limit=0", 422, ["query parameter limit"]),
    ("/api/tracks?limit=1001", 422, ["query parameter limit", "less than or equal to 1000"]),
    ("/api/tracks?offset=-1", 422, ["query parameter offset"]),
    ("/api/tracks?zone=roof", 404, ["zone", "'roof'"]),
    ("/api/tracks/abc", 422, ["path parameter track_id", "integer"]),
    ("/api/tracks/-1", 422, ["path parameter track_id"]),
    ("/api/tracks/77", 404, ["track 77"]),
    ("/api/tracks/99999999999999999999999", 404, ["track 99999999999999999999999"]),  # beyond int64: still a 404
    ("/api/tracks/1/contacts?distance_m=0", 422, ["query parameter distance_m"]),
    ("/api/tracks/1/contacts?since=1700000009&until=1700000001", 400, ["since", "after until"]),
    ("/api/violations?active=maybe", 422, ["query parameter active"]),
    ("/api/violations?track=x", 422, ["query parameter track"]),
    ("/api/violations?zone=roof", 404, ["zone", "'roof'"]),
    ("/api/alerts?types=distance_violation,fire", 400, ["types", "fire", "over_capacity"]),
    ("/api/cameras/east", 404, ["camera_id", "'east'", "north, south"]),
    ("/api/nothing-here", 404, []),
]


@pytest.mark.parametrize(("path", "status", "words"), BAD_REQUESTS, ids=[p for p, _, _ in BAD_REQUESTS])
def test_bad_requests_get_a_4xx_that_names_the_parameter(client: TestClient, state: GatewayState, path: str, status: int, words) -> None:
    state.apply(tracks(T0, {1: (0.0, 0.0), 2: (1.0, 0.0)}))
    state.apply(occupancy(T0, 2))
    response = client.get(path)
    assert response.status_code == status, response.text
    body = response.json()
    message = body["message"] if status == 422 else body["detail"]
    for word in words:
        assert word in message, (word, message)


def test_a_validation_error_keeps_fastapis_detail_list(client: TestClient) -> None:
    body = client.get("/api/tracks?limit=0&offset=-1").json()
    assert [e["loc"] for e in body["detail"]] == [["query", "limit"], ["query", "offset"]]
    assert body["message"].startswith("query parameter limit:")


def test_every_route_answers_a_fed_state(client: TestClient, state: GatewayState) -> None:
    for k in range(3):
        state.apply(tracks(T0 + k * S, {1: (0.0, 0.0), 2: (1.0, 0.0)}, [(1, 2)], zones={1: ["gate"], 2: ["gate"]}))
        state.apply(occupancy(T0 + k * S, 2, gate=2))
    paths = [route.path for route in client.app.routes if getattr(route, "methods", None) == {"GET"} and route.path.startswith("/api")]
    for path in paths:
        url = path.replace("{track_id}", "1").replace("{camera_id}", "north")
        response = client.get(url)
        assert response.status_code == 200, (url, response.text)

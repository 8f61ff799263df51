from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from bevflow.site import parse_site

from bevflow_services.gateway import GatewayState, create_app
from tests.services.gateway.feed import S, SITE_YAML, T0, occupancy


def _feed(state: GatewayState) -> None:
    """Five minutes: the gate crowded twice around a short dip, the shop briefly, the site at the end."""
    for k in range(300):
        gate = 3 if 10 <= k <= 100 or 111 <= k <= 150 else (1 if 101 <= k <= 110 else 0)
        shop = 6 if 200 <= k <= 230 else 0
        total = 10 if k >= 200 else gate + shop
        state.apply(occupancy(T0 + k * S, total, gate=gate, shop=shop))


def _summary(body: dict) -> list[tuple]:
    return [(i["zone"], (i["start_ns"] - T0) // S, (i["end_ns"] - T0) // S, i["peak"], i["level"], i["ongoing"]) for i in body["items"]]


@pytest.mark.parametrize(
    ("query", "expected"),
    [
        # The gate's dip of 10 s is merged (min_gap_s 30); the shop's 31 s is too short (min_duration_s 60);
        # the site is still above 9 (80 % of its capacity of 12) at the newest sample.
        ("", [("gate", 10, 151, 3, 2, False), (None, 200, 299, 10, 9, True)]),
        ("zone=gate&min_gap_s=5", [("gate", 10, 101, 3, 2, False)]),  # the dip now splits, and 40 s is too short
        ("zone=gate&min_gap_s=5&min_duration_s=0", [("gate", 10, 101, 3, 2, False), ("gate", 111, 151, 3, 2, False)]),
        ("zone=shop&min_duration_s=0", [("shop", 200, 231, 6, 5, False)]),
        ("zone=shop&level=6", []),
        ("zone=gate&since=1700000120&min_duration_s=0", [("gate", 120, 151, 3, 2, False)]),
        ("last_s=50&min_duration_s=0", [(None, 249, 299, 10, 9, True)]),
    ],
)
def test_crowded_intervals(client: TestClient, state: GatewayState, query: str, expected: list[tuple]) -> None:
    _feed(state)
    response = client.get(f"/api/intervals?{query}")
    assert response.status_code == 200, response.text
    assert _summary(response.json()) == expected


def test_intervals_carry_iso_times_and_duration(client: TestClient, state: GatewayState) -> None:
    _feed(state)
    first = client.get("/api/intervals?zone=gate").json()["items"][0]
    assert (first["start"], first["end"], first["duration_s"]) == ("2023-11-14T22:13:30.000Z", "2023-11-14T22:15:51.000Z", 141.0)


def test_no_history_no_intervals(client: TestClient) -> None:
    assert client.get("/api/intervals").json() == {"items": []}


def test_a_zone_without_a_level_needs_one_in_the_query() -> None:
    text = SITE_YAML.replace("thresholds:", "  - {id: hall, polygon: [[0, 0], [1, 0], [1, 1]]}\nthresholds:")
    site = parse_site(text)
    state = GatewayState(site)
    with TestClient(create_app(site, state)) as client:
        response = client.get("/api/intervals?zone=hall")
        assert response.status_code == 400
        assert "level" in response.json()["detail"]
        assert client.get("/api/intervals?zone=hall&level=1").status_code == 200

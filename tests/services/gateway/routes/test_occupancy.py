from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from bevflow_services.gateway.state import GatewayState
from tests.services.gateway.feed import S, T0, occupancy


def test_occupancy_before_any_tick_lists_every_zone_at_zero(client: TestClient) -> None:
    body = client.get("/api/occupancy").json()
    assert body["total"] == 0 and body["time_ns"] is None
    assert [(z["id"], z["count"], z["capacity"]) for z in body["zones"]] == [("gate", 0, 3), ("shop", 0, 10)]


def test_occupancy_now_is_the_latest_tick(client: TestClient, state: GatewayState) -> None:
    state.apply(occupancy(T0, 2, gate=1, shop=1))
    state.apply(occupancy(T0 + S, 11, gate=4, shop=5))
    body = client.get("/api/occupancy").json()
    assert (body["total"], body["capacity"], body["level"]) == (11, 12, "crowded")  # 80 % of 12 is 9
    assert body["time"] == "2023-11-14T22:13:21.000Z"
    zones = {z["id"]: (z["count"], z["capacity"], z["crowded_level"], z["level"]) for z in body["zones"]}
    assert zones == {"gate": (4, 3, 2, "over_capacity"), "shop": (5, 10, 5, "crowded")}


def _feed_minute(state: GatewayState) -> None:
    for k in range(60):
        state.apply(occupancy(T0 + k * S, total=k, gate=k % 4, shop=k // 10))


def test_history_is_columnar_one_sample_per_second(client: TestClient, state: GatewayState) -> None:
    _feed_minute(state)
    body = client.get("/api/occupancy/history").json()
    assert body["step_s"] == 1
    assert body["time_ns"] == [T0 + k * S for k in range(60)]
    assert body["total"] == list(range(60))
    assert body["zones"]["gate"] == [k % 4 for k in range(60)]
    assert body["zones"]["shop"] == [k // 10 for k in range(60)]


@pytest.mark.parametrize(
    ("query", "times", "totals", "zones"),
    [
        ("zone=gate&since=1700000050&until=1700000052", [50, 51, 52], [50, 51, 52], {"gate": [2, 3, 0]}),
        ("step_s=20", [0, 20, 40], [19, 39, 59], {"gate": [3, 3, 3], "shop": [1, 3, 5]}),  # maximum of each step
        ("last_s=2", [57, 58, 59], [57, 58, 59], None),
        ("limit=2", [58, 59], [58, 59], None),
        ("since=2023-11-14T22:13:30Z&until=2023-11-14T22:13:31", [10, 11], [10, 11], None),  # no offset: UTC
    ],
)
def test_history_filters(client: TestClient, state: GatewayState, query, times, totals, zones) -> None:
    _feed_minute(state)
    body = client.get(f"/api/occupancy/history?{query}").json()
    assert [(t - T0) // S for t in body["time_ns"]] == times
    assert body["total"] == totals
    if zones is not None:
        assert body["zones"] == zones


def test_history_of_an_empty_state_is_empty(client: TestClient) -> None:
    assert client.get("/api/occupancy/history?zone=shop").json() == {"step_s": 1, "time_ns": [], "total": [], "zones": {"shop": []}}

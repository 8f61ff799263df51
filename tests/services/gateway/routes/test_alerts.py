from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from bevflow.schemas import CameraHealthEvent

from bevflow_services.gateway.state import GatewayState
from tests.services.gateway.feed import S, T0, incident, over_capacity, violation


def _feed(state: GatewayState) -> None:
    state.apply(violation("v1", T0, pair=(1, 2), zone="gate"))
    state.apply(violation("v1", T0, pair=(1, 2), zone="gate", end_ns=T0 + 4 * S))
    state.apply(violation("v2", T0 + 10 * S, pair=(3, 4), zone="shop"))
    state.apply(over_capacity("c1", T0 + 20 * S, zone="gate"))
    state.apply(CameraHealthEvent(id="d1", type="camera_down", camera="north", start_ns=T0 + 30 * S))
    state.apply(violation("v3", T0 + 40 * S, pair=(1, 5), zone=None))
    state.apply(incident("i1", T0 + 2 * S, people=(1, 2, 6), zone="gate"))
    state.apply(incident("i1", T0 + 2 * S, people=(1, 2, 6), zone="gate", end_ns=T0 + 25 * S))
    state.apply(incident("i2", T0 + 41 * S, people=(1, 5), zone=None))


def test_violations_are_alert_messages_newest_first(client: TestClient, state: GatewayState) -> None:
    _feed(state)
    body = client.get("/api/violations").json()
    assert [a["id"] for a in body["items"]] == ["v3", "v2", "v1"]
    assert body["total"] == 3
    v1 = body["items"][2]
    assert (v1["type"], v1["zone"], v1["tracks"], v1["active"]) == ("distance_violation", "gate", [1, 2], False)
    assert (v1["start"], v1["end"]) == ("2023-11-14T22:13:20.000Z", "2023-11-14T22:13:24.000Z")
    assert v1["event"]["min_distance_m"] == 1.2


@pytest.mark.parametrize(
    ("query", "ids"),
    [
        ("zone=gate", ["v1"]),
        ("track=1", ["v3", "v1"]),
        ("active=true", ["v3", "v2"]),
        ("active=false", ["v1"]),
        ("since=1700000005", ["v3", "v2"]),
        ("until=1700000015", ["v2", "v1"]),
        ("limit=1&offset=1", ["v2"]),
    ],
)
def test_violation_filters(client: TestClient, state: GatewayState, query: str, ids: list[str]) -> None:
    _feed(state)
    assert [a["id"] for a in client.get(f"/api/violations?{query}").json()["items"]] == ids


@pytest.mark.parametrize(
    ("query", "ids"),
    [
        ("", ["i2", "d1", "c1", "i1"]),  # the pair events behind the incidents only when asked for
        ("types=distance_violation", ["v3", "v2", "v1"]),
        ("types=over_capacity,camera_down", ["d1", "c1"]),
        ("types=camera_down&active=true", ["d1"]),
        ("zone=gate", ["c1", "i1"]),
    ],
)
def test_alerts_of_every_type(client: TestClient, state: GatewayState, query: str, ids: list[str]) -> None:
    _feed(state)
    assert [a["id"] for a in client.get(f"/api/alerts?{query}").json()["items"]] == ids


@pytest.mark.parametrize(
    ("query", "ids"),
    [("", ["i2", "i1"]), ("active=true", ["i2"]), ("track=6", ["i1"]), ("zone=gate", ["i1"])],
)
def test_incidents(client: TestClient, state: GatewayState, query: str, ids: list[str]) -> None:
    _feed(state)
    body = client.get(f"/api/incidents?{query}").json()
    assert [a["id"] for a in body["items"]] == ids
    i1 = next((a for a in body["items"] if a["id"] == "i1"), None)
    if i1 is not None:
        assert (i1["type"], i1["tracks"], i1["event"]["people"], i1["active"]) == ("distance_incident", [1, 2, 6], 3, False)

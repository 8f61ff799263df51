from __future__ import annotations

from fastapi.testclient import TestClient

from bevflow.schemas import CameraHealthEvent

from bevflow_services.gateway.state import GatewayState
from tests.services.gateway.feed import T0, FakeClock, tracks


def test_health_lists_every_live_service(client: TestClient, state: GatewayState) -> None:
    for name, instance in [("tracker", "a-1"), ("ingest", "a-2"), ("ingest", "b-7"), ("gateway", "a-3")]:
        state.service_up(name, instance)
    state.service_down("ingest", "a-2")
    services = client.get("/api/health").json()["services"]
    assert [(s["name"], s["instance"]) for s in services] == [("gateway", "a-3"), ("ingest", "b-7"), ("tracker", "a-1")]
    assert services[0]["since"] == "2023-11-14T22:13:20.000Z"


def test_health_status_follows_the_data(client: TestClient, state: GatewayState, clock: FakeClock) -> None:
    assert client.get("/api/health").json()["status"] == "no_data"
    state.apply(tracks(T0, {1: (0.0, 0.0)}))
    body = client.get("/api/health").json()
    assert (body["status"], body["tracks_age_s"], body["cameras"]) == ("ok", 0.0, {"up": 0, "down": 0, "unknown": 2})
    state.apply(CameraHealthEvent(id="d", type="camera_down", camera="north", start_ns=T0))
    assert client.get("/api/health").json()["status"] == "degraded"
    clock.advance(6.0)
    assert client.get("/api/health").json()["status"] == "stale"


def test_health_counts_ignored_messages(client: TestClient, state: GatewayState) -> None:
    state.apply(tracks(T0, {}).model_copy(update={"site": "other"}))
    body = client.get("/api/health").json()
    assert (body["ignored_messages"], body["site"], body["bus"]) == (1, "hall", None)


def test_health_says_why_the_data_is_degraded_and_since_when(client: TestClient, state: GatewayState,
                                                              clock: FakeClock) -> None:
    state.apply(tracks(T0, {1: (0.0, 0.0)}))
    assert client.get("/api/health").json()["reasons"] == []
    clock.advance(4.0)
    state.apply(tracks(T0 + 500_000_000, {1: (0.0, 0.0)}))  # captured half a second later, arrived 4 s later
    body = client.get("/api/health").json()
    assert body["status"] == "degraded"
    assert body["reasons"] == ["tracks arrive 3.5 s after capture: the tracker or detector is behind"]
    assert [(p["start"], p["end"]) for p in body["degraded_periods"]] == [("2023-11-14T22:13:24.000Z", None)]

from __future__ import annotations

from fastapi.testclient import TestClient

from bevflow.schemas import CameraHealthEvent

from bevflow_services.gateway.state import GatewayState
from tests.services.gateway.feed import S, T0, FakeClock, tracks


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


def test_health_answers_503_while_the_status_is_not_ok(client: TestClient, state: GatewayState,
                                                       clock: FakeClock) -> None:
    response = client.get("/api/health")
    assert (response.status_code, response.json()["status"]) == (503, "no_data")
    state.apply(tracks(T0, {1: (0.0, 0.0)}))
    response = client.get("/api/health")
    assert (response.status_code, response.json()["status"]) == (200, "ok")
    state.apply(CameraHealthEvent(id="d", type="camera_down", camera="north", start_ns=T0))
    response = client.get("/api/health")
    assert (response.status_code, response.json()["status"]) == (503, "degraded")
    assert response.json()["cameras"]["down"] == 1  # the whole body, as with 200
    clock.advance(6.0)
    assert client.get("/api/health").status_code == 503


def test_degraded_periods_are_recorded_without_anyone_asking(client: TestClient, state: GatewayState,
                                                             clock: FakeClock) -> None:
    for k in range(5):  # a tick a second; the camera is down from just after the first to before the fourth
        if k == 1:
            state.apply(CameraHealthEvent(id="d", type="camera_down", camera="north", start_ns=T0))
        if k == 3:
            state.apply(CameraHealthEvent(id="d", type="camera_down", camera="north", start_ns=T0, end_ns=T0 + 2 * S))
        state.apply(tracks(T0 + k * S, {1: (0.0, 0.0)}))
        clock.advance(1.0)
    periods = client.get("/api/health").json()["degraded_periods"]
    assert [(p["start_ns"], p["end_ns"], p["reasons"]) for p in periods] == [(T0 + S, T0 + 3 * S, ["camera north down"])]

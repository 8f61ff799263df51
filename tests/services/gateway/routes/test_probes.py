"""``/healthz`` always 200; ``/readyz`` 200 only while fresh tracks arrive, whatever the cameras."""

from __future__ import annotations

from fastapi.testclient import TestClient

from bevflow.schemas import CameraHealthEvent

from bevflow_services.gateway.state import GatewayState
from tests.services.gateway.feed import T0, FakeClock, tracks


def test_healthz_answers_while_the_process_serves(client: TestClient) -> None:
    response = client.get("/healthz")
    assert (response.status_code, response.json()) == (200, {"ok": True, "reason": ""})


def test_readyz_follows_the_ticks_not_the_cameras(client: TestClient, state: GatewayState, clock: FakeClock) -> None:
    response = client.get("/readyz")
    assert response.status_code == 503 and "no tracks" in response.json()["reason"]
    state.apply(tracks(T0, {1: (0.0, 0.0)}))
    assert client.get("/readyz").status_code == 200
    state.apply(CameraHealthEvent(id="d", type="camera_down", camera="north", start_ns=T0))
    assert client.get("/readyz").status_code == 200  # degraded, still ready
    assert client.get("/api/health").status_code == 503
    clock.advance(6.0)
    response = client.get("/readyz")
    assert response.status_code == 503 and response.json()["reason"] == "the newest tracks arrived 6 s ago"

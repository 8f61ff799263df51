from __future__ import annotations

from fastapi.testclient import TestClient

from bevflow.schemas import CameraHealthEvent, Detections2D

from bevflow_services.gateway.state import GatewayState
from tests.services.gateway.feed import S, T0, FakeClock


def test_cameras_list_position_and_health(client: TestClient, state: GatewayState, clock: FakeClock) -> None:
    for seq in (0, 1, 4):
        state.apply(Detections2D(camera="north", seq=seq, capture_ns=T0 + seq * S))
    clock.advance(1.5)
    body = client.get("/api/cameras").json()
    assert (body["total"], body["limit"], body["offset"]) == (2, 100, 0)
    north, south = body["items"]
    assert [c["id"] for c in client.get("/api/cameras?offset=1&limit=1").json()["items"]] == ["south"]
    assert (north["id"], north["model"], north["position"], north["monitored_radius_m"]) == ("north", "fisheye", [0.0, 0.0, 4.0], 6.0)
    assert (north["state"], north["frames_received"], north["frames_dropped"], north["last_seq"], north["age_s"]) == ("up", 3, 2, 4, 1.5)
    assert north["last_message"] == "2023-11-14T22:13:20.000Z"
    assert (south["id"], south["position"], south["state"], south["reason"]) == ("south", [10.0, 0.0, 4.0], "unknown", "no message yet")


def test_a_camera_reported_down_shows_the_reason(client: TestClient, state: GatewayState) -> None:
    state.apply(CameraHealthEvent(id="d", type="camera_down", camera="south", start_ns=T0, reason="RTSP timeout"))
    body = client.get("/api/cameras/south").json()
    assert (body["state"], body["reason"]) == ("down", "RTSP timeout")


def test_an_unknown_camera_is_404_listing_the_known_ones(client: TestClient) -> None:
    response = client.get("/api/cameras/east")
    assert response.status_code == 404
    assert response.json()["detail"] == "camera_id: unknown camera 'east'; known cameras: north, south"

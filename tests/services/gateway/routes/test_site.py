from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from bevflow.site import Site

from bevflow_services.gateway import GatewayState, create_app
from bevflow_services.gateway.routes.site import redact_source


def test_site_is_the_site_description(client: TestClient, site: Site) -> None:
    body = client.get("/api/site").json()
    assert Site.model_validate(body) == site
    assert [z["id"] for z in body["zones"]] == ["gate", "shop"]


def test_config_without_the_3d_view(client: TestClient) -> None:
    body = client.get("/api/config").json()
    assert body["view3d_url"] is None
    assert body["websockets"] == {"alerts": "/ws/alerts", "tracks": "/ws/tracks"}
    assert (body["site"], body["social_distance_m"], body["history_s"]) == ("hall", 2.0, 3600.0)
    assert "distance_violation" in body["alert_types"]


@pytest.mark.parametrize(
    ("source", "shown"),
    [
        (None, None),
        ("rtsp://admin:s3cret@10.0.0.5:554/stream1", "rtsp://admin:***@10.0.0.5:554/stream1"),
        ("rtsp://10.0.0.5:554/stream1", "rtsp://10.0.0.5:554/stream1"),
        ("http://viewer@cam.local/mjpg", "http://viewer@cam.local/mjpg"),
        ("/data/hall/north.mp4", "/data/hall/north.mp4"),
    ],
)
def test_camera_passwords_are_hidden(source, shown) -> None:
    assert redact_source(source) == shown


def test_the_site_route_hides_camera_passwords(site: Site) -> None:
    cameras = [site.cameras[0].model_copy(update={"source": "rtsp://admin:s3cret@10.0.0.5/live"}), site.cameras[1]]
    with_password = site.model_copy(update={"cameras": cameras})
    with TestClient(create_app(with_password, GatewayState(with_password))) as client:
        body = client.get("/api/site").json()
    assert body["cameras"][0]["source"] == "rtsp://admin:***@10.0.0.5/live"

"""``/api/calibration``: frames, solving and saving a pose into the site file, consistency, drift."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import yaml
from fastapi.testclient import TestClient

from bevflow.detections import Cylinders
from bevflow.schemas import CalibrationDrift, CameraCylinders, FrameHeader
from bevflow.site import load_site

from bevflow_services.gateway import GatewayState, create_app
from bevflow_services.gateway.calibration_inputs import CalibrationInputs
from bevflow_services.gateway.site_file import site_file_of
from tests.services.gateway import calibration_site
from tests.services.gateway.calibration_site import FLOOR_POINTS, SITE_YAML, TRUE_POSITION, true_camera, true_pixels

T0 = 1_700_000_000_000_000_000


@pytest.fixture
def site_file(tmp_path: Path) -> Path:
    path = tmp_path / "hall.yaml"
    path.write_text(SITE_YAML, encoding="utf-8")
    return path


@pytest.fixture
def state() -> GatewayState:
    return GatewayState(calibration_site.site())


@pytest.fixture
def client(site_file: Path, state: GatewayState) -> Iterator[TestClient]:
    app = create_app(state.site, state)
    app.state.site_file = site_file_of(site_file)
    with TestClient(app) as test_client:
        yield test_client


@pytest.fixture
def builtin_client(state: GatewayState) -> Iterator[TestClient]:
    with TestClient(create_app(state.site, state)) as test_client:  # no site_file: a built-in site
        yield test_client


def points_body(pixels: np.ndarray | None = None, world: list[tuple[float, ...]] | None = None, **extra: Any) -> dict[str, Any]:
    pixels = true_pixels() if pixels is None else pixels
    world = FLOOR_POINTS if world is None else world
    points = [{"name": f"m{k}", "pixel": [float(u), float(v)], "world": list(w)} for k, ((u, v), w) in enumerate(zip(pixels, world, strict=True))]
    return {"points": points, **extra}


def test_solve_recovers_the_true_pose_and_reports_each_point(client: TestClient, site_file: Path) -> None:
    response = client.post("/api/calibration/cameras/gate/solve", json=points_body())
    assert response.status_code == 200, response.text
    body = response.json()
    assert np.allclose(body["position"], TRUE_POSITION, atol=0.01)
    assert body["tilt_deg"] == pytest.approx(1.0, abs=0.05)
    assert body["accepted"] and body["refusal"] is None and body["warnings"] == []
    assert [p["name"] for p in body["points"]] == [f"m{k}" for k in range(8)]
    assert max(p["reprojection_px"] for p in body["points"]) < 0.01
    assert max(p["ground_error_m"] for p in body["points"]) < 0.001
    assert np.allclose([p["projected"] for p in body["points"]], true_pixels(), atol=0.01)
    assert site_file.read_text(encoding="utf-8") == SITE_YAML  # solving writes nothing


def test_save_writes_the_pose_into_the_site_file_keeping_the_rest(client: TestClient, site_file: Path) -> None:
    pixels = true_pixels() + np.random.default_rng(0).normal(0.0, 0.3, (8, 2))  # a click is never exact
    response = client.put("/api/calibration/cameras/gate/extrinsics", json=points_body(pixels))
    assert response.status_code == 200, response.text
    body = response.json()
    assert 0.1 < body["rms_px"] < 1.0 and body["accepted"]
    assert (body["site_file"], body["backup"]) == (str(site_file.resolve()), str(site_file.resolve()) + ".bak")
    assert body["comments_kept"] and "restart the projector and tracker" in body["next"]
    text = site_file.read_text(encoding="utf-8")
    assert "# over the main door" in text and "# the hall by the gate" in text
    saved = load_site(site_file)
    gate = next(c for c in saved.cameras if c.id == "gate")
    assert gate.pose is None and gate.extrinsics is not None
    assert np.allclose(saved.camera("gate").center, TRUE_POSITION, atol=0.05)
    assert np.allclose(gate.extrinsics.rvec, body["rvec"]) and np.allclose(gate.extrinsics.tvec, body["tvec"])
    assert yaml.safe_load(text)["cameras"][1] == yaml.safe_load(SITE_YAML)["cameras"][1]
    assert (site_file.parent / "hall.yaml.bak").read_text(encoding="utf-8") == SITE_YAML
    # The page reads the site again: the camera now hangs where the save put it.
    (gate_now, _) = client.get("/api/calibration").json()["cameras"]
    assert np.allclose(gate_now["position"], TRUE_POSITION, atol=0.05)


@pytest.mark.parametrize(
    ("camera", "body", "status", "message"),
    [
        ("gate", points_body(true_pixels()[:3], FLOOR_POINTS[:3]), 400, "3 points given; at least 4"),
        ("gate", points_body(np.vstack([true_pixels()[:7], [[900.0, 10.0]]])), 400, "m7: pixel outside the 800x800 image"),
        ("lobby", points_body(), 404, "unknown camera 'lobby'; known cameras: gate, shop"),
        ("gate", {"points": [{"pixel": [1, 2], "world": [1]}]}, 422, "world"),
        ("gate", points_body(world=[(x, 2.0) for x, _ in FLOOR_POINTS]), 400, "on one line"),
    ],
    ids=["too-few", "off-image", "unknown-camera", "malformed", "collinear"],
)
def test_bad_points_are_refused_clearly(client: TestClient, site_file: Path, camera: str, body: dict, status: int, message: str) -> None:
    for method, path in (("post", "solve"), ("put", "extrinsics")):
        response = getattr(client, method)(f"/api/calibration/cameras/{camera}/{path}", json=body)
        assert response.status_code == status, response.text
        assert message in str(response.json())
    assert site_file.read_text(encoding="utf-8") == SITE_YAML


def test_a_pose_beyond_the_limits_is_previewed_but_not_saved(client: TestClient, site_file: Path) -> None:
    world = list(FLOOR_POINTS)
    world[3] = (3.0, 7.0)  # a floor point typed 1 m off
    body = points_body(world=world)
    preview = client.post("/api/calibration/cameras/gate/solve", json=body).json()
    assert not preview["accepted"] and "pose refused" in preview["refusal"]
    worst = max(preview["points"], key=lambda p: p["ground_error_m"])
    assert worst["ground_error_m"] > 0.15
    response = client.put("/api/calibration/cameras/gate/extrinsics", json=body)
    assert response.status_code == 400 and response.json()["detail"].startswith("not saved: pose refused")
    assert site_file.read_text(encoding="utf-8") == SITE_YAML
    relaxed = client.put("/api/calibration/cameras/gate/extrinsics", json={**body, "max_rms_px": 500, "max_ground_error_m": 5})
    assert relaxed.status_code == 200 and site_file.read_text(encoding="utf-8") != SITE_YAML


def test_a_builtin_site_cannot_be_saved(builtin_client: TestClient) -> None:
    overview = builtin_client.get("/api/calibration").json()
    assert (overview["editable"], overview["site_file"]) == (False, None)
    assert "--site" in overview["reason"]
    response = builtin_client.put("/api/calibration/cameras/gate/extrinsics", json=points_body())
    assert response.status_code == 409 and "built-in site" in response.json()["detail"]
    assert builtin_client.post("/api/calibration/cameras/gate/solve", json=points_body()).status_code == 200


def test_overview(client: TestClient, site_file: Path) -> None:
    body = client.get("/api/calibration").json()
    assert (body["site"], body["editable"], body["site_file"], body["reason"]) == ("calib-hall", True, str(site_file.resolve()), "")
    assert body["floor"] == [0, 0, 16, 8] and body["zones"] == [[[3, 2], [7, 2], [7, 6], [3, 6]]]
    gate, shop = body["cameras"]
    assert (gate["id"], gate["position"], gate["tilt_deg"], gate["monitored_radius_m"], gate["frame"]) == ("gate", [5, 4, 4], 0, 5, "rendered")
    assert gate["coverage_radius_m"] == 5  # the site's own radius
    assert (shop["monitored_radius_m"], shop["coverage_radius_m"]) == (None, 5.1)  # as `bevflow plan` puts it at 4 m
    assert shop["drift"] == {"camera": "shop", "state": "ok", "shift_m": None, "reference_camera": None, "since": None, "alert_id": None}
    assert (body["min_points"], body["max_rms_px"], body["max_ground_error_m"]) == (6, 3.0, 0.15)


def decode(response: Any) -> np.ndarray:
    assert response.status_code == 200 and response.headers["content-type"] == "image/jpeg"
    image = cv2.imdecode(np.frombuffer(response.content, np.uint8), cv2.IMREAD_COLOR)
    assert image is not None
    return image


def test_frame_is_the_rendered_floor_grid_until_a_frame_arrives(client: TestClient) -> None:
    response = client.get("/api/calibration/cameras/gate/frame")
    image = decode(response)
    assert image.shape == (800, 800, 3) and response.headers["x-frame-source"] == "rendered"
    # The grid crossing (5, 4) lies straight below the camera: a bright dot at the image centre
    # (the marker below the camera is drawn there too), while a cell's middle is background.
    assert image[398:403, 398:403].max() > 150
    middle = site_cam_pixel(5.5, 4.5)
    assert image[middle[1], middle[0]].max() < 80
    assert client.get("/api/calibration/cameras/lobby/frame").status_code == 404


def site_cam_pixel(x: float, y: float) -> tuple[int, int]:
    u, v = calibration_site.site().camera("gate").project(np.array([[x, y, 0.0]]))[0]
    return int(round(u)), int(round(v))


@pytest.mark.parametrize("encoding", ["bgr8", "jpeg", "gray8"])
def test_frame_is_the_latest_from_the_bus_scaled_to_the_camera(client: TestClient, encoding: str) -> None:
    inputs = CalibrationInputs()
    client.app.state.calibration_inputs = inputs  # type: ignore[attr-defined]  # as the gateway's main does
    picture = np.zeros((400, 400, 3), np.uint8)
    picture[:, :200] = (0, 0, 255)  # left half red
    if encoding == "jpeg":
        payload = cv2.imencode(".jpg", picture)[1].ravel()
    elif encoding == "gray8":
        payload = np.ascontiguousarray(picture[:, :, 2])
    else:
        payload = picture
    inputs.put_frame(FrameHeader(camera="gate", seq=1, capture_ns=T0, width=400, height=400, encoding=encoding), payload)
    response = client.get("/api/calibration/cameras/gate/frame")
    image = decode(response)
    assert image.shape == (800, 800, 3) and response.headers["x-frame-source"] == "live"
    left, right = image[400, 100].astype(int), image[400, 700].astype(int)
    assert left[2] > 200 and right.max() < 30
    assert client.get("/api/calibration").json()["cameras"][0]["frame"] == "live"
    over = decode(client.get("/api/calibration/cameras/gate/frame?grid=true"))
    px = site_cam_pixel(7.0, 4.0)  # on a grid line, in the black half: the line is drawn over it
    assert over[px[1], px[0]].max() > 60 and image[px[1], px[0]].max() < 30


def test_frames_can_be_fetched_on_demand(client: TestClient) -> None:
    asked = []

    def fetch(camera: str) -> tuple[FrameHeader, np.ndarray] | None:
        asked.append(camera)
        if camera != "gate":
            return None  # no frame came in time
        return FrameHeader(camera="gate", seq=len(asked), capture_ns=T0, width=800, height=800), np.full((800, 800, 3), 200, np.uint8)

    client.app.state.calibration_inputs = CalibrationInputs(fetch_frame=fetch)  # type: ignore[attr-defined]
    assert [c["frame"] for c in client.get("/api/calibration").json()["cameras"]] == ["rendered", "rendered"]
    assert asked == []  # the overview never waits for frames
    response = client.get("/api/calibration/cameras/gate/frame")
    assert response.headers["x-frame-source"] == "live" and decode(response)[400, 400].min() > 180
    assert client.get("/api/calibration/cameras/shop/frame").headers["x-frame-source"] == "rendered"
    assert asked == ["gate", "shop"]
    assert [c["frame"] for c in client.get("/api/calibration").json()["cameras"]] == ["live", "rendered"]


def test_consistency_from_the_projectors_cylinders(client: TestClient) -> None:
    inputs = CalibrationInputs()
    client.app.state.calibration_inputs = inputs  # type: ignore[attr-defined]
    rng = np.random.default_rng(1)
    for k in range(30):  # one person in the overlap per tick; shop puts them 0.2 m further east
        xy = np.array([[rng.uniform(7.5, 9.5), rng.uniform(2.0, 6.0)]])
        t = T0 + k * 100_000_000
        inputs.put_cylinders(CameraCylinders.from_cylinders("gate", k, t, Cylinders(xy=xy)))
        inputs.put_cylinders(CameraCylinders.from_cylinders("shop", k, t + 5_000_000, Cylinders(xy=xy + [0.2, 0.0])))
    body = client.get("/api/calibration/consistency").json()
    assert (body["ticks"], body["tolerance_m"], body["min_samples"]) == (30, 0.45, 20)
    (pair,) = body["pairs"]
    assert (pair["camera_a"], pair["camera_b"], pair["samples"], pair["judged"], pair["agrees"]) == ("gate", "shop", 30, True, True)
    assert pair["median_offset_m"] == pytest.approx(0.2, abs=1e-6)
    strict = client.get("/api/calibration/consistency?tolerance_m=0.1&min_samples=40").json()["pairs"][0]
    assert (strict["judged"], strict["agrees"]) == (False, None)
    assert client.get("/api/calibration/consistency?gate_m=0").status_code == 422


def test_drift_per_camera_follows_the_trackers_alerts(client: TestClient, state: GatewayState) -> None:
    event = CalibrationDrift(id="calibration-drift-shop-1", start_ns=T0, camera="shop", shift_m=0.21, reference_camera="gate")
    state.apply(event)
    gate, shop = client.get("/api/calibration/drift").json()
    assert gate["state"] == "ok"
    assert (shop["state"], shop["shift_m"], shop["reference_camera"], shop["alert_id"]) == ("moved", 0.21, "gate", event.id)
    assert shop["since"] == "2023-11-14T22:13:20.000Z"
    assert client.get("/api/calibration").json()["cameras"][1]["drift"]["state"] == "moved"
    state.apply(event.model_copy(update={"end_ns": T0 + 10}))
    assert [d["state"] for d in client.get("/api/calibration/drift").json()] == ["ok", "ok"]
    (alert,) = client.get("/api/alerts").json()["items"]  # in the alert history like any other alert
    assert (alert["id"], alert["type"], alert["end_ns"]) == (event.id, "calibration_drift", T0 + 10)


def test_pixels_of_the_true_camera_differ_from_the_files_pose() -> None:
    """The fixture is a real test of saving: the file's pose does not already explain the clicks."""
    site_pixels = calibration_site.site().camera("gate").project(np.array([(x, y, 0.0) for x, y in FLOOR_POINTS]))
    assert np.linalg.norm(site_pixels - true_pixels(), axis=1).min() > 5.0
    assert np.allclose(true_camera().center, TRUE_POSITION)

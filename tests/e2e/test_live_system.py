"""The live system as separate processes on loopback: simulated cameras in, REST and websocket
alerts out, checked against the simulator's own ground truth."""

from __future__ import annotations

import asyncio
import json
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
import websockets

from bevflow.schemas import CameraCylinders, Detections2D, SimulatedTruth

from bevflow_services import bus
from bevflow_services.launcher import ServiceGroup, free_port, start_pipeline
from tests.e2e.http import get_json

pytestmark = pytest.mark.e2e
PEOPLE = 24


class TruthLog:
    """The simulator's ground truth, as published by the ingest, keyed by capture time."""

    def __init__(self, group: ServiceGroup) -> None:
        cfg = bus.BusConfig(mode="peer", listen=("tcp/127.0.0.1:0",), connect=(f"tcp/127.0.0.1:{group.hub_port}",))
        self.session = bus.open_session(cfg)
        self.frames: dict[int, int] = {}
        self.lock = threading.Lock()
        self.subscription = bus.subscribe(self.session, bus.Keys("demo-hall").truth,
                                          bus.JsonCodec(SimulatedTruth), self._on_truth)

    def _on_truth(self, truth: SimulatedTruth) -> None:
        with self.lock:
            self.frames[truth.capture_ns] = len(truth.tracks)

    def count_at(self, time_ns: int) -> int | None:
        with self.lock:
            if not self.frames:
                return None
            nearest = min(self.frames, key=lambda t: abs(t - time_ns))
            return self.frames[nearest] if abs(nearest - time_ns) < 300_000_000 else None

    def close(self) -> None:
        self.subscription.close()
        self.session.close()


async def first_alert(url: str, timeout_s: float) -> dict:
    async with websockets.connect(url, open_timeout=5) as ws:
        return json.loads(await asyncio.wait_for(ws.recv(), timeout_s))


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory):
    group = ServiceGroup(site="demo-hall", log_dir=Path(tmp_path_factory.mktemp("logs")))
    port = free_port()
    try:
        base = start_pipeline(group, port, boxes="simulated", history_db=None,
                              ingest_args=("--people", str(PEOPLE)), gateway_args=("--no-view3d",))
        truth = TruthLog(group)
        yield base, truth, group
        truth.close()
    finally:
        group.stop()


def test_every_service_announces_itself(live) -> None:
    base, _, _ = live
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        names = {s["name"] for s in get_json(f"{base}/api/health")["services"]}
        if {"ingest", "projector", "tracker", "gateway"} <= names:
            break
        time.sleep(0.5)
    assert {"ingest", "projector", "tracker", "gateway"} <= names


def test_rest_occupancy_follows_the_simulated_ground_truth(live) -> None:
    base, truth, group = live
    time.sleep(6)  # tracks need 3 detections to be confirmed; let the crowd settle in
    errors = []
    for _ in range(10):
        occupancy = get_json(f"{base}/api/occupancy")
        expected = truth.count_at(occupancy["time_ns"])
        if expected is not None:
            errors.append(occupancy["total"] - expected)
        time.sleep(0.5)
    assert len(errors) >= 5, f"too few occupancy samples matched a ground-truth frame; logs in {group.log_dir}"
    # Tracks are confirmed after 3 detections and kept 5 misses, so a few people may be counted
    # a tick early or late at the border; the count must never wander off.
    assert max(abs(e) for e in errors) <= max(3, PEOPLE // 5), errors
    assert abs(sum(errors) / len(errors)) <= 2.0, errors
    zones = {z["id"] for z in get_json(f"{base}/api/occupancy")["zones"]}
    assert zones == {"gate", "corridor", "shop"}


def test_a_distance_alert_arrives_on_the_websocket(live) -> None:
    base, _, _ = live
    url = base.replace("http://", "ws://") + "/ws/alerts?types=distance_violation&replay=active"
    alert = asyncio.run(first_alert(url, timeout_s=30))
    assert alert["type"] == "distance_violation"
    assert len(alert["tracks"]) == 2 and alert["start"]
    assert "zone" in alert


def test_garbage_on_the_bus_and_bad_requests_do_not_stop_the_stream(live) -> None:
    base, truth, group = live
    keys = bus.Keys("demo-hall")
    now = time.time_ns()
    session = truth.session
    garbage = [
        (keys.detections("hall-1"), b"\x00\xffnot json"),
        (keys.detections("hall-2"), b'{"schema_version": 1, "camera": "hall-2"}'),
        (keys.detections("no-such-camera"), Detections2D(camera="no-such-camera", seq=1, capture_ns=now,
                                                         boxes=[(1, 2, 30, 60)]).model_dump_json().encode()),
        (keys.cylinders("hall-3"), CameraCylinders(camera="hall-3", seq=1, capture_ns=now + 3600 * 10**9).model_dump_json().encode()),
        (keys.cylinders("hall-4"), CameraCylinders(camera="hall-4", seq=1, capture_ns=now - 3600 * 10**9).model_dump_json().encode()),
        (keys.cylinders("hall-5"), b'{"schema_version": 99}'),
        (keys.events, b"[1, 2, 3]"),
        (keys.tracks, b'{"site": "demo-hall"}'),
    ]
    before = get_json(f"{base}/api/occupancy")["time_ns"]
    for _ in range(5):
        for key, payload in garbage:
            session.put(key, payload)
        time.sleep(0.2)
    for path, status in [("/api/occupancy/history?since=10&until=5", 400), ("/api/tracks/abc", 422),
                         ("/api/occupancy/history?zone=nowhere", 404), ("/api/violations?limit=-1", 422)]:
        try:
            urllib.request.urlopen(f"{base}{path}", timeout=5)
            code = 200
        except urllib.error.HTTPError as exc:
            code = exc.code
        assert code == status, path
    time.sleep(2)
    assert not group.dead(), [c.name for c in group.dead()]
    after = get_json(f"{base}/api/occupancy")
    assert after["time_ns"] > before and after["total"] > 0
    health = get_json(f"{base}/api/health")
    assert {"ingest", "projector", "tracker", "gateway"} <= {s["name"] for s in health["services"]}
    assert sum(health["bus"]["rejected"].values()) > 0  # the gateway saw and refused its share

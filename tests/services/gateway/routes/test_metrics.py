"""``/metrics``: Prometheus text with the same counters as ``/api/health`` and ``/api/cameras``,
and the Grafana dashboard in docker/ asking only for series that exist."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from prometheus_client.parser import text_string_to_metric_families

from bevflow.schemas import CameraHealthEvent, FrameHeader, ServiceMetrics
from bevflow.site import Site

from bevflow_services.bus import BusStats
from bevflow_services.service_metrics import MetricsBook
from bevflow_services.gateway.state import GatewayState
from tests.services.gateway.access import secured_client
from tests.services.gateway.feed import S, T0, FakeClock, incident, occupancy, tracks


def scrape(client: TestClient, **kwargs) -> dict[tuple[str, tuple], float]:
    response = client.get("/metrics", **kwargs)
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/plain; version=")
    samples = {}
    for family in text_string_to_metric_families(response.text):
        assert family.name.startswith("bevflow_"), family.name
        for sample in family.samples:
            samples[(sample.name, tuple(sorted(sample.labels.items())))] = sample.value
    return samples


def frame(camera: str, seq: int, capture_ns: int) -> FrameHeader:
    return FrameHeader(camera=camera, seq=seq, capture_ns=capture_ns, width=4, height=4)


def test_status_follows_health(client: TestClient, state: GatewayState, clock: FakeClock) -> None:
    before = scrape(client)
    assert before[("bevflow_site_ok", ())] == 0.0
    assert before[("bevflow_site_status", (("status", "no_data"),))] == 1.0
    state.apply(tracks(T0, {1: (0.0, 0.0)}))
    after = scrape(client)
    assert after[("bevflow_site_ok", ())] == 1.0
    assert after[("bevflow_site_status", (("status", "ok"),))] == 1.0
    assert after[("bevflow_site_status", (("status", "no_data"),))] == 0.0


def test_cameras_frames_and_lag(client: TestClient, state: GatewayState, clock: FakeClock) -> None:
    clock.advance(0.25)
    for seq in (1, 2, 5):  # 3 and 4 lost
        state.apply(frame("north", seq, T0))
    state.apply(CameraHealthEvent(id="d", type="camera_down", camera="south", start_ns=T0))
    m = scrape(client)
    assert m[("bevflow_camera_frames_received_total", (("camera", "north"),))] == 3
    assert m[("bevflow_camera_frames_dropped_total", (("camera", "north"),))] == 2
    assert m[("bevflow_camera_lag_seconds", (("camera", "north"),))] == 0.25
    assert m[("bevflow_camera_state", (("camera", "north"), ("state", "up")))] == 1.0
    assert m[("bevflow_camera_state", (("camera", "south"), ("state", "down")))] == 1.0


def test_ticks_latency_occupancy_alerts(client: TestClient, state: GatewayState, clock: FakeClock) -> None:
    clock.advance(0.5)
    state.apply(tracks(T0, {1: (0.0, 0.0)}))
    clock.advance(0.2)
    state.apply(tracks(T0 + S // 10, {1: (0.0, 0.0)}))
    state.apply(occupancy(T0, total=7, gate=4))
    state.apply(incident("i1", T0))
    m = scrape(client)
    assert m[("bevflow_tick_latency_seconds_count", ())] == 2
    assert abs(m[("bevflow_tick_latency_seconds_sum", ())] - 1.1) < 1e-9
    assert abs(m[("bevflow_last_tick_latency_seconds", ())] - 0.6) < 1e-9
    assert abs(m[("bevflow_tick_interval_seconds", ())] - 0.1) < 1e-9
    assert m[("bevflow_occupancy_people", ())] == 7
    assert m[("bevflow_zone_occupancy_people", (("zone", "gate"),))] == 4
    assert m[("bevflow_alerts_active", (("type", "distance_incident"),))] == 1
    assert m[("bevflow_websocket_clients", (("stream", "alerts"),))] == 0


def test_bus_counters_when_fed_from_the_bus(client: TestClient) -> None:
    stats = BusStats()
    stats.count("received", 5)
    stats.count("dropped", 2)
    stats.reject("k", "invalid json", "x")
    client.app.state.bus_stats = stats  # type: ignore[attr-defined]
    m = scrape(client)
    assert m[("bevflow_bus_messages_total", (("outcome", "dropped"),))] == 2
    assert m[("bevflow_bus_rejected_total", (("reason", "invalid json"),))] == 1


def test_metrics_need_a_viewer_token(site: Site, state: GatewayState) -> None:
    with secured_client(site, state) as (client, secure):
        assert client.get("/metrics").status_code == 401
        assert scrape(client, headers={"Authorization": f"Bearer {secure.tokens['viewer']}"})


def test_the_grafana_dashboard_asks_only_for_series_that_exist(client: TestClient, state: GatewayState,
                                                               clock: FakeClock) -> None:
    _fed_gateway(client, state, clock)
    state.apply(tracks(T0, {1: (0.0, 0.0)}))
    state.apply(tracks(T0 + S // 10, {1: (0.0, 0.0)}))
    state.apply(occupancy(T0, total=1))
    client.app.state.bus_stats = BusStats()  # type: ignore[attr-defined]
    suffixes = {"counter": ("",), "summary": ("_sum", "_count"), "gauge": ("",),  # counters' TYPE has _total
                "histogram": ("_bucket", "_sum", "_count")}
    served = {name + suffix for name, kind in re.findall(r"^# TYPE (\S+) (\w+)$", client.get("/metrics").text, re.M)
              for suffix in suffixes[kind]}  # every family, with or without samples now
    dashboard = json.loads((Path(__file__).resolve().parents[4] / "docker" / "grafana-dashboard.json").read_text())
    asked = {name for panel in dashboard["panels"] for target in panel["targets"]
             for name in re.findall(r"\bbevflow_[a-z_]+", target["expr"])}
    assert asked and asked <= served, sorted(asked - served)


def _report(service: str, instance: str, book: MetricsBook, time_ns: int) -> ServiceMetrics:
    return book.message("hall", service, instance, time_ns)


# What issue 20 asks /metrics for, and the series that answer it (labels each must carry).
REQUIRED = [
    ("frames in, per camera", "bevflow_camera_frames_received_total", {"camera": "north"}),
    ("frames dropped, per camera", "bevflow_camera_frames_dropped_total", {"camera": "north"}),
    ("frames late, per camera", "bevflow_camera_frames_late_total", {"camera": "south", "instance": "t1"}),
    ("detector latency histogram", "bevflow_detector_latency_seconds_bucket", {"le": "0.1", "instance": "d1"}),
    ("tick duration", "bevflow_tick_duration_seconds_count", {"instance": "t1"}),
    ("frame-to-alert latency", "bevflow_frame_to_alert_seconds_count", {}),
    ("open incidents", "bevflow_alerts_active", {"type": "distance_incident"}),
    ("alerts raised by type", "bevflow_alerts_raised_total", {"type": "distance_incident"}),
    ("websocket clients", "bevflow_websocket_clients", {"stream": "alerts"}),
    ("history write latency", "bevflow_history_write_seconds_count", {"instance": "r1"}),
    ("history backlog", "bevflow_history_backlog_rows", {"instance": "r1"}),
    ("alerts refused by a forwarder", "bevflow_alert_feed_alerts_total", {"instance": "m1", "outcome": "refused"}),
    ("a forwarder's outbox backlog", "bevflow_outbox_backlog_alerts", {"instance": "m1"}),
]


def _fed_gateway(client: TestClient, state: GatewayState, clock: FakeClock) -> None:
    """The state fed as in a running site, and one report from each service that measures itself."""
    state.apply(frame("north", 1, T0))
    state.apply(incident("i1", T0).model_copy(update={"raised_ns": T0}))
    detector, tracker, recorder, mqtt = MetricsBook(), MetricsBook(), MetricsBook(), MetricsBook()
    mqtt.count("alert_feed_alerts", 3, outcome="refused")
    mqtt.set("outbox_backlog_alerts", 7)
    detector.observe("detector_latency_seconds", 0.08)
    tracker.count("camera_frames_late", camera="south")
    tracker.observe("tick_duration_seconds", 0.004)
    recorder.observe("history_write_seconds", 0.002)
    recorder.set("history_backlog_rows", 12)
    store = client.app.state.service_metrics  # type: ignore[attr-defined]
    for service, instance, book in (("detector", "d1", detector), ("tracker", "t1", tracker), ("recorder", "r1", recorder),
                                    ("mqtt", "m1", mqtt)):
        store.put(_report(service, instance, book, clock()))


@pytest.mark.parametrize(("what", "name", "labels"), REQUIRED, ids=[r[0] for r in REQUIRED])
def test_every_series_the_issue_asks_for_is_served(client: TestClient, state: GatewayState, clock: FakeClock,
                                                    what: str, name: str, labels: dict) -> None:
    _fed_gateway(client, state, clock)
    m = scrape(client)
    assert (name, tuple(sorted(labels.items()))) in m, sorted(k for k in m if k[0] == name)


def test_service_reports_become_series_and_go_when_the_service_stops(client: TestClient, state: GatewayState,
                                                                     clock: FakeClock) -> None:
    _fed_gateway(client, state, clock)
    m = scrape(client)
    assert m[("bevflow_detector_latency_seconds_bucket", (("instance", "d1"), ("le", "0.05")))] == 0
    assert m[("bevflow_detector_latency_seconds_bucket", (("instance", "d1"), ("le", "0.1")))] == 1
    assert m[("bevflow_history_backlog_rows", (("instance", "r1"),))] == 12
    assert m[("bevflow_alerts_raised_total", (("type", "over_capacity"),))] == 0
    assert m[("bevflow_frame_to_alert_seconds_count", ())] == 1
    clock.advance(60)  # no report for a minute: those instances are gone
    assert not any(k[0].startswith("bevflow_history_") for k in scrape(client))


def test_a_report_cannot_add_series_of_its_own(client: TestClient, clock: FakeClock) -> None:
    forged = ServiceMetrics.model_validate({"site": "hall", "service": "x", "instance": "x", "time_ns": clock(),
                                            "values": [{"name": "site_ok", "value": 1}, {"name": "anything", "value": 1}]})
    client.app.state.service_metrics.put(forged)  # type: ignore[attr-defined]
    assert [k for k in scrape(client) if k[0].endswith(("anything", "anything_total"))] == []


def test_health_and_metrics_say_which_model_and_provider_each_camera_runs(client: TestClient, clock: FakeClock) -> None:
    book = MetricsBook()
    book.set("detector_model_info", 1.0, camera="north", model="rim-tiles", provider="CUDAExecutionProvider")
    book.set("detector_model_info", 1.0, camera="south", model="bevflow-person-centernet.onnx", provider="CPUExecutionProvider")
    client.app.state.service_metrics.put(_report("detector", "d1", book, clock()))  # type: ignore[attr-defined]
    health = client.get("/api/health").json()
    assert health["detector_models"] == [
        {"camera": "north", "model": "rim-tiles", "provider": "CUDAExecutionProvider", "instance": "d1"},
        {"camera": "south", "model": "bevflow-person-centernet.onnx", "provider": "CPUExecutionProvider", "instance": "d1"},
    ]
    labels = (("camera", "north"), ("instance", "d1"), ("model", "rim-tiles"), ("provider", "CUDAExecutionProvider"))
    assert scrape(client)[("bevflow_detector_model_info", labels)] == 1
    clock.advance(60)  # the detector stopped reporting: its cameras' models are no longer claimed
    assert client.get("/api/health").json()["detector_models"] == []

"""The site's health as Prometheus metrics, read from the gateway's state at each scrape.

Everything here is what ``/api/health`` and ``/api/cameras`` already know, in Prometheus's text
format (``prometheus-client``): whether the site is ok, per-camera frames received and lost, how
far behind each camera and the tracker's ticks are, live services, open alerts, occupancy and
websocket clients. Nothing is counted twice: a scrape reads the same counters the JSON routes do.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator
from typing import Any

from prometheus_client import generate_latest
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric, SummaryMetricFamily
from prometheus_client.registry import Collector, CollectorRegistry

from bevflow_services.gateway.routes.health import Status, site_health
from bevflow_services.gateway.state import GatewayState

PREFIX = "bevflow_"
STATUSES: tuple[Status, ...] = ("ok", "degraded", "stale", "no_data")
CAMERA_STATES = ("up", "down", "unknown")


def exposition(state: GatewayState, bus_stats: Any = None) -> bytes:
    """The metrics in Prometheus's text format. A registry of its own each time, never the
    process-wide one, so two gateways in one process (tests) never mix."""
    registry = CollectorRegistry(auto_describe=False)
    registry.register(SiteCollector(state, bus_stats))
    return generate_latest(registry)


class SiteCollector(Collector):
    """Yields every ``bevflow_*`` metric from the state, at scrape time."""

    def __init__(self, state: GatewayState, bus_stats: Any = None) -> None:
        self.state = state
        self.bus_stats = bus_stats  # bevflow_services.bus.BusStats, when fed from the bus

    def collect(self) -> Iterator[Metric]:
        yield from self._site()
        yield from self._cameras()
        yield from self._ticks()
        yield from self._alerts_and_clients()
        yield from self._bus()

    def _site(self) -> Iterator[Metric]:
        health = site_health(self.state)
        status = _gauge("site_status", "1 for the site's current /api/health status", ["status"])
        for name in STATUSES:
            status.add_metric([name], float(health.status == name))
        yield status
        yield _value(_gauge("site_ok", "1 when /api/health says ok (answers 200), else 0"), float(health.status == "ok"))
        yield _value(_gauge("degraded_reasons", "how many reasons the live data is degraded for now"), len(health.reasons))
        yield _value(_gauge("uptime_seconds", "seconds since the gateway started"), health.uptime_s)
        if health.tracks_age_s is not None:
            yield _value(_gauge("tracks_age_seconds", "seconds since the newest tracks message arrived"), health.tracks_age_s)
        services = _gauge("services_up", "live instances of each service (liveliness tokens)", ["service"])
        for service, count in sorted(Counter(s.name for s in health.services).items()):
            services.add_metric([service], count)
        yield services
        yield _value(CounterMetricFamily(PREFIX + "ignored_messages", "messages refused: another site, an unknown "
                                         "camera, out of order"), health.ignored_messages)
        occupancy = self.state.occupancy
        if occupancy is not None:
            yield _value(_gauge("occupancy_people", "people in the whole site"), occupancy.total)
            zones = _gauge("zone_occupancy_people", "people in each zone", ["zone"])
            for zone in occupancy.zones:
                zones.add_metric([zone.id], zone.count)
            yield zones

    def _cameras(self) -> Iterator[Metric]:
        labels = ["camera"]
        state = _gauge("camera_state", "1 for each camera's state: up, down or unknown (before its first message)",
                       ["camera", "state"])
        received = CounterMetricFamily(PREFIX + "camera_frames_received", "frames of each camera that reached the "
                                       "gateway", labels=labels)
        dropped = CounterMetricFamily(PREFIX + "camera_frames_dropped", "frames of each camera lost on the way "
                                      "(gaps in its sequence numbers)", labels=labels)
        lag = _gauge("camera_lag_seconds", "arrival minus capture time of each camera's newest message (the "
                     "ingest, detector and projector behind it)", labels)
        age = _gauge("camera_age_seconds", "seconds since each camera's newest message arrived", labels)
        for camera in self.state.camera_health():
            for name in CAMERA_STATES:
                state.add_metric([camera.camera, name], float(camera.state == name))
            received.add_metric([camera.camera], camera.received)
            dropped.add_metric([camera.camera], camera.dropped)
            if camera.last_capture_ns is not None and camera.last_received_ns is not None:
                lag.add_metric([camera.camera], (camera.last_received_ns - camera.last_capture_ns) / 1e9)
            if camera.age_s is not None:
                age.add_metric([camera.camera], camera.age_s)
        yield from (state, received, dropped, lag, age)

    def _ticks(self) -> Iterator[Metric]:
        timing = self.state.tick_timing()
        yield SummaryMetricFamily(PREFIX + "tick_latency_seconds", "tracker ticks received, and their capture to "
                                  "arrival time at the gateway (cameras, detector, projector and tracker together)",
                                  count_value=timing.count, sum_value=timing.latency_sum_s)
        if timing.latency_s is not None:
            yield _value(_gauge("last_tick_latency_seconds", "capture to arrival at the gateway of the newest tick"),
                         timing.latency_s)
        if timing.interval_s is not None:
            yield _value(_gauge("tick_interval_seconds", "capture time between the newest two ticks"), timing.interval_s)

    def _alerts_and_clients(self) -> Iterator[Metric]:
        active = _gauge("alerts_active", "alerts started and not ended, by type", ["type"])
        for kind, count in sorted(Counter(e.type for e in self.state.active_alerts()).items()):
            active.add_metric([kind], count)
        yield active
        clients = _gauge("websocket_clients", "websocket clients connected, by stream", ["stream"])
        clients.add_metric(["alerts"], len(self.state.alerts))
        clients.add_metric(["tracks"], len(self.state.tracks_stream))
        yield clients

    def _bus(self) -> Iterator[Metric]:
        if self.bus_stats is None:
            return
        snapshot = self.bus_stats.snapshot()
        messages = CounterMetricFamily(PREFIX + "bus_messages", "messages the gateway's subscriptions handled, by "
                                       "outcome (dropped: a full queue lost its oldest)", labels=["outcome"])
        for outcome in ("received", "decoded", "dropped", "handler_errors"):
            messages.add_metric([outcome], snapshot[outcome])
        yield messages
        rejected = CounterMetricFamily(PREFIX + "bus_rejected", "messages refused as invalid, by reason",
                                       labels=["reason"])
        for reason, count in sorted(snapshot["rejected"].items()):
            rejected.add_metric([reason], count)
        yield rejected


def _gauge(name: str, documentation: str, labels: list[str] | None = None) -> GaugeMetricFamily:
    return GaugeMetricFamily(PREFIX + name, documentation, labels=labels)


def _value(metric: GaugeMetricFamily | CounterMetricFamily, value: float) -> Metric:
    metric.add_metric([], value)
    return metric

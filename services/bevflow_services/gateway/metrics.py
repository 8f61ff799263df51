"""The site's health as Prometheus metrics, read from the gateway's state at each scrape.

Everything here is what ``/api/health`` and ``/api/cameras`` already know, in Prometheus's text
format (``prometheus-client``): whether the site is ok, per-camera frames received and lost, how
far behind each camera and the tracker's ticks are, live services, open alerts, occupancy and
websocket clients. Nothing is counted twice: a scrape reads the same counters the JSON routes do.
Besides: the alerts the gateway received (``AlertTally``: raised by type, and how long after the
capture of the frames behind them), and what the other services measure about themselves and
send over the bus (``ServiceMetricsStore``; the series are named in
``bevflow_services.service_metrics.SERIES``).
"""

from __future__ import annotations

import threading
import time
from collections import Counter, OrderedDict
from collections.abc import Callable, Iterator
from typing import Any

from prometheus_client import generate_latest
from prometheus_client.core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    HistogramMetricFamily,
    Metric,
    SummaryMetricFamily,
)
from prometheus_client.registry import Collector, CollectorRegistry

from bevflow.schemas import EVENT_TYPES, AlertMessage, HistogramSeries, MetricSeries, ServiceMetrics

from bevflow_services.gateway.site_health import Status, site_health
from bevflow_services.gateway.state import GatewayState
from bevflow_services.service_metrics import REPORT_EVERY_S, SERIES, Histogram

PREFIX = "bevflow_"
STATUSES: tuple[Status, ...] = ("ok", "degraded", "stale", "no_data")
CAMERA_STATES = ("up", "down", "unknown")
# A service instance that has not reported for this long has stopped: its series go.
SERVICE_STALE_S = 4 * REPORT_EVERY_S
SEEN_ALERTS = 4096  # alert ids remembered to count each alert as raised once


class AlertTally:
    """Alerts as the gateway receives them: how many were raised, by type, and the capture of the
    frames behind each message to its arrival here (one host's clock, or NTP-synchronised hosts).
    ``keep`` is an observer of the state's alert fan-out. Thread-safe."""

    def __init__(self, clock: Callable[[], int] = time.time_ns) -> None:
        self.clock = clock
        self.raised: Counter[str] = Counter()
        self.latency = Histogram()
        self._seen: OrderedDict[str, None] = OrderedDict()
        self._lock = threading.Lock()

    def keep(self, alert: AlertMessage) -> None:
        raised_ns = alert.event.raised_ns
        with self._lock:
            if alert.id not in self._seen:
                self.raised[alert.type] += 1
                self._seen[alert.id] = None
                if len(self._seen) > SEEN_ALERTS:
                    self._seen.popitem(last=False)
            if raised_ns is not None:
                self.latency.observe(max(0.0, (self.clock() - raised_ns) / 1e9))

    def snapshot(self) -> tuple[dict[str, int], HistogramSeries]:
        with self._lock:
            return dict(self.raised), HistogramSeries(name="frame_to_alert_seconds", bounds=list(self.latency.bounds),
                                                      counts=self.latency.cumulative(), count=self.latency.count,
                                                      sum=self.latency.total)


class ServiceMetricsStore:
    """The newest ``ServiceMetrics`` of each service instance, from the bus. Thread-safe."""

    def __init__(self, clock: Callable[[], int] = time.time_ns) -> None:
        self.clock = clock
        self._newest: dict[tuple[str, str], ServiceMetrics] = {}
        self._lock = threading.Lock()

    def put(self, message: ServiceMetrics) -> None:  # on a Zenoh thread
        with self._lock:
            self._newest[(message.service, message.instance)] = message

    def current(self) -> list[ServiceMetrics]:
        """Each instance's newest report, leaving out instances silent for ``SERVICE_STALE_S``."""
        oldest = self.clock() - int(SERVICE_STALE_S * 1e9)
        with self._lock:
            return [m for _, m in sorted(self._newest.items()) if m.time_ns >= oldest]


def exposition(state: GatewayState, bus_stats: Any = None, alerts: AlertTally | None = None,
               services: ServiceMetricsStore | None = None) -> bytes:
    """The metrics in Prometheus's text format. A registry of its own each time, never the
    process-wide one, so two gateways in one process (tests) never mix."""
    registry = CollectorRegistry(auto_describe=False)
    registry.register(SiteCollector(state, bus_stats, alerts, services))
    return generate_latest(registry)


class SiteCollector(Collector):
    """Yields every ``bevflow_*`` metric from the state, at scrape time."""

    def __init__(self, state: GatewayState, bus_stats: Any = None, alerts: AlertTally | None = None,
                 services: ServiceMetricsStore | None = None) -> None:
        self.state = state
        self.bus_stats = bus_stats  # bevflow_services.bus.BusStats, when fed from the bus
        self.alerts = alerts
        self.services = services

    def collect(self) -> Iterator[Metric]:
        yield from self._site()
        yield from self._cameras()
        yield from self._ticks()
        yield from self._alerts_and_clients()
        yield from self._alert_tally()
        yield from self._services()
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
        active = _gauge("alerts_active", "alerts started and not ended, by type (distance_incident: the open "
                        "incidents)", ["type"])
        counts: Counter[str] = Counter(e.type for e in self.state.active_alerts())
        for kind in EVENT_TYPES:
            active.add_metric([kind], counts[kind])
        yield active
        clients = _gauge("websocket_clients", "websocket clients connected, by stream", ["stream"])
        clients.add_metric(["alerts"], len(self.state.alerts))
        clients.add_metric(["tracks"], len(self.state.tracks_stream))
        yield clients

    def _alert_tally(self) -> Iterator[Metric]:
        if self.alerts is None:
            return
        raised, latency = self.alerts.snapshot()
        counter = CounterMetricFamily(PREFIX + "alerts_raised", "alerts the gateway received, each counted once, "
                                      "by type", labels=["type"])
        for kind in EVENT_TYPES:
            counter.add_metric([kind], raised.get(kind, 0))
        yield counter
        family = HistogramMetricFamily(PREFIX + latency.name, "capture of the frames behind an alert message to its "
                                       "arrival at the gateway (detection, tracking, analysis and the bus)")
        _add_histogram(family, [], latency)
        yield family

    def _services(self) -> Iterator[Metric]:
        """What the services reported over the bus, one family per series name of ``SERIES``,
        each sample labelled with the instance that measured it."""
        if self.services is None:
            return
        families: dict[str, tuple[Any, list[str]]] = {}
        for report in self.services.current():
            reported: list[MetricSeries | HistogramSeries] = [*report.values, *report.histograms]
            for series in reported:
                info = SERIES.get(series.name)
                if info is None or (info.kind == "histogram") != isinstance(series, HistogramSeries):
                    continue  # not a series this gateway serves
                labels = ["instance", *sorted(series.labels)]
                family, names = families.setdefault(series.name, (_family(series.name, info.kind, info.help, labels), labels))
                if names != labels:
                    continue  # another label set under the same name: a mismatched service
                values = [report.instance, *(series.labels[k] for k in labels[1:])]
                if isinstance(series, HistogramSeries):
                    _add_histogram(family, values, series)
                else:
                    family.add_metric(values, series.value)
        yield from (family for family, _ in families.values())

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


def _family(name: str, kind: str, documentation: str, labels: list[str]) -> Metric:
    if kind == "counter":
        return CounterMetricFamily(PREFIX + name, documentation, labels=labels)
    if kind == "histogram":
        return HistogramMetricFamily(PREFIX + name, documentation, labels=labels)
    return _gauge(name, documentation, labels)


def _add_histogram(family: Any, labels: list[str], series: HistogramSeries) -> None:
    buckets = [(repr(float(b)), float(c)) for b, c in zip(series.bounds, series.counts, strict=True)]
    family.add_metric(labels, [*buckets, ("+Inf", float(series.count))], series.sum)


def _gauge(name: str, documentation: str, labels: list[str] | None = None) -> GaugeMetricFamily:
    return GaugeMetricFamily(PREFIX + name, documentation, labels=labels)


def _value(metric: GaugeMetricFamily | CounterMetricFamily, value: float) -> Metric:
    metric.add_metric([], value)
    return metric

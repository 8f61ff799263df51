"""What a service measures about itself, sent over the bus for the gateway's ``/metrics``.

The gateway sees the data flow (frames, ticks, alerts) but not what happens inside the other
processes: how long the detector takes, how long a tick takes to compute, which cameras' results
reach the tracker too late, how fast the history is written. Each of those services keeps a
``MetricsBook`` and publishes it every ``REPORT_EVERY_S`` as a ``ServiceMetrics`` message (totals
since the process started, as Prometheus expects), on ``Keys.metrics(service, instance)``, the way
its liveliness token announces it. The gateway keeps each instance's newest and serves the series
named in ``SERIES``, and only those: a message on the bus cannot add series at will.
"""

from __future__ import annotations

import bisect
import logging
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Literal

from bevflow.schemas import HistogramSeries, MetricSeries, ServiceMetrics

from bevflow_services import bus
from bevflow_services.runtime import periodically

log = logging.getLogger(__name__)

REPORT_EVERY_S = 5.0
# Seconds: from a millisecond (a tick of a quiet hall) to ten (a detector far behind).
LATENCY_BUCKETS_S: tuple[float, ...] = (0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0)

Kind = Literal["counter", "gauge", "histogram"]


@dataclass(frozen=True)
class SeriesInfo:
    kind: Kind
    help: str


SERIES: dict[str, SeriesInfo] = {
    "camera_frames_late": SeriesInfo("counter", "results of each camera that reached the tracker after their tick had "
                                     "closed, so left out of it"),
    "detector_latency_seconds": SeriesInfo("histogram", "capture of a frame to its boxes leaving the detector (the "
                                           "ingest, the wait for the detector and the detection)"),
    "tick_duration_seconds": SeriesInfo("histogram", "the tracker's time to fuse, track and analyse one tick"),
    "history_write_seconds": SeriesInfo("histogram", "the recorder's time to write one batch to the history database"),
    "history_backlog_rows": SeriesInfo("gauge", "rows the recorder holds that are not in the history database yet"),
    "alert_feed_alerts": SeriesInfo("counter", "alerts an MQTT or webhook service took from the bus, by outcome: "
                                    "forwarded, refused (beyond the flood limit) or lapsed (forwarded ended, unrenewed)"),
    "outbox_backlog_alerts": SeriesInfo("gauge", "alerts an MQTT or webhook service holds that its receiver has not "
                                        "acknowledged yet (they go out, in order, once it answers)"),
    "detector_frames_reused": SeriesInfo("counter", "frames of each camera that showed nothing new, whose last boxes "
                                         "the detector sent again without running (bevflow serve detector --skip-still)"),
    "detector_model_info": SeriesInfo("gauge", "1 for each camera the detector serves, labelled with its model and the "
                                      "ONNX Runtime execution provider that model runs on"),
}


@dataclass
class Histogram:
    """Observations counted into cumulative buckets, as Prometheus's histograms are."""

    bounds: tuple[float, ...] = LATENCY_BUCKETS_S
    buckets: list[int] = field(default_factory=list)  # per bound, not cumulative; the last is +Inf
    count: int = 0
    total: float = 0.0

    def __post_init__(self) -> None:
        self.buckets = self.buckets or [0] * (len(self.bounds) + 1)

    def observe(self, value: float) -> None:
        self.buckets[bisect.bisect_left(self.bounds, value)] += 1
        self.count += 1
        self.total += value

    def cumulative(self) -> list[int]:
        """Observations at or below each bound."""
        running, out = 0, []
        for n in self.buckets[:-1]:
            running += n
            out.append(running)
        return out


Labels = tuple[tuple[str, str], ...]


class MetricsBook:
    """One process's counters, gauges and histograms (names from ``SERIES``). Thread-safe."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._values: dict[tuple[str, Labels], float] = {}
        self._histograms: dict[tuple[str, Labels], Histogram] = {}

    @staticmethod
    def _key(name: str, kinds: tuple[Kind, ...], labels: dict[str, str]) -> tuple[str, Labels]:
        if name not in SERIES or SERIES[name].kind not in kinds:
            raise KeyError(f"{name!r} is not a {' or '.join(kinds)} in service_metrics.SERIES")
        return name, tuple(sorted(labels.items()))

    def count(self, name: str, by: float = 1.0, **labels: str) -> None:
        key = self._key(name, ("counter",), labels)
        with self._lock:
            self._values[key] = self._values.get(key, 0.0) + by

    def set(self, name: str, value: float, **labels: str) -> None:
        key = self._key(name, ("gauge",), labels)
        with self._lock:
            self._values[key] = value

    def observe(self, name: str, seconds: float, **labels: str) -> None:
        key = self._key(name, ("histogram",), labels)
        with self._lock:
            self._histograms.setdefault(key, Histogram()).observe(seconds)

    @contextmanager
    def timed(self, name: str, **labels: str) -> Iterator[None]:
        """Observe how long the ``with`` block took."""
        start = time.perf_counter()
        try:
            yield
        finally:
            self.observe(name, time.perf_counter() - start, **labels)

    def message(self, site: str, service: str, instance: str, time_ns: int) -> ServiceMetrics:
        with self._lock:
            values = [MetricSeries(name=n, labels=dict(labels), value=v)
                      for (n, labels), v in sorted(self._values.items())]
            histograms = [HistogramSeries(name=n, labels=dict(labels), bounds=list(h.bounds), counts=h.cumulative(),
                                          count=h.count, sum=h.total)
                          for (n, labels), h in sorted(self._histograms.items())]
        return ServiceMetrics(site=site, service=service, instance=instance, time_ns=time_ns, values=values,
                              histograms=histograms)


@contextmanager
def reporting(session: Any, site: str, service: str, book: MetricsBook,
              every_s: float = REPORT_EVERY_S, clock: Callable[[], int] = time.time_ns) -> Iterator[None]:
    """Publish ``book`` every ``every_s`` seconds (and once more at the end) while the block runs."""
    keys, instance = bus.Keys(site), bus.default_instance_id()
    publication = bus.Publication(session, keys.metrics(service, instance), bus.JsonCodec(ServiceMetrics))

    def publish() -> None:
        publication.put(book.message(site, service, instance, clock()))

    try:
        with periodically(every_s, publish, f"{service}-metrics"):
            yield
    finally:
        try:
            publish()
        except Exception:  # measurements must never stop the service they measure
            log.exception("could not publish %s metrics", service)
        publication.close()

"""``MetricsBook``: what a service measures, as the ``ServiceMetrics`` message the gateway serves."""

from __future__ import annotations

import pytest

from bevflow.schemas import ServiceMetrics

from bevflow_services.service_metrics import SERIES, Histogram, MetricsBook


@pytest.mark.parametrize(
    ("values", "cumulative"),
    [
        ([], [0, 0, 0]),
        ([0.1], [1, 1, 1]),  # a bound holds the values equal to it
        ([0.05, 0.15, 0.3, 9.0], [1, 2, 3]),
    ],
)
def test_histogram_buckets_are_cumulative(values: list[float], cumulative: list[int]) -> None:
    histogram = Histogram(bounds=(0.1, 0.2, 0.5))
    for value in values:
        histogram.observe(value)
    assert histogram.cumulative() == cumulative
    assert histogram.count == len(values) and histogram.total == pytest.approx(sum(values))


def test_a_book_becomes_one_message_that_survives_the_bus() -> None:
    book = MetricsBook()
    book.count("camera_frames_late", camera="north")
    book.count("camera_frames_late", 2, camera="north")
    book.count("camera_frames_late", 0, camera="south")
    book.set("history_backlog_rows", 7)
    with book.timed("tick_duration_seconds"):
        pass
    message = ServiceMetrics.model_validate_json(book.message("hall", "tracker", "t1", 5).model_dump_json())
    values = {(v.name, tuple(v.labels.items())): v.value for v in message.values}
    assert values == {("camera_frames_late", (("camera", "north"),)): 3, ("camera_frames_late", (("camera", "south"),)): 0,
                      ("history_backlog_rows", ()): 7}
    [tick] = message.histograms
    assert tick.name == "tick_duration_seconds" and tick.count == 1 and tick.counts[-1] == 1


@pytest.mark.parametrize(
    ("call", "name"),
    [("count", "no_such_series"), ("count", "tick_duration_seconds"), ("set", "camera_frames_late"),
     ("observe", "history_backlog_rows")],
)
def test_only_the_named_series_of_the_right_kind(call: str, name: str) -> None:
    with pytest.raises(KeyError, match="service_metrics.SERIES"):
        getattr(MetricsBook(), call)(name, 1.0)


def test_every_series_is_named_for_prometheus() -> None:
    assert all(name.islower() and " " not in name and info.help for name, info in SERIES.items())

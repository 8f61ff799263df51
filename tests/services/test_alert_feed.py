"""``AlertFeed``, what ``bevflow serve mqtt`` and ``bevflow serve webhook`` forward from the bus:
alerts as they come, the ended version of those nobody renews, and no flood."""

from __future__ import annotations

import argparse
import logging
import time

import pytest

from bevflow.alert_lease import BURST, LEASE_S
from bevflow.schemas import AlertMessage, Event, FEED_EVENT_TYPES, OpenAlerts

from bevflow_services.alert_feed import AlertFeed, lease_seconds
from tests.services.gateway.feed import S, T0, FakeClock, incident, over_capacity, violation

NOW = T0 + 3600 * S  # the service's clock; the alerts started an hour earlier


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock(NOW)


@pytest.fixture
def forwarded() -> list[Event]:
    return []


@pytest.fixture
def feed(clock: FakeClock, forwarded: list[Event]) -> AlertFeed:
    return AlertFeed(forwarded.append, FEED_EVENT_TYPES, clock=clock)


def renewal(*ids: str) -> OpenAlerts:
    return OpenAlerts(site="hall", time_ns=T0, ids=list(ids))


def test_a_forged_open_alert_is_forwarded_then_ended_at_its_arrival_once_its_lease_is_over(
        feed: AlertFeed, clock: FakeClock, forwarded: list[Event]) -> None:
    feed.on_event(incident("forged", T0))
    clock.advance(LEASE_S)
    assert feed.end_lapsed() == []  # one whole lease: not over yet
    clock.advance(1.0)
    feed.end_lapsed()
    clock.advance(LEASE_S * 2)
    assert feed.end_lapsed() == []  # ended once
    messages = [AlertMessage.from_event(e) for e in forwarded]
    assert [(m.id, m.active, m.end_ns) for m in messages] == [("forged", True, None), ("forged", False, NOW)]
    assert messages[1].event.model_copy(update={"end_ns": None}) == incident("forged", T0)  # all else as it came
    assert feed.counts == {"forwarded": 1, "lapsed": 1}


def test_a_renewed_alert_does_not_end_and_ends_at_its_last_renewal_once_renewals_stop(
        feed: AlertFeed, clock: FakeClock, forwarded: list[Event]) -> None:
    feed.on_event(over_capacity("c1", T0))
    for _ in range(6):
        clock.advance(LEASE_S / 3)
        feed.on_open_alerts(renewal("c1", "unknown"))
        assert feed.end_lapsed() == []
    last_renewal = clock.now
    clock.advance(LEASE_S + 1)
    assert [(e.id, e.end_ns) for e in feed.end_lapsed()] == [("c1", last_renewal)]
    assert [e.id for e in forwarded] == ["c1", "c1"]


def test_an_alert_the_tracker_ends_is_forwarded_ended_and_never_lapses(
        feed: AlertFeed, clock: FakeClock, forwarded: list[Event]) -> None:
    feed.on_event(incident("i1", T0))
    feed.on_event(incident("i1", T0, end_ns=T0 + 5 * S))
    clock.advance(LEASE_S * 2)
    assert feed.end_lapsed() == []
    assert [(e.id, e.end_ns) for e in forwarded] == [("i1", None), ("i1", T0 + 5 * S)]


def test_a_flood_beyond_the_burst_is_refused_counted_and_logged_now_and_then(
        feed: AlertFeed, clock: FakeClock, forwarded: list[Event], caplog: pytest.LogCaptureFixture) -> None:
    flood = 3 * BURST
    with caplog.at_level(logging.WARNING, logger="bevflow_services.alert_feed"):
        for k in range(flood):
            feed.on_event(incident(f"forged-{k}", T0))
    assert len(forwarded) == BURST and feed.counts["refused"] == flood - BURST
    assert len(caplog.records) == 1 and "a flood" in caplog.text
    feed.on_event(incident("forged-0", T0, end_ns=T0 + S))  # a held alert's end is not a new alert
    clock.advance(1.0)
    feed.on_event(over_capacity("real", T0))  # the bucket refills at its rate
    assert [e.id for e in forwarded[-2:]] == ["forged-0", "real"]
    assert feed.counts == {"forwarded": BURST + 2, "refused": flood - BURST}
    clock.advance(LEASE_S + 1.0)
    assert len(feed.end_lapsed()) == BURST  # the forged ones still open, "real" too
    reported = {v.labels["outcome"]: v.value for v in feed.book.message("hall", "mqtt", "m1", clock()).values
                if v.name == "alert_feed_alerts"}
    assert reported == {"forwarded": BURST + 2, "refused": flood - BURST, "lapsed": BURST}  # what /metrics will serve


def test_alerts_of_other_types_are_not_forwarded_held_or_counted(feed: AlertFeed, clock: FakeClock,
                                                                 forwarded: list[Event]) -> None:
    assert "distance_violation" not in FEED_EVENT_TYPES
    for k in range(BURST + 1):
        feed.on_event(violation(f"v{k}", T0))
    clock.advance(LEASE_S * 2)
    assert forwarded == [] and feed.end_lapsed() == [] and feed.counts == {}


def test_the_lapsed_alerts_are_ended_on_a_thread_while_the_block_runs(forwarded: list[Event]) -> None:
    feed = AlertFeed(forwarded.append, FEED_EVENT_TYPES, lease_s=0.05)
    with feed.ending_lapsed(every_s=0.01):
        feed.on_event(over_capacity("forged", T0))
        deadline = time.monotonic() + 5.0
        while len(forwarded) < 2:
            assert time.monotonic() < deadline, forwarded
            time.sleep(0.01)
    assert [(e.id, e.end_ns is not None) for e in forwarded] == [("forged", False), ("forged", True)]


@pytest.mark.parametrize("text", ["0", "-1", "nan", "inf"])
def test_a_lease_is_a_positive_number_of_seconds(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match="positive number of seconds"):
        lease_seconds(text)

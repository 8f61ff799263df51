"""What a service that forwards the bus's alerts to an outside receiver (``bevflow serve mqtt``,
``bevflow serve webhook``) passes on.

Such a receiver cannot tell a forged alert from the tracker's, so the forwarding service applies
what the gateway applies (``bevflow.alert_lease``): new alerts are taken at most at the rate
limit, the rest refused and counted; and each open alert is held under a lease that the tracker's
``OpenAlerts`` renew. An open alert nobody renews is forwarded once more, ended at its last
renewal, in the shape of an alert the tracker ends; so a forged one does not stay open for ever
at the receiver.
"""

from __future__ import annotations

import argparse
import logging
import math
import threading
import time
from collections import Counter
from collections.abc import Callable, Collection, Iterator
from contextlib import contextmanager
from typing import Any

from bevflow.alert_lease import LEASE_S, OpenAlertLeases, RateLimit
from bevflow.schemas import Event, OpenAlerts

from bevflow_services import bus
from bevflow_services.outbox import Outbox
from bevflow_services.runtime import periodically
from bevflow_services.service_metrics import REPORT_EVERY_S, MetricsBook, reporting

log = logging.getLogger(__name__)

LAPSE_CHECK_S = 1.0  # how often the open alerts nobody renews are ended
REFUSAL_LOG_EVERY_S = 10.0  # a flood logs a line now and then, not one per alert


def add_arguments(group: argparse._ArgumentGroup) -> None:
    """The hidden ``--alert-lease-s``: tests shorten the lease with it."""
    group.add_argument("--alert-lease-s", type=lease_seconds, default=LEASE_S, help=argparse.SUPPRESS)


def lease_seconds(text: str) -> float:
    value = float(text)
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"a lease is a positive number of seconds, not {text!r}")
    return value


class AlertFeed:
    """Takes the bus's alerts of ``types`` and their renewals, and hands ``forward`` what to pass
    on: each alert that is taken, and the ended version of each open one whose lease lapsed.

    ``forward`` is called under a lock, so what it receives is in the order decided here (an
    alert's own end and its lapse cannot overtake each other). ``counts`` holds ``forwarded``,
    ``refused`` and ``lapsed``. ``on_event`` and ``on_open_alerts`` may run on any thread.
    """

    def __init__(self, forward: Callable[[Event], object], types: Collection[str], *, lease_s: float = LEASE_S,
                 clock: Callable[[], int] = time.time_ns) -> None:
        self.forward = forward
        self.types = frozenset(types)
        self.clock = clock
        self.counts: Counter[str] = Counter()
        self.book = MetricsBook()  # the same counts for /metrics (``running``)
        self._leases = OpenAlertLeases(lease_s)
        self._rate = RateLimit()
        self._lock = threading.Lock()
        self._last_refusal_log = -REFUSAL_LOG_EVERY_S

    def on_event(self, event: Event) -> None:
        if event.type not in self.types:
            return
        with self._lock:
            now = self.clock()
            if event.id not in self._leases and not self._rate.allow(now):
                self._refuse(f"alert {event.id!r}: more new alerts than the bus may bring (a flood)")
                return
            if not self._leases.room_for(event):
                self._refuse(f"alert {event.id!r}: {self._leases.max_open} alerts are open already")
                return
            if event.end_ns is None:
                self._leases.opened(event, now)
            else:
                self._leases.closed(event.id)
            self.forward(event)
            self._tally("forwarded")

    def on_open_alerts(self, renewal: OpenAlerts) -> None:
        with self._lock:
            self._leases.renew(renewal.ids, self.clock())

    def end_lapsed(self) -> list[Event]:
        """Forward, ended, the open alerts nobody renewed within the lease; returns them."""
        with self._lock:
            ended = self._leases.lapsed(self.clock())
            for event in ended:
                self.forward(event)
                self._tally("lapsed")
        if ended:
            log.warning("%d open alerts ended by themselves: no renewal from the tracker for their lease", len(ended))
        return ended

    def _tally(self, outcome: str) -> None:
        self.counts[outcome] += 1
        self.book.count("alert_feed_alerts", outcome=outcome)

    def _refuse(self, why: str) -> None:
        self._tally("refused")
        now = time.monotonic()
        if now - self._last_refusal_log >= REFUSAL_LOG_EVERY_S:
            self._last_refusal_log = now
            log.warning("refused %s (%d refused so far)", why, self.counts["refused"])

    def subscribe(self, session: Any, keys: bus.Keys) -> list[bus.Subscription[Any]]:
        """The site's alerts (with what the tracker's cache still holds) and their renewals."""
        return [
            bus.HistorySubscription(session, keys.events, bus.JsonCodec[Event](Event, "Event"), self.on_event),
            bus.subscribe(session, keys.open_alerts, bus.JsonCodec(OpenAlerts), self.on_open_alerts),
        ]

    @contextmanager
    def running(self, session: Any, site_id: str, service: str, outbox: Outbox) -> Iterator[None]:
        """While the block runs: lapsed alerts are ended, and this feed's counts and ``outbox``'s
        backlog (what the receiver has not acknowledged yet) go to the gateway's ``/metrics``."""

        def backlog() -> None:
            self.book.set("outbox_backlog_alerts", outbox.backlog())

        backlog()
        with self.ending_lapsed(), periodically(REPORT_EVERY_S, backlog, f"{service}-backlog"), \
                reporting(session, site_id, service, self.book):  # fmt: skip
            yield

    @contextmanager
    def ending_lapsed(self, every_s: float = LAPSE_CHECK_S) -> Iterator[None]:
        """While the block runs, ``end_lapsed`` every ``every_s`` seconds on a thread of its own."""
        with periodically(every_s, self.end_lapsed, "alert-leases"):
            yield

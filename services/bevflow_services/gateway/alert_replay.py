"""``/ws/alerts?since=ID``: the alerts a client missed, from the history, in the order they were sent.

Every alert message has a position: the latest of its times, which is the capture time of the
data that raised it (``raised_ns``) for what the tracker sends, and the end for an alert the
gateway or the recorder ended because its lease ran out; then its id. The tracker raises alerts
in capture-time order, so positions follow the order in which the gateway sends them. A client that
reconnects with the id of the last alert it received gets every alert whose newest message comes
after that alert's newest message, in position order, each once in its newest state (the history
keeps one row per alert, updated when it changes or ends); then the live stream, less what the
replay already sent.

The recorder writes the history in batches, a second or so behind the bus, so the gateway also
remembers the last ``RECENT_ALERTS`` alert messages itself: what the database does not have yet
comes from there.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Iterator
from bevflow.schemas import AlertMessage, Event
from bevflow.units import NS_PER_S

from bevflow_services.gateway.history import EventQuery, HistoryStore

RECENT_ALERTS = 4096
# How long before its last message an alert may have ended (an incident closes once it has been
# quiet a while): history rows that ended earlier than this before the cursor cannot be newer.
END_TO_RAISE_NS = 3600 * NS_PER_S
PAGE = 1000
MAX_REPLAY = 10_000  # beyond this a client is better served by /api/alerts
Position = tuple[int, str]


class ReplayError(ValueError):
    """A ``since`` the gateway cannot replay from; the message names why."""


def position(event: Event) -> Position:
    """Where the message carrying ``event`` stands in the alert stream."""
    times = [t for t in (event.raised_ns, event.end_ns) if t is not None]
    return max(times, default=event.start_ns), event.id


class RecentAlerts:
    """The newest state of the last ``size`` alerts the gateway received, oldest first. Thread-safe."""

    def __init__(self, size: int = RECENT_ALERTS) -> None:
        self.size = size
        self._events: OrderedDict[str, Event] = OrderedDict()
        self._lock = threading.Lock()

    def add(self, event: Event) -> None:
        with self._lock:
            self._events.pop(event.id, None)
            self._events[event.id] = event
            while len(self._events) > self.size:
                self._events.popitem(last=False)

    def keep(self, alert: AlertMessage) -> None:
        self.add(alert.event)

    def get(self, event_id: str) -> Event | None:
        with self._lock:
            return self._events.get(event_id)

    def events(self) -> list[Event]:
        with self._lock:
            return list(self._events.values())


def missed_alerts(since_id: str, recent: RecentAlerts, history: HistoryStore, types: frozenset[str] | None,
                  wanted: Callable[[AlertMessage], bool]) -> list[AlertMessage]:
    """The alerts after ``since_id`` that ``wanted`` passes, oldest position first; ``ReplayError``
    for an id neither the gateway nor the history knows, or too many alerts to replay."""
    if not since_id:
        raise ReplayError("since: give the id of the last alert received")
    cursor_event = recent.get(since_id) or history.event(since_id)
    if cursor_event is None:
        raise ReplayError(f"since: no alert {since_id!r} in the history (too old, or never raised)")
    cursor = position(cursor_event)
    newest: dict[str, Event] = {}
    for event in [*history_rows(history, types, cursor[0] - END_TO_RAISE_NS), *recent.events()]:
        if position(event) > cursor and (event.id not in newest or position(event) > position(newest[event.id])):
            newest[event.id] = event
    messages = [AlertMessage.from_event(e) for e in sorted(newest.values(), key=position)]
    return [m for m in messages if wanted(m)]


def history_rows(history: HistoryStore, types: frozenset[str] | None, ended_after_ns: int) -> Iterator[Event]:
    """Every stored alert still open or ended after ``ended_after_ns``, a page at a time."""
    query = EventQuery(types=types, since_ns=ended_after_ns)
    offset = 0
    while True:
        page, total = history.events(query, PAGE, offset)
        if total > MAX_REPLAY:
            raise ReplayError(f"since: {total} alerts to replay, more than {MAX_REPLAY}; read them from /api/alerts "
                              "and reconnect without since")
        yield from page
        offset += len(page)
        if not page or offset >= total:
            return

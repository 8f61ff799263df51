"""How long an alert from the bus stays open without word from the tracker, and how many new
alerts a receiver takes.

The bus needs no password on one host, so anyone who reaches it can publish alerts. Getting in is
then expected; never ending is not. So an open alert has a lease: the tracker publishes the ids
of the alerts it still has open (``bevflow.schemas.OpenAlerts``) every ``RENEW_EVERY_S``, and a
receiver (the gateway, the recorder, the MQTT and webhook services) counts an open alert as over
once ``LEASE_S`` have passed since it last arrived or was renewed. An alert nobody renews (forged,
or left open by a tracker that died) ends by itself, and ends at its last renewal.
``OpenAlertLeases`` keeps that account for a receiver that holds its open alerts in memory.

A flood is also bounded where it arrives: each receiver takes alerts at ``RATE_PER_S`` on average
with bursts of ``BURST`` (the tracker's default alert cache, which a restarted recorder fetches at
once) and refuses and counts the rest.

>>> lease_over(renewed_ns=0, now_ns=int(LEASE_S * NS_PER_S))
False
>>> lease_over(renewed_ns=0, now_ns=int(LEASE_S * NS_PER_S) + 1)
True
>>> bucket = RateLimit(rate_per_s=1.0, burst=2)
>>> [bucket.allow(0), bucket.allow(0), bucket.allow(0), bucket.allow(NS_PER_S)]
[True, True, False, True]
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from bevflow.schemas import Event
from bevflow.units import NS_PER_S

LEASE_S = 60.0
# Four renewals per lease: one or two lost on a congested link do not end a real alert.
RENEW_EVERY_S = 15.0
# The tracker raises a handful of alerts a second in a crowded hall; a hundred is far beyond it.
RATE_PER_S = 100.0
BURST = 10_000
# The most open alerts a receiver keeps in memory (each a few hundred bytes): more than a flood at
# the rate limit can open within one lease (BURST + RATE_PER_S * LEASE_S), so it is a backstop.
MAX_OPEN = 20_000


def lease_over(renewed_ns: int, now_ns: int, lease_s: float = LEASE_S) -> bool:
    """Whether an open alert last renewed at ``renewed_ns`` has lapsed at ``now_ns``."""
    return now_ns - renewed_ns > int(lease_s * NS_PER_S)


@dataclass
class RateLimit:
    """A token bucket: ``allow`` is True at most ``rate_per_s`` times a second on average, and
    ``burst`` times at once after a quiet spell."""

    rate_per_s: float = RATE_PER_S
    burst: int = BURST
    _tokens: float = field(default=-1.0, init=False)
    _last_ns: int | None = field(default=None, init=False)

    def allow(self, now_ns: int) -> bool:
        if self._last_ns is None:
            self._tokens = float(self.burst)
        else:
            elapsed_s = max(0, now_ns - self._last_ns) / NS_PER_S
            self._tokens = min(float(self.burst), self._tokens + elapsed_s * self.rate_per_s)
        self._last_ns = now_ns
        if self._tokens < 1.0:
            return False
        self._tokens -= 1.0
        return True


class OpenAlertLeases:
    """The open alerts a receiver holds, each with when it last arrived or was renewed (on the
    receiver's clock), at most ``max_open`` of them. Not thread-safe: its owner locks.

    >>> from bevflow.schemas import OverCapacity
    >>> leases = OpenAlertLeases(lease_s=60.0)
    >>> alert = OverCapacity(id="c1", start_ns=0, capacity=3, peak=5)
    >>> leases.opened(alert, now_ns=10 * NS_PER_S)
    True
    >>> leases.lapsed(now_ns=70 * NS_PER_S)  # exactly one lease later: not over yet
    []
    >>> [(e.id, e.end_ns) for e in leases.lapsed(now_ns=71 * NS_PER_S)]  # ended at its last renewal
    [('c1', 10000000000)]
    >>> "c1" in leases
    False
    """

    def __init__(self, lease_s: float = LEASE_S, max_open: int = MAX_OPEN) -> None:
        self.lease_s = lease_s
        self.max_open = max_open
        self._open: dict[str, tuple[Event, int]] = {}  # id: (the alert as last received, renewed_ns)

    def __contains__(self, alert_id: object) -> bool:
        return alert_id in self._open

    def __len__(self) -> int:
        return len(self._open)

    def room_for(self, event: Event) -> bool:
        """Whether ``opened`` would hold ``event``: an alert held already (an update) or an ended
        one always, a new open one while fewer than ``max_open`` are held."""
        return event.end_ns is not None or event.id in self._open or len(self._open) < self.max_open

    def opened(self, event: Event, now_ns: int) -> bool:
        """Hold an open alert (or its update), its lease starting again at ``now_ns``; False, and
        nothing held, when there is no room for it."""
        if not self.room_for(event):
            return False
        self._open[event.id] = (event, now_ns)
        return True

    def closed(self, alert_id: str) -> None:
        """The alert ended (an ended version arrived): it is no longer held."""
        self._open.pop(alert_id, None)

    def renew(self, ids: Iterable[str], now_ns: int) -> None:
        """The tracker still has these open: their leases start again at ``now_ns``. Ids not held
        (never received, refused, already ended) are left alone."""
        for alert_id in ids:
            held = self._open.get(alert_id)
            if held is not None:
                self._open[alert_id] = (held[0], now_ns)

    def held(self) -> list[Event]:
        """Every alert held, lapsed or not, in the order they first arrived."""
        return [event for event, _ in self._open.values()]

    def live(self, now_ns: int) -> list[Event]:
        """The alerts held whose lease is not over at ``now_ns``, in the order they first arrived."""
        return [event for event, renewed in self._open.values() if not lease_over(renewed, now_ns, self.lease_s)]

    def lapsed(self, now_ns: int) -> list[Event]:
        """Stop holding the alerts whose lease is over at ``now_ns``, and return each ended at its
        last renewal (at its start if it was renewed before it started, as a forged one may be)."""
        over = [alert_id for alert_id, (_, renewed) in self._open.items() if lease_over(renewed, now_ns, self.lease_s)]
        ended: list[Event] = []
        for alert_id in over:
            event, renewed = self._open.pop(alert_id)
            ended.append(event.model_copy(update={"end_ns": max(event.start_ns, renewed)}))
        return ended

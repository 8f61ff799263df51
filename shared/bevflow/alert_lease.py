"""How long an alert from the bus stays open without word from the tracker, and how many new
alerts a receiver takes.

The bus needs no password on one host, so anyone who reaches it can publish alerts. Getting in is
then expected; never ending is not. So an open alert has a lease: the tracker publishes the ids
of the alerts it still has open (``bevflow.schemas.OpenAlerts``) every ``RENEW_EVERY_S``, and a
receiver (the gateway, the recorder) counts an open alert as over once ``LEASE_S`` have passed
since it last arrived or was renewed. An alert nobody renews (forged, or left open by a tracker
that died) ends by itself, and ends at its last renewal.

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

from dataclasses import dataclass, field

from bevflow.units import NS_PER_S

LEASE_S = 60.0
# Four renewals per lease: one or two lost on a congested link do not end a real alert.
RENEW_EVERY_S = 15.0
# The tracker raises a handful of alerts a second in a crowded hall; a hundred is far beyond it.
RATE_PER_S = 100.0
BURST = 10_000
# The most open alerts a gateway keeps in memory (each a few hundred bytes): more than a flood at
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

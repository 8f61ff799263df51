"""The alert filters every alert listing shares (``/api/alerts``, ``/api/violations``,
``/api/incidents``, ``/api/history/events``), checked against the site."""

from __future__ import annotations

from bevflow_services.gateway.history import EventQuery
from bevflow_services.gateway.params import check_zone


def event_query(site, window, types: frozenset[str] | None, zone: str | None, track: int | None,
                active: bool | None) -> EventQuery:
    """The alert filters every alert listing shares, checked against the site."""
    return EventQuery(types=types, zone=check_zone(site, zone), track=track, active=active,
                      since_ns=window.since_ns, until_ns=window.until_ns)

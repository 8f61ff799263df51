"""The tracker's renewals of its open alerts (``OpenAlerts``), published by a test while it waits,
and the lease scenario the alert forwarders (MQTT, webhook) are tested with."""

from __future__ import annotations

import time
from collections.abc import Callable

from bevflow.schemas import Event, OpenAlerts

from bevflow_services import bus
from tests.services.gateway.feed import T0, incident, over_capacity

RENEW_EVERY_S = 0.2  # several times per test lease, so a late one does not end a renewed alert


def renew_until(renewals: bus.Publication[OpenAlerts], ids: list[str], done: Callable[[], bool], timeout_s: float,
                explain: Callable[[], str]) -> None:
    """Renew ``ids`` on site "hall" every ``RENEW_EVERY_S`` until ``done()``; fail with
    ``explain()`` after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not done():
        assert time.monotonic() < deadline, explain()
        renewals.put(OpenAlerts(site="hall", time_ns=time.time_ns(), ids=ids))
        time.sleep(RENEW_EVERY_S)


def forge_one_and_renew_another(session: bus.Session, forwarded: Callable[[], int], lease_s: float, timeout_s: float,
                                explain: Callable[[], str]) -> None:
    """On site "hall": raise a distance incident "forged" that nobody renews and an over-capacity
    alert "renewed" renewed every ``RENEW_EVERY_S``, until ``forwarded()`` counts both and the
    forged one again (ended by its lease), then for two more leases, in which nothing more may
    come; fail with ``explain()`` after ``timeout_s``."""
    keys = bus.Keys("hall")
    events = bus.Publication(session, keys.events, bus.JsonCodec(Event, "Event"))
    renewals = bus.Publication(session, keys.open_alerts, bus.JsonCodec(OpenAlerts))
    try:
        assert events.wait_for_subscribers(timeout_s) and renewals.wait_for_subscribers(timeout_s), explain()
        events.put(incident("forged", T0))
        events.put(over_capacity("renewed", T0))
        renew_until(renewals, ["renewed"], lambda: forwarded() >= 3, timeout_s, explain)
        quiet_until = time.monotonic() + 2 * lease_s  # the renewed one outlives another lease or two
        renew_until(renewals, ["renewed"], lambda: time.monotonic() > quiet_until, timeout_s, explain)
    finally:
        events.close()
        renewals.close()

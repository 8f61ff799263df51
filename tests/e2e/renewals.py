"""The tracker's renewals of its open alerts (``OpenAlerts``), published by a test while it waits."""

from __future__ import annotations

import time
from collections.abc import Callable

from bevflow.schemas import OpenAlerts

from bevflow_services import bus

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

"""Audit rows for looks at personal data: a person's path, contacts or track summaries, and the
live streams that show where everyone is. ``/api/audit`` lists them."""

from __future__ import annotations

import threading
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import Request
from starlette.requests import HTTPConnection

from bevflow.units import NS_PER_S

from bevflow_services.gateway.auth import Access, AccessDep, client_address, get_access

POLL_QUIET_S = 600.0  # a viewer polling again after this long starts a new audited spell
MAX_POLLERS = 10_000


def record_trace(request: Request, access: AccessDep, action: str, track_id: int | None, detail: str = "") -> None:
    """Write the audit row for a look at personal data (a path, contacts, track summaries)."""
    principal = getattr(request.state, "principal", None)
    who = principal.name if principal is not None else "unknown"
    access.store.audit(access.clock(), who, action, track_id, client_address(request), detail)


class PollAudit:
    """Audit rows for polling a route that shows where everyone is (``GET /api/tracks``): one when
    a viewer (name and address) starts, none again until it has been quiet ``quiet_s``, so a
    dashboard polling every second writes one row per spell, not one per request."""

    def __init__(self, quiet_s: float = POLL_QUIET_S) -> None:
        self.quiet_ns = int(quiet_s * NS_PER_S)
        self._last: dict[tuple[str, str], int] = {}
        self._lock = threading.Lock()

    def record(self, request: Request, access: Access, action: str) -> None:
        principal = getattr(request.state, "principal", None)
        who, client, now = (principal.name if principal is not None else "unknown"), client_address(request), access.clock()
        with self._lock:
            last = self._last.get((who, client))
            self._last[(who, client)] = now
            if len(self._last) > MAX_POLLERS:  # forget the longest quiet, so the table stays small
                del self._last[min(self._last, key=self._last.__getitem__)]
        if last is None or now - last > self.quiet_ns:
            access.store.audit(now, who, action, None, client, f"polling started (again within {self.quiet_ns // NS_PER_S} s of a poll: not recorded)")


@asynccontextmanager
async def audited_stream(conn: HTTPConnection, action: str) -> AsyncIterator[None]:
    """Audit rows for a live stream that shows where everyone is (``live_tracks``): one when it
    opens and one when it closes, with how long it ran. Watching it long enough rebuilds paths,
    which is tracing, so it is recorded like the routes that trace a person."""
    access = get_access(conn)
    principal = access.principal(conn)
    who, client = (principal.name if principal is not None else "unknown"), client_address(conn)
    access.store.audit(access.clock(), who, action, None, client, "opened")
    started = time.monotonic()
    try:
        yield
    finally:  # written at once, even when the stream's task is being cancelled
        access.store.audit(access.clock(), who, action, None, client, f"closed after {time.monotonic() - started:.0f} s")

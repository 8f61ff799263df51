"""Audit rows for looks at personal data: a person's path, contacts or track summaries, and the
live streams that show where everyone is. ``/api/audit`` lists them."""

from __future__ import annotations

import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import Request
from starlette.requests import HTTPConnection

from bevflow_services.gateway.auth import AccessDep, client_address, get_access


def record_trace(request: Request, access: AccessDep, action: str, track_id: int | None, detail: str = "") -> None:
    """Write the audit row for a look at personal data (a path, contacts, track summaries)."""
    principal = getattr(request.state, "principal", None)
    who = principal.name if principal is not None else "unknown"
    access.store.audit(access.clock(), who, action, track_id, client_address(request), detail)


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

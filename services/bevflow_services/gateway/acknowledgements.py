"""Alert acknowledgements, kept by the gateway: who acknowledged which alert, and when.

With the history database (``--db``) they are stored in its ``acknowledgements`` table, so they
outlive the gateway; with the in-memory history they live as long as it does. The routes that
make and list them are in ``routes.acknowledge``; alert listings carry them (``acknowledgements_of``)
and ``/ws/acknowledgements`` sends them as they are made (``acknowledgements_stream``).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Any

from fastapi import WebSocket
from pydantic import BaseModel, Field
from starlette.requests import HTTPConnection

from bevflow.schemas import iso_utc

from bevflow_services.gateway.fanout import Broadcaster
from bevflow_services.gateway.history import EventQuery
from bevflow_services.gateway.state import GatewayState
from bevflow_services.gateway.ws.forwarding import json_sender, serve
from bevflow_services.storage import Acknowledgement, HistoryDatabase


class AcknowledgementView(BaseModel):
    alert_id: str
    user: str
    time: str
    time_ns: int = Field(description="when it was acknowledged (gateway clock)")
    note: str


def view(ack: Acknowledgement) -> AcknowledgementView:
    return AcknowledgementView(alert_id=ack.event_id, user=ack.user, time=iso_utc(ack.time_ns), time_ns=ack.time_ns,
                               note=ack.note)


class AcknowledgementBook:
    """Acknowledgements of one gateway's alerts: in the history database if it has one, else in
    memory (the latest ``max_alerts`` alerts' worth). New ones go out on ``stream``."""

    def __init__(self, state: GatewayState, max_alerts: int = 10_000) -> None:
        self.state = state
        self.db: HistoryDatabase | None = getattr(state.history, "db", None)
        self.stream: Broadcaster[AcknowledgementView] = Broadcaster(256)
        self.max_alerts = max_alerts
        self._lock = threading.Lock()
        self._memory: OrderedDict[str, list[Acknowledgement]] = OrderedDict()
        self._next_id = 1

    def acknowledge(self, alert_id: str, user: str, note: str = "") -> Acknowledgement:
        """Record it; ``KeyError`` for an alert the gateway does not know."""
        now = self.state.clock()
        if "\x00" in alert_id:  # no alert id has one, and PostgreSQL refuses to look for it
            raise KeyError(alert_id)
        note = note.replace("\x00", "\\x00")
        if self.db is not None:
            ack = self.db.acknowledge(alert_id, user, now, note)
        else:
            if not self._known(alert_id):
                raise KeyError(alert_id)
            with self._lock:
                ack = Acknowledgement(self._next_id, alert_id, user, now, note)
                self._next_id += 1
                self._memory.setdefault(alert_id, []).append(ack)
                self._memory.move_to_end(alert_id)
                while len(self._memory) > self.max_alerts:
                    self._memory.popitem(last=False)
        self.stream.publish(view(ack))
        return ack

    def _known(self, alert_id: str) -> bool:
        if any(e.id == alert_id for e in self.state.active_alerts()):
            return True
        events, _ = self.state.history.events(EventQuery(), limit=1_000_000)
        return any(e.id == alert_id for e in events)

    def of(self, alert_ids: list[str]) -> dict[str, list[Acknowledgement]]:
        """Acknowledgements of each of ``alert_ids`` (ids without any are left out), oldest first."""
        if self.db is not None:
            found: dict[str, list[Acknowledgement]] = {}
            unique = [a for a in dict.fromkeys(alert_ids) if "\x00" not in a]
            for start in range(0, len(unique), 500):  # one query per page of alerts, not per alert
                chunk = unique[start:start + 500]
                rows = self.db.backend.query(
                    "SELECT id, event_id, user_name, time_ns, note FROM acknowledgements "
                    f"WHERE event_id IN ({', '.join('?' * len(chunk))}) ORDER BY time_ns, id", chunk)
                for i, e, u, t, n in rows:
                    found.setdefault(str(e), []).append(Acknowledgement(int(i), str(e), str(u), int(t), str(n)))
            return found
        with self._lock:
            return {a: list(self._memory[a]) for a in alert_ids if a in self._memory}

    def latest(self, limit: int) -> list[Acknowledgement]:
        """The newest ``limit`` acknowledgements, oldest first."""
        if self.db is not None:
            rows = self.db.backend.query(
                "SELECT id, event_id, user_name, time_ns, note FROM acknowledgements ORDER BY time_ns DESC, id DESC LIMIT ?",
                [int(limit)])
            return [Acknowledgement(int(i), str(e), str(u), int(t), str(n)) for i, e, u, t, n in reversed(rows)]
        with self._lock:
            every = sorted((a for acks in self._memory.values() for a in acks), key=lambda a: (a.time_ns, a.id))
        return every[-limit:]


def get_book(conn: HTTPConnection) -> AcknowledgementBook:
    book = getattr(conn.app.state, "acknowledgements", None)
    if book is None:
        book = conn.app.state.acknowledgements = AcknowledgementBook(conn.app.state.gateway)
    return book


def acknowledgements_of(conn: HTTPConnection, alert_ids: list[str]) -> dict[str, list[AcknowledgementView]]:
    """For alert listings: each alert's acknowledgements, as views."""
    return {k: [view(a) for a in v] for k, v in get_book(conn).of(alert_ids).items()}


async def acknowledgements_stream(websocket: WebSocket) -> Any:
    """``/ws/acknowledgements``: one ``AcknowledgementView`` per text frame as they are made."""
    book = get_book(websocket)
    async with book.stream.subscribe() as sub:
        await websocket.accept()
        await serve(websocket, sub, json_sender(websocket))

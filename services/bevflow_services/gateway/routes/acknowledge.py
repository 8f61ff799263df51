"""Alert acknowledgements, kept by the gateway: who acknowledged which alert, and when.

- ``POST /api/alerts/{id}/acknowledge`` (operator) ``{"note": "..."}``: records it, and sends it to
  every dashboard on ``/ws/acknowledgements``;
- ``POST /api/alerts/acknowledge`` (operator) ``{"ids": [...], "note": "..."}``: the same for
  several alerts at once (unknown ids are listed, not fatal);
- ``GET /api/acknowledgements?ids=a,b``: the acknowledgements of those alerts (or the latest ones);
- alert listings (``/api/alerts``, ``/api/violations``) carry each alert's acknowledgements.

With the history database (``--db``) they are stored in its ``acknowledgements`` table, so they
outlive the gateway; with the in-memory history they live as long as it does.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Path, Query, WebSocket
from pydantic import BaseModel, Field
from starlette.requests import HTTPConnection

from bevflow.schemas import iso_utc

from bevflow_services.gateway.auth import Operator, Viewer
from bevflow_services.gateway.fanout import Broadcaster
from bevflow_services.gateway.history import EventQuery
from bevflow_services.gateway.state import GatewayState
from bevflow_services.storage import Acknowledgement, HistoryDatabase

router = APIRouter(prefix="/api", tags=["alerts"])
AlertId = Annotated[str, Path(min_length=1, max_length=200, description="an alert id from /api/alerts")]
MAX_IDS = 1000


class AcknowledgementView(BaseModel):
    alert_id: str
    user: str
    time: str
    time_ns: int = Field(description="when it was acknowledged (gateway clock)")
    note: str


class AcknowledgeBody(BaseModel):
    note: str = Field("", max_length=1000)


class BulkAcknowledgeBody(AcknowledgeBody):
    ids: list[Annotated[str, Field(min_length=1, max_length=200)]] = Field(min_length=1, max_length=MAX_IDS)


class BulkAcknowledged(BaseModel):
    acknowledged: list[AcknowledgementView]
    unknown: list[str] = Field(description="ids the gateway knows no alert for; nothing recorded for them")


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


@router.post("/alerts/{alert_id}/acknowledge", response_model=AcknowledgementView, status_code=201,
             summary="Acknowledge an alert (operator)", responses={404: {"description": "no such alert"}})
def acknowledge(alert_id: AlertId, principal: Operator, conn: HTTPConnection, body: AcknowledgeBody | None = None) -> AcknowledgementView:
    try:
        ack = get_book(conn).acknowledge(alert_id, principal.name, body.note if body else "")
    except KeyError:
        raise HTTPException(404, f"alert_id: no alert {alert_id!r} (see /api/alerts)") from None
    return view(ack)


@router.post("/alerts/acknowledge", response_model=BulkAcknowledged, status_code=201,
             summary="Acknowledge several alerts at once (operator)")
def acknowledge_many(body: BulkAcknowledgeBody, principal: Operator, conn: HTTPConnection) -> BulkAcknowledged:
    book = get_book(conn)
    done, unknown = [], []
    for alert_id in dict.fromkeys(body.ids):
        try:
            done.append(view(book.acknowledge(alert_id, principal.name, body.note)))
        except KeyError:
            unknown.append(alert_id)
    return BulkAcknowledged(acknowledged=done, unknown=unknown)


@router.get("/acknowledgements", response_model=list[AcknowledgementView], summary="Who acknowledged which alert")
def acknowledgements(
    _: Viewer,
    conn: HTTPConnection,
    ids: Annotated[str | None, Query(max_length=200_000, description="comma-separated alert ids; default: the latest 1000")] = None,
) -> list[AcknowledgementView]:
    book = get_book(conn)
    if ids is None:
        return [view(a) for a in book.latest(MAX_IDS)]
    wanted = [i for i in ids.split(",") if i][:MAX_IDS]
    found = book.of(wanted)
    return [view(a) for alert_id in wanted for a in found.get(alert_id, [])]


def acknowledgements_of(conn: HTTPConnection, alert_ids: list[str]) -> dict[str, list[AcknowledgementView]]:
    """For alert listings: each alert's acknowledgements, as views."""
    return {k: [view(a) for a in v] for k, v in get_book(conn).of(alert_ids).items()}


async def acknowledgements_stream(websocket: WebSocket) -> Any:
    """``/ws/acknowledgements``: one ``AcknowledgementView`` per text frame as they are made."""
    from bevflow_services.gateway.routes.streams import json_sender, serve

    book = get_book(websocket)
    async with book.stream.subscribe() as sub:
        await websocket.accept()
        await serve(websocket, sub, json_sender(websocket))

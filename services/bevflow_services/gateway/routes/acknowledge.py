"""Alert acknowledgements, kept by the gateway: who acknowledged which alert, and when.

- ``POST /api/alerts/{id}/acknowledge`` (operator) ``{"note": "..."}``: records it, and sends it to
  every dashboard on ``/ws/acknowledgements``;
- ``POST /api/alerts/acknowledge`` (operator) ``{"ids": [...], "note": "..."}``: the same for
  several alerts at once (unknown ids are listed, not fatal);
- ``GET /api/acknowledgements?ids=a,b``: the acknowledgements of those alerts (or the latest ones);
- alert listings (``/api/alerts``, ``/api/violations``) carry each alert's acknowledgements.

They are kept by ``bevflow_services.gateway.acknowledgements``, in the history database when
there is one.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, Query
from pydantic import BaseModel, Field
from starlette.requests import HTTPConnection

from bevflow_services.gateway.acknowledgements import AcknowledgementView, get_book, view
from bevflow_services.gateway.auth import Operator, Viewer

router = APIRouter(prefix="/api", tags=["alerts"])
AlertId = Annotated[str, Path(min_length=1, max_length=200, description="an alert id from /api/alerts")]
MAX_IDS = 1000


class AcknowledgeBody(BaseModel):
    note: str = Field("", max_length=1000)


class BulkAcknowledgeBody(AcknowledgeBody):
    ids: list[Annotated[str, Field(min_length=1, max_length=200)]] = Field(min_length=1, max_length=MAX_IDS)


class BulkAcknowledged(BaseModel):
    acknowledged: list[AcknowledgementView]
    unknown: list[str] = Field(description="ids the gateway knows no alert for; nothing recorded for them")


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

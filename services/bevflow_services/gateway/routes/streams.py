"""Websockets: ``/ws/alerts`` (alerts as they start and end) and ``/ws/tracks`` (every tracker tick).

``/ws/alerts?types=distance_incident,over_capacity&zones=gate&replay=active`` sends one
``AlertMessage`` JSON object per text frame: an alert when it starts and the same ``id`` again when
it changes or ends (``active`` false, ``end`` set). ``types`` and ``zones`` are comma-separated
filters (omit ``types`` to get every type but ``distance_violation``, the per-pair events that
``distance_incident`` groups; omit ``zones`` for every zone; an alert with zone null only passes
when ``zones`` is omitted);
``replay=active`` first sends the alerts already ongoing. ``since=ID`` (the id of the last alert a
client received, when it reconnects) first sends, from the history, every alert whose newest
message came after that alert's, oldest first, each once in its newest state, then goes on live
without repeating them (``bevflow_services.gateway.alert_replay``); an id the history does not
hold is refused with 400. ``/ws/tracks`` sends one ``Tracks`` JSON object per tick, starting with
the latest one.

Clients prove who they are as for REST (the dashboard's session cookie, or an API token in the
``Authorization`` header) or with ``?token=TOKEN``; without either the connection is refused with
401, and ``/ws/tracks`` and ``/ws/alerts`` need the viewer role (403 otherwise).
A bad parameter refuses the connection with HTTP 400 and ``{"detail": "..."}`` naming it (or, on a
server without the websocket denial-response extension, closes with code 1008 and that reason).
Clients never send anything; what they send is ignored.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Any

from fastapi import APIRouter, HTTPException, WebSocket, WebSocketDisconnect
from fastapi.responses import JSONResponse
from pydantic import BaseModel

from bevflow.schemas import EVENT_TYPES, FEED_EVENT_TYPES, AlertMessage, Tracks

from bevflow_services.gateway.alert_replay import ReplayError, missed_alerts, position
from bevflow_services.gateway.auth import get_access
from bevflow_services.gateway.fanout import Subscription, pump
from bevflow_services.gateway.params import split_csv
from bevflow_services.gateway.routes.users import audited_stream
from bevflow_services.gateway.state import GatewayState

router = APIRouter()
REPLAY_CHOICES = ("none", "active")
# What sending to a client that has just gone away raises, depending on the server.
CLIENT_GONE = (WebSocketDisconnect, OSError, RuntimeError)
# How often an open stream's credential is checked again: revoking it ends the stream within this.
RECHECK_S = 0.5


class AlertFilter:
    """Which alerts a subscriber wants."""

    def __init__(self, types: frozenset[str] | None, zones: frozenset[str] | None) -> None:
        self.types = types
        self.zones = zones

    def __call__(self, alert: AlertMessage) -> bool:
        if self.types is not None and alert.type not in self.types:
            return False
        return self.zones is None or alert.zone in self.zones


def alert_filter(query: Any, state: GatewayState) -> tuple[AlertFilter, bool]:
    """The filter and the replay flag from the query string; HTTPException naming a bad parameter."""
    unknown = sorted(set(query.keys()) - {"types", "zones", "replay", "since", "token"})
    if unknown:
        raise HTTPException(400, f"unknown parameter(s) {', '.join(unknown)}; allowed: types, zones, replay, since")
    types = split_csv(query.get("types"), "types", EVENT_TYPES) or frozenset(FEED_EVENT_TYPES)
    zones = split_csv(query.get("zones"), "zones", tuple(z.id for z in state.site.zones))
    replay = query.get("replay", "none")
    if replay not in REPLAY_CHOICES:
        raise HTTPException(400, f"replay: must be one of {', '.join(REPLAY_CHOICES)}, got {replay!r}")
    if "since" in query and replay == "active":
        raise HTTPException(400, "since and replay=active exclude each other: since already sends what changed")
    return AlertFilter(types, zones), replay == "active"


async def replay_since(websocket: WebSocket, state: GatewayState, wanted: AlertFilter) -> list[AlertMessage]:
    """What the client missed since the alert ``?since=`` names; HTTPException(400) if it cannot be replayed."""
    try:
        return await asyncio.to_thread(missed_alerts, websocket.query_params["since"], websocket.app.state.recent_alerts,
                                       state.history, wanted.types, wanted)  # a database query
    except ReplayError as exc:
        raise HTTPException(400, str(exc)) from None


async def refuse(websocket: WebSocket, exc: HTTPException) -> None:
    if "websocket.http.response" in websocket.scope.get("extensions", {}):
        await websocket.send_denial_response(JSONResponse({"detail": exc.detail}, status_code=exc.status_code))
    else:
        await websocket.close(code=1008, reason=str(exc.detail)[:120])


async def authorized(websocket: WebSocket, role: str = "viewer") -> bool:
    """Whether the client may have this stream; if not, refuses it (401 or 403) and says False."""
    principal = get_access(websocket).principal(websocket)
    if principal is None:
        await refuse(websocket, HTTPException(401, "log in, or pass an API token (?token=TOKEN)"))
        return False
    if not principal.can(role):
        await refuse(websocket, HTTPException(403, f"this stream needs the {role} role; {principal.name} is a {principal.role}"))
        return False
    if principal.via == "session" and not same_origin(websocket):
        # Another site's page opening a socket with the user's cookie (browsers that ignore SameSite).
        await refuse(websocket, HTTPException(403, "a session cookie is accepted only from the gateway's own pages"))
        return False
    return True


def same_origin(websocket: WebSocket) -> bool:
    """Whether the handshake's Origin (if the client sent one) is the host it connected to."""
    origin = websocket.headers.get("origin")
    if origin is None:
        return True  # not a browser
    return origin.split("://", 1)[-1].rstrip("/") == websocket.headers.get("host", "")


async def until_revoked(websocket: WebSocket, role: str = "viewer") -> None:
    """Return once the client's credential no longer grants ``role`` (its token revoked, its user
    removed or demoted, its password changed, its session ended or expired), closing the socket
    with 1008. The check was made once at the handshake; repeating it is what ends a stream that
    was opened before access was taken away, whichever process took it (the gateway or
    ``bevflow users`` on the database)."""
    access = get_access(websocket)
    while True:
        await asyncio.sleep(RECHECK_S)
        principal = await asyncio.to_thread(access.principal, websocket)  # a database query
        if principal is None or not principal.can(role):
            await websocket.close(code=1008, reason="access revoked or expired")
            return


async def serve(websocket: WebSocket, sub: Subscription[Any], send: Callable[[Any], Awaitable[None]]) -> None:
    """Forward ``sub`` to the client until it disconnects or loses access; its reads are only
    watched for closing."""

    async def until_closed() -> None:
        while (await websocket.receive())["type"] != "websocket.disconnect":
            pass

    tasks = [asyncio.create_task(pump(sub, send)), asyncio.create_task(until_closed()),
             asyncio.create_task(until_revoked(websocket))]
    try:
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in tasks:
            task.cancel()
        outcomes = await asyncio.gather(*tasks, return_exceptions=True)
    for outcome in outcomes:
        if isinstance(outcome, Exception) and not isinstance(outcome, CLIENT_GONE):
            raise outcome


def skip_replayed(send: Callable[[AlertMessage], Awaitable[None]],
                  replayed: list[AlertMessage]) -> Callable[[AlertMessage], Awaitable[None]]:
    """``send``, less the live alerts the replay already sent in the same or a newer state."""
    sent = {a.id: position(a.event) for a in replayed}

    async def send_new(alert: AlertMessage) -> None:
        if alert.id not in sent or position(alert.event) > sent[alert.id]:
            await send(alert)

    return send_new


def json_sender(websocket: WebSocket) -> Callable[[BaseModel], Awaitable[None]]:
    async def send(message: BaseModel) -> None:
        await websocket.send_text(message.model_dump_json())

    return send


@router.websocket("/ws/alerts")
async def alerts_stream(websocket: WebSocket) -> None:
    state: GatewayState = websocket.app.state.gateway
    if not await authorized(websocket):
        return
    try:
        wanted, replay = alert_filter(websocket.query_params, state)
    except HTTPException as exc:
        await refuse(websocket, exc)
        return
    send = json_sender(websocket)
    # Subscribe before accepting, so that a client that sees the connection open is certain to get
    # every alert from then on; and before replaying, so an alert starting meanwhile is not lost
    # (with replay=active it may come twice: clients update alerts by id).
    async with state.alerts.subscribe(wanted) as sub:
        if "since" in websocket.query_params:
            try:
                missed = await replay_since(websocket, state, wanted)
            except HTTPException as exc:
                await refuse(websocket, exc)
                return
            await websocket.accept()
            for alert in missed:
                await send(alert)
            await serve(websocket, sub, skip_replayed(send, missed))
            return
        await websocket.accept()
        if replay:
            for event in state.active_alerts():
                alert = AlertMessage.from_event(event)
                if wanted(alert):
                    await send(alert)
        await serve(websocket, sub, send)


@router.websocket("/ws/tracks")
async def tracks_stream(websocket: WebSocket) -> None:
    state: GatewayState = websocket.app.state.gateway
    if not await authorized(websocket):
        return
    unknown = sorted(set(websocket.query_params.keys()) - {"token"})
    if unknown:
        names = ", ".join(unknown)
        await refuse(websocket, HTTPException(400, f"unknown parameter(s) {names}; /ws/tracks takes only token"))
        return
    send_json = json_sender(websocket)
    newest_sent = -1

    async def send(tracks: Tracks) -> None:
        nonlocal newest_sent
        if tracks.time_ns > newest_sent:  # the latest tick may also be in the queue already
            newest_sent = tracks.time_ns
            await send_json(tracks)

    async with state.tracks_stream.subscribe() as sub, audited_stream(websocket, "live_tracks"):
        await websocket.accept()
        latest = state.tracks
        if latest is not None:
            await send(latest)
        await serve(websocket, sub, send)


@router.websocket("/ws/acknowledgements")
async def acknowledgements_stream(websocket: WebSocket) -> None:
    """Alert acknowledgements as operators make them (``AcknowledgementView`` JSON per frame)."""
    from bevflow_services.gateway.routes.acknowledge import acknowledgements_stream as stream

    if not await authorized(websocket):
        return
    unknown = sorted(set(websocket.query_params.keys()) - {"token"})
    if unknown:
        await refuse(websocket, HTTPException(400, f"unknown parameter(s) {', '.join(unknown)}; takes only token"))
        return
    await stream(websocket)

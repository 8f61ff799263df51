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

from fastapi import APIRouter, HTTPException, WebSocket

from bevflow.schemas import EVENT_TYPES, FEED_EVENT_TYPES, AlertMessage, Tracks

from bevflow_services.gateway.acknowledgements import acknowledgements_stream as send_acknowledgements
from bevflow_services.gateway.alert_replay import ReplayError, missed_alerts, position
from bevflow_services.gateway.params import split_csv
from bevflow_services.gateway.state import GatewayState
from bevflow_services.gateway.trace_audit import audited_stream
from bevflow_services.gateway.ws.access import authorized, refuse
from bevflow_services.gateway.ws.forwarding import json_sender, serve

router = APIRouter()
REPLAY_CHOICES = ("none", "active")


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


def skip_replayed(send: Callable[[AlertMessage], Awaitable[None]],
                  replayed: list[AlertMessage]) -> Callable[[AlertMessage], Awaitable[None]]:
    """``send``, less the live alerts the replay already sent in the same or a newer state."""
    sent = {a.id: position(a.event) for a in replayed}

    async def send_new(alert: AlertMessage) -> None:
        if alert.id not in sent or position(alert.event) > sent[alert.id]:
            await send(alert)

    return send_new


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
    if not await authorized(websocket):
        return
    unknown = sorted(set(websocket.query_params.keys()) - {"token"})
    if unknown:
        await refuse(websocket, HTTPException(400, f"unknown parameter(s) {', '.join(unknown)}; takes only token"))
        return
    await send_acknowledgements(websocket)

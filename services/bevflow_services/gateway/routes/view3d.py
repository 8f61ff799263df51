"""The 3D view through the gateway, behind the same login as the dashboard.

viser has no login of its own, so it listens on loopback only (``View3D`` on 127.0.0.1) and the
gateway relays to it: ``GET /view3d/...`` its page, and ``/view3d`` its websocket (viser's page
opens its websocket at its own address, less the trailing slash). Both need the viewer role, like
the live map; the websocket shows everyone's position, so it is audited as ``live_tracks``, and it
is closed when its user's access is taken away, like ``/ws/tracks``.
"""

from __future__ import annotations

import asyncio
import urllib.error
import urllib.parse
import urllib.request
from typing import Any

import websockets
from fastapi import APIRouter, HTTPException, Request, WebSocket
from fastapi.responses import RedirectResponse, Response
from websockets.asyncio.client import ClientConnection

from bevflow_services.gateway.auth import Viewer
from bevflow_services.gateway.trace_audit import audited_stream
from bevflow_services.gateway.view3d_path import PATH
from bevflow_services.gateway.ws.access import authorized, refuse, until_revoked
from bevflow_services.gateway.ws.forwarding import CLIENT_GONE

LOOPBACK = "127.0.0.1"
FETCH_TIMEOUT_S = 10.0
router = APIRouter(include_in_schema=False)


def view_port(app: Any) -> int:
    port = app.state.view3d_port
    if port is None:
        raise HTTPException(404, "the 3D view is not running on this gateway")
    return int(port)


@router.get(PATH)
def to_page() -> RedirectResponse:
    return RedirectResponse(f"{PATH}/", status_code=307)


@router.get(PATH + "/{path:path}")
async def page(path: str, request: Request, _: Viewer) -> Response:
    """viser's page (and any file it asks for), fetched from the loopback viser server."""
    url = f"http://{LOOPBACK}:{view_port(request.app)}/{urllib.parse.quote(path)}"
    status, content_type, body = await asyncio.to_thread(fetch, url)
    return Response(body, status_code=status, media_type=content_type, headers={"Cache-Control": "no-store"})


def fetch(url: str) -> tuple[int, str, bytes]:
    try:
        with urllib.request.urlopen(url, timeout=FETCH_TIMEOUT_S) as response:
            return response.status, response.headers.get("content-type", "application/octet-stream"), response.read()
    except urllib.error.HTTPError as error:
        return error.code, error.headers.get("content-type", "text/plain"), error.read()
    except (urllib.error.URLError, OSError):
        raise HTTPException(503, "the 3D view is not answering") from None


@router.websocket(PATH)
async def socket(websocket: WebSocket) -> None:
    """viser's websocket, relayed both ways to the loopback viser server."""
    if not await authorized(websocket):
        return
    try:
        upstream = await websockets.connect(f"ws://{LOOPBACK}:{view_port(websocket.app)}",
                                            subprotocols=websocket.scope.get("subprotocols") or None,
                                            max_size=None, compression=None, open_timeout=FETCH_TIMEOUT_S)
    except HTTPException as exc:
        await refuse(websocket, exc)
        return
    except (TimeoutError, OSError, websockets.InvalidHandshake):
        await refuse(websocket, HTTPException(503, "the 3D view is not answering"))
        return
    async with upstream, audited_stream(websocket, "live_tracks"):
        await websocket.accept(subprotocol=upstream.subprotocol)
        await relay(websocket, upstream)


async def relay(websocket: WebSocket, upstream: ClientConnection) -> None:
    """Forward messages both ways until either side closes or the client loses access."""

    async def down() -> None:
        async for message in upstream:
            if isinstance(message, bytes):
                await websocket.send_bytes(message)
            else:
                await websocket.send_text(message)

    async def up() -> None:
        while (message := await websocket.receive())["type"] != "websocket.disconnect":
            if message.get("bytes") is not None:
                await upstream.send(message["bytes"])
            elif message.get("text") is not None:
                await upstream.send(message["text"])

    tasks = [asyncio.create_task(down()), asyncio.create_task(up()), asyncio.create_task(until_revoked(websocket))]
    try:
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in tasks:
            task.cancel()
        outcomes = await asyncio.gather(*tasks, return_exceptions=True)
    for outcome in outcomes:
        if isinstance(outcome, Exception) and not isinstance(outcome, (*CLIENT_GONE, websockets.ConnectionClosed)):
            raise outcome

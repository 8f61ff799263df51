"""Forwarding a subscription to a websocket client until it disconnects or loses access."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Any

from fastapi import WebSocket, WebSocketDisconnect
from pydantic import BaseModel

from bevflow_services.gateway.fanout import Subscription, pump
from bevflow_services.gateway.ws.access import until_revoked

# What sending to a client that has just gone away raises, depending on the server.
CLIENT_GONE = (WebSocketDisconnect, OSError, RuntimeError)


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


def json_sender(websocket: WebSocket) -> Callable[[BaseModel], Awaitable[None]]:
    async def send(message: BaseModel) -> None:
        await websocket.send_text(message.model_dump_json())

    return send

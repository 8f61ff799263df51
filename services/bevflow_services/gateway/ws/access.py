"""Who may open a websocket, and for how long: the handshake's check (refused with 401 or 403, or
1008 on a server without the denial-response extension), and the repeated check that closes a
stream once its credential no longer grants the role."""

from __future__ import annotations

import asyncio

from fastapi import HTTPException, WebSocket
from fastapi.responses import JSONResponse

from bevflow_services.gateway.auth import get_access

# How often an open stream's credential is checked again: revoking it ends the stream within this.
RECHECK_S = 0.5


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

"""Taking access away ends the streams already open: a revoked token, a removed user, a new
password, each closes that user's websockets with 1008, over a real server."""

from __future__ import annotations

import time

import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

from bevflow.site import Site

from bevflow_services.gateway import GatewayState, create_app
from bevflow_services.gateway.auth import SESSION_COOKIE, Access
from tests.services.gateway.access import secured_access
from tests.services.gateway.feed import T0, tracks
from tests.services.gateway.live import serve_in_thread

STREAMS = ("/ws/tracks", "/ws/alerts", "/ws/acknowledgements")


def revoke_token(access: Access, name: str) -> None:
    for token in access.store.tokens(name):
        access.store.revoke_token(token.id)


def remove_user(access: Access, name: str) -> None:
    access.store.remove_user(name)


def change_password(access: Access, name: str) -> None:
    access.store.set_password(name, access.hash_password("a brand new passphrase"))


def closed_within(ws: ClientConnection, deadline_s: float) -> int | None:
    """The close code if the server closes ``ws`` within ``deadline_s``; None if it stays open."""
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        try:
            ws.recv(timeout=end - time.monotonic())
        except TimeoutError:
            return None
        except ConnectionClosed as closed:
            return closed.rcvd.code if closed.rcvd is not None else None
    return None


@pytest.mark.parametrize("path", STREAMS)
@pytest.mark.parametrize(("credential", "take_away"), [
    ("token", revoke_token),
    ("token", remove_user),
    ("token", change_password),
    ("session", change_password),
    ("session", remove_user),
])
def test_taking_access_away_closes_open_streams(site: Site, state: GatewayState, path: str, credential: str,
                                                take_away) -> None:
    access, tokens = secured_access()
    state.apply(tracks(T0, {1: (0.0, 0.0)}))
    headers = {}
    if credential == "session":
        headers["Cookie"] = f"{SESSION_COOKIE}={access.start_session(access.store.user('viewer'))}"
    else:
        path += f"?token={tokens['viewer']}"
    with serve_in_thread(create_app(site, state, access=access)) as address:
        with connect(f"ws://{address}{path}", additional_headers=headers) as ws:
            other = connect(f"ws://{address}{STREAMS[0]}?token={tokens['operator']}")
            assert closed_within(ws, 0.6) is None  # still allowed: stays open
            take_away(access, "viewer")
            assert closed_within(ws, 5.0) == 1008
            assert closed_within(other, 0.6) is None  # another user's stream goes on
            other.close()


def test_watching_the_live_tracks_is_audited(site: Site, state: GatewayState) -> None:
    access, tokens = secured_access()
    state.apply(tracks(T0, {1: (0.0, 0.0)}))
    with serve_in_thread(create_app(site, state, access=access)) as address:
        with connect(f"ws://{address}/ws/tracks?token={tokens['viewer']}") as ws:
            assert '"time_ns"' in ws.recv(timeout=5)
            opened, _ = access.store.audit_log(user="viewer")
            assert [(e.action, e.client, e.detail) for e in opened] == [("live_tracks", "127.0.0.1", "opened")]
        deadline = time.monotonic() + 5.0
        while len(entries := access.store.audit_log(user="viewer")[0]) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
    assert [e.detail.split(" after ")[0] for e in entries] == ["closed", "opened"]  # newest first
    with serve_in_thread(create_app(site, state, access=access)) as address:  # the other streams are not tracing
        with connect(f"ws://{address}/ws/alerts?token={tokens['operator']}") as ws:
            assert closed_within(ws, 0.3) is None
    assert access.store.audit_log(user="operator")[1] == 0

"""The 3D view behind the gateway's login: viser listens on loopback only, and ``/view3d/`` (its
page) and ``/view3d`` (its websocket) need the viewer role, over a real server with a real viser."""

from __future__ import annotations

import time
import urllib.error
import urllib.request

import pytest
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

import viser
from bevflow.site import Site

from bevflow_services.gateway import GatewayState, create_app
from bevflow_services.launcher import free_port
from tests.services.gateway.access import secured_access
from tests.services.gateway.live import serve_in_thread

PROTOCOL = f"viser-v{viser.__version__}"  # what viser's page asks for


def get(url: str, token: str | None = None) -> tuple[int, str]:
    request = urllib.request.Request(url, headers={"Authorization": f"Bearer {token}"} if token else {})
    try:
        with urllib.request.urlopen(request, timeout=10) as response:
            return response.status, response.read().decode(errors="replace")
    except urllib.error.HTTPError as refused:
        return refused.code, refused.read().decode(errors="replace")


def listening_addresses(port: int) -> list[str]:
    """The local addresses (hex, as /proc/net shows them) of sockets listening on ``port``."""
    found = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = open(table).read().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            local, state = line.split()[1], line.split()[3]
            address, port_hex = local.split(":")
            if state == "0A" and int(port_hex, 16) == port:  # 0A: LISTEN
                found.append(address)
    return found


@pytest.fixture
def gateway(site: Site, state: GatewayState):
    access, tokens = secured_access()
    view_port = free_port()
    with serve_in_thread(create_app(site, state, access=access, view3d_port=view_port)) as address:
        yield address, view_port, access, tokens


def test_the_page_needs_a_login(gateway) -> None:
    address, _, _, tokens = gateway
    assert get(f"http://{address}/view3d/")[0] == 401
    status, page = get(f"http://{address}/view3d/", tokens["viewer"])
    assert status == 200 and "<html" in page.lower()


def test_viser_listens_on_loopback_only(gateway) -> None:
    _, view_port, _, _ = gateway
    assert get(f"http://127.0.0.1:{view_port}/")[0] == 200  # there, for the gateway
    addresses = listening_addresses(view_port)
    if not addresses:
        pytest.skip("no /proc/net/tcp to read listening sockets from")
    assert addresses == ["0100007F"]  # 127.0.0.1, not 0.0.0.0 (00000000) nor any other address


def test_the_socket_needs_a_login_is_relayed_audited_and_closed_on_revocation(gateway) -> None:
    address, _, access, tokens = gateway
    with pytest.raises(InvalidStatus) as refused:
        connect(f"ws://{address}/view3d", subprotocols=[PROTOCOL]).close()
    assert refused.value.response.status_code == 401
    with connect(f"ws://{address}/view3d?token={tokens['viewer']}", subprotocols=[PROTOCOL], max_size=None) as ws:
        assert ws.subprotocol == PROTOCOL
        assert isinstance(ws.recv(timeout=10), bytes)  # viser's scene, relayed
        assert [e.action for e in access.store.audit_log(user="viewer")[0]] == ["live_tracks"]
        access.store.revoke_token(access.store.tokens("viewer")[0].id)
        deadline = time.monotonic() + 5.0
        with pytest.raises(ConnectionClosed) as closed:
            while time.monotonic() < deadline:
                ws.recv(timeout=deadline - time.monotonic())
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 1008
